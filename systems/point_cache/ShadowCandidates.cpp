#include "systems/point_cache/ShadowCandidates.h"

#include "runtime/core/Error.h"
#include "runtime/math/Distance.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <vector>

namespace qgi {
namespace {

// Blocks of this many cells per axis (a power of two), halved kCullDepth times to single cells.
constexpr int kCullBlock = 8;
constexpr int kCullDepth = 3;
static_assert(kCullBlock == 1 << kCullDepth);

/// The ball (c, R) against the cone of rays from every x within h of q to the light.
/// The cone lies inside the capsule of radius b around the segment from q to L, so a ball
/// clear of the capsule (with raySlack more) is clear of the cone: most pairs are settled by
/// that cheaper test. Both in double: a box's test must pass wherever one of its points' does,
/// and the point's and the box's distances and sums rounded in float could differ by more than
/// the box's margins where R is thousands of cells wide or c far from the grid.
bool passes(const glm::vec3& c, float R, const glm::vec3& q, const AreaLight& light, float h,
            float raySlack) {
    const double reach = double(R) + double(raySlack) + double(h);
    if (distanceToSegment(glm::dvec3(c), glm::dvec3(q), glm::dvec3(light.centre)) >=
        reach + double(light.boundRadius) + double(raySlack))
        return false;
    return distanceBeyondCone(c, q, light.centre, light.boundRadius) < reach;
}

bool eitherPose(const MobileMove& m, const glm::vec3& q, const AreaLight& light, float h,
                float raySlack) {
    return passes(m.before, m.radiusBefore, q, light, h, raySlack) ||
           passes(m.after, m.radiusAfter, q, light, h, raySlack);
}

/// A superset of eitherPose(): the culling's test.
bool aroundBoth(const MobileMove& m, const glm::vec3& q, const AreaLight& light, float h,
                float raySlack) {
    return m.merged ? passes(m.middle, m.radiusBoth, q, light, h, raySlack)
                    : eitherPose(m, q, light, h, raySlack);
}

} // namespace

MobileMove MobileMove::make(const glm::vec3& before, float radiusBefore, const glm::vec3& after,
                            float radiusAfter) {
    MobileMove m;
    m.before = before;
    m.after = after;
    m.radiusBefore = radiusBefore;
    m.radiusAfter = radiusAfter;
    const float halfStep = 0.5f * glm::length(after - before);
    const float wider = std::max(radiusBefore, radiusAfter);
    if (halfStep <= wider) {
        m.merged = true;
        m.middle = 0.5f * (before + after);
        // Widened for the rounding of the middle and of the sum.
        const glm::vec3 extent = glm::abs(before) + glm::abs(after);
        m.radiusBoth =
            (halfStep + wider) * (1.f + 1e-5f) + 1e-6f * std::max({extent.x, extent.y, extent.z});
    }
    return m;
}

bool mayShadow(const MobileMove& move, const glm::vec3& x, const glm::vec3& n,
               const AreaLight& light, float raySlack) {
    if (glm::dot(n, light.centre - x) < -light.boundRadius) return false;
    return eitherPose(move, x, light, 0.f, raySlack);
}

std::size_t
forEachShadowedPair(const PointGrid& grid, std::span<const glm::vec3> positions,
                    std::span<const glm::vec3> normals, std::span<const AreaLight> lights,
                    std::span<const MobileMove> moves, float raySlack,
                    const std::function<void(std::uint32_t, std::uint32_t, std::uint32_t)>& visit) {
    QGI_ASSERT(positions.size() == grid.pointCount() && normals.size() == grid.pointCount());
    if (moves.empty() || lights.empty() || grid.pointCount() == 0) return 0;
    const glm::ivec3 dims = grid.dims();
    const float cell = grid.cellSize();
    const glm::ivec3 blocks = (dims + kCullBlock - 1) / kCullBlock;
    const std::size_t blockCount = std::size_t(blocks.x) * blocks.y * blocks.z;
    const std::size_t lightCount = lights.size();
    // A point may sit up to a rounding of its coordinates outside the cell floor() put it in.
    const glm::vec3 far =
        glm::max(glm::abs(grid.origin()), glm::abs(grid.origin() + glm::vec3(dims) * cell));
    const float rounding = 2e-6f * std::max({far.x, far.y, far.z});
    const auto ball = [&](const glm::ivec3& lo, const glm::ivec3& hi) {
        const glm::vec3 size = glm::vec3(hi - lo) * cell;
        return std::pair(grid.origin() + glm::vec3(lo) * cell + 0.5f * size,
                         0.5f * glm::length(size) * (1.f + 1e-5f) + rounding);
    };
    const auto hasPoints = [&](const glm::ivec3& lo, const glm::ivec3& hi) {
        for (int k = lo.z; k < hi.z; ++k)
            for (int j = lo.y; j < hi.y; ++j) {
                const std::size_t row = std::size_t(k * dims.y + j) * std::size_t(dims.x);
                if (grid.cellStart()[row + std::size_t(lo.x)] !=
                    grid.cellStart()[row + std::size_t(hi.x)])
                    return true;
            }
        return false;
    };
    // The (move, light) pairs, as m * lights + l, from `from` that pass for every x within h
    // of q.
    const auto filter = [&](std::span<const std::uint32_t> from, const glm::vec3& q, float h,
                            std::vector<std::uint32_t>& out) {
        out.clear();
        for (const std::uint32_t pair : from)
            if (aroundBoth(moves[pair / lightCount], q, lights[pair % lightCount], h, raySlack))
                out.push_back(pair);
    };
    std::vector<std::uint32_t> everyPair(moves.size() * lightCount);
    for (std::size_t i = 0; i < everyPair.size(); ++i)
        everyPair[i] = std::uint32_t(i);

    std::atomic<std::size_t> tested{0};
    tbb::parallel_for(std::size_t(0), blockCount, [&](std::size_t b) {
        const glm::ivec3 bi(int(b % blocks.x), int(b / blocks.x % blocks.y),
                            int(b / (std::size_t(blocks.x) * blocks.y)));
        const glm::ivec3 blockLo = bi * kCullBlock, blockHi = glm::min(blockLo + kCullBlock, dims);
        if (!hasPoints(blockLo, blockHi)) return;
        // levels[d]: the pairs the box at depth d of the walk passed.
        std::array<std::vector<std::uint32_t>, kCullDepth + 1> levels;
        {
            const auto [centre, radius] = ball(blockLo, blockHi);
            filter(everyPair, centre, radius, levels[0]);
        }
        if (levels[0].empty()) return;
        std::size_t testedHere = 0;
        const auto testPoints = [&](std::uint32_t c, std::span<const std::uint32_t> pairs) {
            for (const std::uint32_t p : grid.pointsHeldBy(c)) {
                ++testedHere;
                for (const std::uint32_t pair : pairs) {
                    const auto m = std::uint32_t(pair / lightCount);
                    const auto l = std::uint32_t(pair % lightCount);
                    if (mayShadow(moves[m], positions[p], normals[p], lights[l], raySlack))
                        visit(p, m, l);
                }
            }
        };
        const auto walk = [&](const auto& self, const glm::ivec3& lo, const glm::ivec3& hi,
                              std::size_t depth) -> void {
            const glm::ivec3 extent = hi - lo;
            if (extent == glm::ivec3(1)) {
                testPoints(std::uint32_t((lo.z * dims.y + lo.y) * dims.x + lo.x), levels[depth]);
                return;
            }
            // Halving rounds up: a side of at most 2^kCullDepth cells is one cell after
            // kCullDepth halvings.
            QGI_ASSERT(depth < std::size_t(kCullDepth));
            const glm::ivec3 mid = lo + (extent + 1) / 2;
            for (int octant = 0; octant < 8; ++octant) {
                glm::ivec3 childLo = lo, childHi = hi;
                bool empty = false;
                for (int a = 0; a < 3; ++a) {
                    if (octant >> a & 1)
                        childLo[a] = mid[a];
                    else
                        childHi[a] = mid[a];
                    empty = empty || childLo[a] >= childHi[a];
                }
                if (empty || !hasPoints(childLo, childHi)) continue;
                const auto [centre, radius] = ball(childLo, childHi);
                filter(levels[depth], centre, radius, levels[depth + 1]);
                if (!levels[depth + 1].empty()) self(self, childLo, childHi, depth + 1);
            }
        };
        walk(walk, blockLo, blockHi, 0);
        tested += testedHere;
    });
    return tested;
}

} // namespace qgi
