#version 450 core
// Shadow pass: depth only, as seen from a light.

layout(location = ATTRIBUTE_POSITION) in vec3 aPosition;

layout(location = UNIFORM_MODEL) uniform mat4 uModel;
layout(location = UNIFORM_VIEW_PROJECTION) uniform mat4 uViewProjection;

void main() { gl_Position = uViewProjection * (uModel * vec4(aPosition, 1.0)); }
