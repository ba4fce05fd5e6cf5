#pragma once

#include <glm/vec3.hpp>

namespace qgi {

/// Spot light at the entity's world position, shining along its local -Z axis (glTF).
/// Full intensity inside innerConeAngle, smooth falloff to zero at outerConeAngle.
struct SpotLight {
    glm::vec3 color{1.f};            ///< linear RGB
    float intensity = 1.f;           ///< radiant intensity on the axis, W/sr
    float innerConeAngle = 0.f;      ///< radians, half angle
    float outerConeAngle = 0.7853982f; ///< radians, half angle, at most pi/2
};

} // namespace qgi
