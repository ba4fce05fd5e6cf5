#pragma once

#include <glm/vec3.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

/** The query structure of the point cache (seed 003 section 1.6): a uniform 3D grid whose cells
 *  list every point whose oriented disc overlaps them. Point p's disc is centred on p, lies in
 *  its tangent plane and has its search radius R_p; it is thickened by planeTolerance * R_p on
 *  both sides, because a shaded position within that distance of the plane still takes p.
 *
 *  A point is *in range* of a shaded position x with unit normal n when
 *    |x - p| < R_p,  n_p . n >= minNormalCosine,  |n_p . (x - p)| <= planeTolerance * R_p.
 *  Insertion is conservative (a cell takes p when the thick disc's bounding box meets the cell
 *  and the cell's box reaches the thick plane), so the cell holding x lists every point in
 *  range of x: a query looks at one cell. Built once; queries are const and thread safe. */
class PointGrid {
public:
    struct Params {
        float cellSize = 1.f; ///< metres
        float minNormalCosine = 0.5f;
        float planeTolerance = 0.5f; ///< fraction of R_p
    };

    /// Longest allowed cell count; a build that would need more cells uses wider cells.
    static constexpr std::uint64_t kMaxCells = 1ull << 24;

    /// Builds over the points: unit normals, search radii R_p > 0 (metres). All finite (the
    /// cache checks). An empty set gives an empty grid whose queries find nothing.
    void build(std::span<const glm::vec3> positions, std::span<const glm::vec3> normals,
               std::span<const float> searchRadii, const Params& params);

    /// The in-range rule above, for one point.
    bool inRange(std::uint32_t point, const glm::vec3& x, const glm::vec3& n) const;

    /// Candidates of the cell holding x (a superset of the points in range); empty outside
    /// the grid.
    std::span<const std::uint32_t> candidates(const glm::vec3& x) const;
    /// Index of the cell holding x, or -1 outside the grid. Every point is listed in the cell
    /// holding its position.
    std::int64_t cellOf(const glm::vec3& x) const;
    /// The points whose position cell c holds (each point lies in one cell), in increasing
    /// order: a walk over cells that visits each point once.
    std::span<const std::uint32_t> pointsHeldBy(std::uint32_t cell) const;

    /// Calls f(point, distance) for every point in range of x, in increasing point order.
    template <typename F> void forEachInRange(const glm::vec3& x, const glm::vec3& n, F&& f) const {
        for (const std::uint32_t p : candidates(x)) {
            if (inRange(p, x, n)) f(p, distanceTo(p, x));
        }
    }

    std::size_t pointCount() const { return mPositions.size(); }
    std::size_t entryCount() const { return mCellPoints.size(); }
    glm::ivec3 dims() const { return mDims; }
    glm::vec3 origin() const { return mOrigin; }
    float cellSize() const { return mCellSize; }
    const Params& params() const { return mParams; }
    /// CSR layout, for the GPU copy: cell c lists cellPoints[cellStart[c] .. cellStart[c + 1]);
    /// cell (i, j, k) is c = (k * dims.y + j) * dims.x + i.
    std::span<const std::uint32_t> cellStart() const { return mCellStart; }
    std::span<const std::uint32_t> cellPoints() const { return mCellPoints; }
    float searchRadius(std::uint32_t point) const { return mRadii[point]; }

private:
    float distanceTo(std::uint32_t p, const glm::vec3& x) const;

    Params mParams;
    float mCellSize = 1.f;
    glm::vec3 mOrigin{0.f};
    glm::ivec3 mDims{0};
    std::vector<glm::vec3> mPositions, mNormals;
    std::vector<float> mRadii;
    std::vector<std::uint32_t> mCellStart, mCellPoints;
    /// Every point by the cell holding its position: mHeldBy[i] is cellOf(position of
    /// mHeldPoints[i]), both sorted by (cell, point).
    std::vector<std::uint32_t> mHeldBy, mHeldPoints;
};

} // namespace qgi
