#version 450 core
// Scene pass: outgoing radiance of a diffuse surface, W/(m^2 sr), into the HDR target:
//   albedo / pi * (E_indirect + E_direct) + emission
// E_indirect is the per-vertex irradiance (photon mode: all light) or the avatar's SH;
// E_direct, in hybrid mode only (HYBRID defined), comes from the lights with shadow maps.
// Glossy and mirror static surfaces add their specular radiance from the VLF (vlf.glsl).

#include "common/lighting.glsl"
#include "common/sh.glsl"
#include "common/vlf.glsl"
#include "common/pointcache.glsl"

layout(location = UNIFORM_ALBEDO) uniform vec3 uAlbedo;
layout(location = UNIFORM_EMISSION) uniform vec3 uEmission;
layout(location = UNIFORM_LIGHTING) uniform int uLighting;
layout(location = UNIFORM_MIRRORED) uniform bool uMirrored;
layout(location = UNIFORM_SH) uniform vec3 uSh[9];
layout(location = UNIFORM_CAMERA_POSITION) uniform vec3 uCameraPosition;
layout(binding = BASE_COLOR_UNIT) uniform sampler2D uBaseColor;

in VertexData {
    vec3 worldPosition;
    vec3 normal;
    vec2 uv;
    vec3 irradiance;
} vIn;

layout(location = 0) out vec4 oRadiance;

void main() {
    // Both sides are drawn; the back side is shaded with the normal turned toward the viewer.
    // A mirroring model matrix swaps which winding faces front.
    vec3 n = normalize(vIn.normal);
    if (gl_FrontFacing == uMirrored) n = -n;

    vec3 albedo = uAlbedo * texture(uBaseColor, vIn.uv).rgb;
    vec3 irradiance = vec3(0.0);
    if (uLighting == LIGHTING_VERTEX || uLighting == LIGHTING_POINT_CACHE)
        irradiance = vIn.irradiance;
    else if (uLighting == LIGHTING_SH) irradiance = shIrradiance(uSh, n);
    // Point cache (hybrid mode): soft shadows of area lights + indirect light, per fragment.
    float nearest = 1e9;
    if (uLighting == LIGHTING_POINT_CACHE || uPointParams.w > 0.5) {
        vec4 cached = pointCacheIrradiance(vIn.worldPosition, n, nearest);
#ifdef HYBRID
        if (uLighting == LIGHTING_POINT_CACHE && cached.w > 0.0) irradiance = cached.rgb;
#endif
    }
#ifdef HYBRID
    irradiance += directIrradiance(vIn.worldPosition, n);
#endif

    oRadiance = vec4(albedo * (1.0 / PI) * irradiance + uEmission, 1.0);
    // Glossy and mirror static surfaces: their specular part from the baked VLF.
    oRadiance.rgb += vlfRadiance(vIn.worldPosition, n, normalize(uCameraPosition - vIn.worldPosition));
    // Point-set view: a dot of a fifth of the spacing radius on every cache point.
    if (uPointParams.w > 0.5 && nearest < 0.2) oRadiance = vec4(4.0, 0.5, 0.1, 1.0);
}
