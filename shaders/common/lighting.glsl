// Direct irradiance from the frame's lights with shadow-map visibility (hybrid mode).
// Layout of LightBlock: SceneRenderer.cpp (GpuLightBlock); every macro comes from the C++ side.
// Every shadow map is a layer of one depth array, so there is a single lookup path: llvmpipe
// runs both sides of any branch it cannot prove uniform.

const float PI = 3.14159265358979;

struct Light {
    vec4 position;  // xyz: metres (point, spot); w: shadow texel size per metre of distance
                    //      (perspective maps) or in metres (directional)
    vec4 direction; // xyz: unit spot axis, or the direction directional light travels
    vec4 radiance;  // rgb: W/sr (point, spot) or W/m^2 (directional)
    vec4 spot;      // x, y: cone scale and offset on cos(angle)
    ivec4 kind;     // x: LIGHT_*; y: shadow faces (0 none, 1 one map, 6 cube); z: first layer
};

layout(std140, binding = LIGHT_BLOCK_BINDING) uniform LightBlock {
    mat4 uShadowMatrices[MAX_SHADOW_LAYERS]; // world to shadow clip space, per layer
    ivec4 uLightCount;                       // x: lights in uLights
    Light uLights[MAX_LIGHTS];
};

layout(binding = SHADOW_UNIT) uniform sampler2DArrayShadow uShadowMaps;

// Shadow lookups are offset along the normal by this many shadow texels (their world size at
// the point): with the slope-scaled depth bias of the shadow pass it keeps lit surfaces free
// of acne, and it moves shadow edges by no more than that.
const float kNormalOffsetTexels = 1.5;

// The cube face (+X -X +Y -Y +Z -Z) that sees direction v: its major axis.
int cubeFace(vec3 v) {
    vec3 a = abs(v);
    if (a.x >= a.y && a.x >= a.z) return v.x >= 0.0 ? 0 : 1;
    if (a.y >= a.z) return v.y >= 0.0 ? 2 : 3;
    return v.z >= 0.0 ? 4 : 5;
}

// Fraction of the light reaching p: 2x2 taps half a texel apart, each a hardware 2x2 PCF
// lookup, together a 3x3-texel tent.
float visibility(Light light, vec3 p) {
    int layer = light.kind.z + (light.kind.y == 6 ? cubeFace(p - light.position.xyz) : 0);
    vec4 clip = uShadowMatrices[layer] * vec4(p, 1.0);
    vec3 coord = 0.5 * clip.xyz / clip.w + 0.5;
    if (any(lessThan(coord, vec3(0.0))) || any(greaterThan(coord, vec3(1.0)))) return 1.0;
    vec2 texel = 1.0 / vec2(textureSize(uShadowMaps, 0).xy);
    float sum = 0.0;
    for (int i = 0; i < 4; ++i) {
        vec2 o = vec2((i & 1) == 0 ? -0.5 : 0.5, (i & 2) == 0 ? -0.5 : 0.5) * texel;
        sum += texture(uShadowMaps, vec4(coord.xy + o, float(layer), coord.z));
    }
    return 0.25 * sum;
}

// Irradiance, W/m^2, arriving directly from every light at p on a surface with unit normal n.
vec3 directIrradiance(vec3 p, vec3 n) {
    vec3 sum = vec3(0.0);
    for (int i = 0; i < uLightCount.x; ++i) {
        Light light = uLights[i];
        vec3 toLight;
        vec3 irradiance;
        float distance = 1.0;
        if (light.kind.x == LIGHT_DIRECTIONAL) {
            toLight = -light.direction.xyz;
            irradiance = light.radiance.rgb;
        } else {
            vec3 d = light.position.xyz - p;
            float distance2 = dot(d, d);
            distance = sqrt(distance2);
            toLight = d / distance;
            irradiance = light.radiance.rgb / distance2;
            if (light.kind.x == LIGHT_SPOT) {
                // glTF KHR_lights_punctual: linear in cos(angle) between the cones, squared.
                float cosAngle = dot(light.direction.xyz, -toLight);
                float t = clamp(cosAngle * light.spot.x + light.spot.y, 0.0, 1.0);
                irradiance *= t * t;
            }
        }
        float cosTheta = dot(n, toLight);
        if (cosTheta <= 0.0) continue;
        if (light.kind.y != 0) {
            float texel = light.position.w * (light.kind.x == LIGHT_DIRECTIONAL ? 1.0 : distance);
            irradiance *= visibility(light, p + n * (kNormalOffsetTexels * texel));
        }
        sum += irradiance * cosTheta;
    }
    return sum;
}
