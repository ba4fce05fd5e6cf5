#pragma once

#include "systems/point_cache/PointGrid.h"
#include "systems/point_cache/PointShading.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <functional>
#include <span>

namespace qgi {

/// A moved mobile's bounding ball at its old and new pose, and one ball holding both when the
/// step is short (no longer than the mobile is wide): the culling then tests one ball, not two.
struct MobileMove {
    glm::vec3 before{0.f}, after{0.f};
    float radiusBefore = 0.f, radiusAfter = 0.f;
    bool merged = false;
    glm::vec3 middle{0.f};
    float radiusBoth = 0.f;

    static MobileMove make(const glm::vec3& before, float radiusBefore, const glm::vec3& after,
                           float radiusAfter);
};

/** Whether a shadow ray from the point x (unit normal n) to `light` may pass the mobile's ball
 *  at its old or new pose. The rays from x to the points within the light's bounding radius b
 *  of its centre L lie in the cone distanceBeyondCone(c, x, L, b) measures, which a ball
 *  (c, R) can meet only where that is below R; a ray's ends lie up to `raySlack` off x and off
 *  the light's points, which moves each of its points by as much. A light wholly below the
 *  point's horizon adds nothing, mobile or not: false. */
bool mayShadow(const MobileMove& move, const glm::vec3& x, const glm::vec3& n,
               const AreaLight& light, float raySlack);

/** Calls visit(point, move, light) for every point of `grid` (positions and unit normals as it
 *  was built from) and every (move, light) with mayShadow() true, without testing every point:
 *  blocks of 8^3 grid cells, halved down to single cells, are tested by their bounding balls
 *  against the pairs their parent passed (the test widened by h holds for every x within h of
 *  the ball's centre: moving the cone's apex by h moves each of its points by at most h; a
 *  child's ball lies in its parent's), and only the points a passing cell holds
 *  (PointGrid::pointsHeldBy) are tested, against the pairs their cell passed. The result is
 *  exactly the all-points test's.
 *  Calls for one point come from one task, in (move, light) order; calls for different
 *  points may run concurrently. Returns the number of points tested. */
std::size_t forEachShadowedPair(
    const PointGrid& grid, std::span<const glm::vec3> positions, std::span<const glm::vec3> normals,
    std::span<const AreaLight> lights, std::span<const MobileMove> moves, float raySlack,
    const std::function<void(std::uint32_t point, std::uint32_t move, std::uint32_t light)>& visit);

} // namespace qgi
