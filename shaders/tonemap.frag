#version 450 core
// HDR radiance -> display: exposure, the ACES filmic curve fitted by Narkowicz (2015,
// "ACES Filmic Tone Mapping Curve"), per channel, then the exact sRGB encoding into an 8-bit
// target:  out = srgb(aces(exposure * L)),  aces(x) = x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14)

layout(binding = HDR_UNIT) uniform sampler2D uHdr;
layout(location = UNIFORM_EXPOSURE) uniform float uExposure;

layout(location = 0) out vec4 oColor;

vec3 acesFilmic(vec3 x) {
    return clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

vec3 srgbEncode(vec3 c) {
    return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, greaterThan(c, vec3(0.0031308)));
}

void main() {
    vec3 radiance = max(texelFetch(uHdr, ivec2(gl_FragCoord.xy), 0).rgb, vec3(0.0));
    oColor = vec4(srgbEncode(acesFilmic(uExposure * radiance)), 1.0);
}
