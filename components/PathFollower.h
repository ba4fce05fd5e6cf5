#pragma once

#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>

#include <vector>

namespace qgi {

/// One pose on a scripted path.
struct PathKey {
    float time = 0.f;                         ///< seconds from the path's start
    glm::vec3 position{0.f};                  ///< metres, in the parent's frame
    glm::quat rotation{1.f, 0.f, 0.f, 0.f};
};

/// Drives the entity's Transform along keyframes (linear position, slerped rotation).
struct PathFollower {
    std::vector<PathKey> keys; ///< sorted by time
    bool loop = true;          ///< wrap around after the last key; otherwise hold it
    float timeOffset = 0.f;    ///< seconds added to the frame time
};

} // namespace qgi
