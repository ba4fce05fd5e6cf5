#pragma once

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <cmath>

namespace qgi {

/// Distance from c to the segment [a, b] (to a itself when the segment has no length), in the
/// vectors' precision (float or double).
template <typename T, glm::qualifier Q>
T distanceToSegment(const glm::vec<3, T, Q>& c, const glm::vec<3, T, Q>& a,
                    const glm::vec<3, T, Q>& b) {
    const glm::vec<3, T, Q> ab = b - a;
    const T len2 = glm::dot(ab, ab);
    const T t = len2 > T(0) ? std::clamp(glm::dot(c - a, ab) / len2, T(0), T(1)) : T(0);
    return glm::length(a + t * ab - c);
}

/** How far c lies beyond the cone of segments from `apex` to the points within `radius` of
 *  `centre`: min over t in [0, 1] of |c - (apex + t (centre - apex))| - t radius. The point at
 *  t of any such segment lies within t radius of apex + t (centre - apex), so a ball of radius
 *  R around c can meet one of those segments only where this is below R. Tighter than
 *  distanceToSegment(c, apex, centre) - radius near the apex, where the cone is thin. The
 *  function is convex in t; its minimum is found in closed form, in double. */
inline double distanceBeyondCone(const glm::vec3& c, const glm::vec3& apex, const glm::vec3& centre,
                                 float radius) {
    const glm::dvec3 u = glm::dvec3(c) - glm::dvec3(apex);
    const glm::dvec3 d = glm::dvec3(centre) - glm::dvec3(apex);
    const double length = glm::length(d), r = double(radius);
    if (!(length > 0.0)) return glm::length(u) - r; // the cone is the ball itself
    const glm::dvec3 axis = d / length;
    const double along = glm::dot(u, axis);              // c's distance along the axis
    const double across = glm::length(u - along * axis); // and from it
    // g(s) = sqrt((along - s)^2 + across^2) - k s over s = t length in [0, length], with
    // k = r / length: g'(s) = 0 where (s - along) / sqrt(...) = k, that is at
    // s = along + k across / sqrt(1 - k^2); for k >= 1, g never rises and s = length.
    const double k = r / length;
    const double s =
        k >= 1.0 ? length : std::clamp(along + k * across / std::sqrt(1.0 - k * k), 0.0, length);
    return std::sqrt((along - s) * (along - s) + across * across) - k * s;
}

} // namespace qgi
