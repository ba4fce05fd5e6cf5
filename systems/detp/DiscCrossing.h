#pragma once

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <cstdint>

namespace qgi {

/// Segment `segment` crosses disc `disc` (indices into whatever the query was given).
struct DiscCrossing {
    std::uint32_t segment = 0;
    std::uint32_t disc = 0;
};

/// How far past its end, in disc radii, a segment still counts as reaching a disc's plane. A
/// segment that lands on the vertex's own surface ends on the tangent plane itself, give or take
/// float rounding; where the surface folds slightly at the vertex (the published Cornell walls
/// are not quite planar: their two triangles meet at about half a degree), half of the disc
/// lies just behind the surface and landings there stop short of its plane by up to
/// r sin(fold / 2). This slack counts those landings for folds up to about 2 degrees; with
/// 1e-3 the fold of the Cornell red wall showed as a dark line.
inline constexpr float kDiscEndTolerance = 0.02f;

/** DETP's counting rule (seed 000 section 3.6.3): does the segment origin + t * direction,
 *  t in [0, length] (length = +inf for a segment that left the scene), cross the disc of
 *  `radius` centred on `center` in the plane with unit normal `normal`?
 *  - only from the front: direction . normal < 0 (a segment from behind, or parallel, is not
 *    light arriving at this side of the surface);
 *  - at a plane crossing 0 <= t <= length + kDiscEndTolerance * radius;
 *  - within the disc: |origin + t * direction - center| <= radius.
 *  Returns that t, or -1 when the segment does not cross. `direction` is unit length. This is
 *  the reference the disc index is checked against.                                        */
inline float discCrossing(const glm::vec3& origin, const glm::vec3& direction, float length,
                          const glm::vec3& center, const glm::vec3& normal, float radius) {
    const float cosine = glm::dot(direction, normal);
    if (!(cosine < 0.f)) return -1.f;
    const float t = glm::dot(center - origin, normal) / cosine;
    if (!(t >= 0.f) || !(t <= length + kDiscEndTolerance * radius)) return -1.f; // NaN: no
    const glm::vec3 offset = origin + t * direction - center;
    return glm::dot(offset, offset) <= radius * radius ? t : -1.f;
}

inline bool crossesDisc(const glm::vec3& origin, const glm::vec3& direction, float length,
                        const glm::vec3& center, const glm::vec3& normal, float radius) {
    return discCrossing(origin, direction, length, center, normal, radius) >= 0.f;
}

} // namespace qgi
