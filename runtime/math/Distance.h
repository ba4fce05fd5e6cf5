#pragma once

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>

namespace qgi {

/// Distance from c to the segment [a, b] (to a itself when the segment has no length).
inline float distanceToSegment(const glm::vec3& c, const glm::vec3& a, const glm::vec3& b) {
    const glm::vec3 ab = b - a;
    const float len2 = glm::dot(ab, ab);
    const float t = len2 > 0.f ? std::clamp(glm::dot(c - a, ab) / len2, 0.f, 1.f) : 0.f;
    return glm::length(a + t * ab - c);
}

} // namespace qgi
