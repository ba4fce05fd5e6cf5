#include "runtime/scene/BuiltinPaths.h"

#include "runtime/core/Error.h"

#include <glm/geometric.hpp>

namespace qgi {

glm::quat facing(const glm::vec3& direction) {
    return glm::quatLookAtRH(glm::normalize(direction), glm::vec3(0.f, 1.f, 0.f));
}

PathFollower walkingLoop(std::span<const glm::vec3> corners, float speed, float turnSeconds) {
    QGI_ASSERT(corners.size() >= 2 && speed > 0.f);
    const std::size_t n = corners.size();
    const auto leg = [&](std::size_t i) { return corners[(i + 1) % n] - corners[i]; };
    PathFollower path;
    float time = 0.f;
    for (std::size_t i = 0; i < n; ++i) {
        path.keys.push_back({time, corners[i], facing(leg((i + n - 1) % n))});
        time += turnSeconds;
        path.keys.push_back({time, corners[i], facing(leg(i))});
        time += glm::length(leg(i)) / speed;
    }
    path.keys.push_back({time, corners[0], path.keys.front().rotation});
    return path;
}

} // namespace qgi
