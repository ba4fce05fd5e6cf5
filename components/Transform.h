#pragma once

#include "runtime/ecs/Entity.h"

#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>

namespace qgi {

/// Local pose relative to `parent` (or the world when parent is null). Metres, right-handed, Y up.
/// Write it with `registry.patch<Transform>(e)` so the transform system sees the change.
struct Transform {
    glm::vec3 translation{0.f};            ///< metres
    glm::quat rotation{1.f, 0.f, 0.f, 0.f}; ///< unit quaternion (w, x, y, z)
    glm::vec3 scale{1.f};
    Entity parent{};                        ///< null: a root
};

} // namespace qgi
