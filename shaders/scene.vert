#version 450 core
// Scene pass: carries world position, normal, texture coordinate and per-vertex irradiance.

layout(location = ATTRIBUTE_POSITION) in vec3 aPosition;
layout(location = ATTRIBUTE_NORMAL) in vec3 aNormal;
layout(location = ATTRIBUTE_UV) in vec2 aUv;
layout(location = ATTRIBUTE_IRRADIANCE) in vec3 aIrradiance;

layout(location = UNIFORM_MODEL) uniform mat4 uModel;
layout(location = UNIFORM_NORMAL_MATRIX) uniform mat3 uNormalMatrix;
layout(location = UNIFORM_VIEW_PROJECTION) uniform mat4 uViewProjection;

out VertexData {
    vec3 worldPosition;
    vec3 normal;
    vec2 uv;
    vec3 irradiance;
} vOut;

void main() {
    vec4 world = uModel * vec4(aPosition, 1.0);
    vOut.worldPosition = world.xyz;
    vOut.normal = uNormalMatrix * aNormal;
    vOut.uv = aUv;
    vOut.irradiance = aIrradiance;
    gl_Position = uViewProjection * world;
}
