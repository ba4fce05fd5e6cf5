#pragma once

#include <glm/vec3.hpp>

namespace qgi {

/// Distant light shining along the entity's local -Z axis (glTF).
struct DirectionalLight {
    glm::vec3 color{1.f};   ///< linear RGB
    float irradiance = 1.f; ///< W/m^2 on a surface facing the light
};

} // namespace qgi
