#pragma once

#include <glm/vec3.hpp>

namespace qgi {

/// Isotropic point light at the entity's world position. Total power = 4 pi * intensity * color.
struct PointLight {
    glm::vec3 color{1.f};  ///< linear RGB
    float intensity = 1.f; ///< radiant intensity, W/sr
};

} // namespace qgi
