#pragma once

#include "runtime/ecs/Entity.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <cstdint>

namespace qgi {

/// The closest intersection of a Ray with a StaticMesh or MobileMesh triangle.
struct Hit {
    float t = 0.f;               ///< ray parameter: point = origin + t * direction
    Entity entity;               ///< the mesh entity hit
    std::uint32_t primitive = 0; ///< triangle p of the entity's Mesh: indices[3p .. 3p + 2]
    /// (u, v) of the hit point on the triangle's object-space corners:
    /// point = (1 - u - v) * p0 + u * p1 + v * p2.
    glm::vec2 barycentrics{0.f};
    /// Unit geometric normal in world space, on the triangle's front side (the side from which
    /// its corners appear counter-clockwise in object space). Not flipped towards the ray.
    glm::vec3 normal{0.f};
};

} // namespace qgi
