#pragma once

#include <glm/vec3.hpp>

#include <algorithm>

namespace qgi {

/// Spot light at the entity's world position, shining along its local -Z axis (glTF).
/// Full intensity inside innerConeAngle, falling to zero at outerConeAngle (spotFalloff).
struct SpotLight {
    glm::vec3 color{1.f};            ///< linear RGB
    float intensity = 1.f;           ///< radiant intensity on the axis, W/sr
    float innerConeAngle = 0.f;      ///< radians, half angle
    float outerConeAngle = 0.7853982f; ///< radians, half angle, at most pi/2
};

/// Share of the axis intensity a spot sends at cos(angle to its axis) `cosAngle`: glTF
/// KHR_lights_punctual's falloff, which every lighting path (shader, photons, probes, VLF)
/// follows: clamp((c - cosOuter) / max(1e-3, cosInner - cosOuter), 0, 1)^2.
inline float spotFalloff(float cosAngle, float cosInner, float cosOuter) {
    const float x =
        std::clamp((cosAngle - cosOuter) / std::max(1e-3f, cosInner - cosOuter), 0.f, 1.f);
    return x * x;
}

} // namespace qgi
