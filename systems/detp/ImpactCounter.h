#pragma once

#include "runtime/ecs/Entity.h"
#include "systems/detp/CompensatedSum.h"
#include "systems/detp/ReceiverSet.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

struct PhotonSegments;

/** Impact count (seed 000 sections 3.5 and 3.6.1), kept for comparison with DETP.
 *  Each receiver triangle accumulates the power of the segments that end on it (from either
 *  side: a stored hit is an impact) in double precision, carrying its rounding error
 *  (CompensatedSum), so the paper's Add/Subtract update is exact up to rounding for static and
 *  mobile triangles alike. A vertex's irradiance is
 *  the area-weighted mean of its incident triangles' power / area,
 *      E(v) = sum_t P_t / sum_t A_t   over the triangles t around v,
 *  which is the flux through the vertex's one-ring over the ring's area: unbiased under
 *  uniform light, and not swayed by a sliver triangle that happened to catch one photon.   */
class ImpactCounter {
public:
    /// Sizes the per-triangle sums for `receivers` (triangles, areas, adjacency) and zeroes
    /// them.
    void reset(const ReceiverSet& receivers);

    /// Adds `sign` x power of every segment indices[k] of `segments` that hit a receiver
    /// triangle. Sequential, in index order: the same calls give bit-identical sums.
    void accumulate(const ReceiverSet& receivers, const PhotonSegments& segments,
                    std::span<const std::uint32_t> indices, double sign);
    /// An impact of `power` on mesh `hit` that moved from triangle `from` to triangle `to`
    /// (PhotonDelta::relabels).
    void moveImpact(const ReceiverSet& receivers, Entity hit, std::uint32_t from, std::uint32_t to,
                    const glm::vec3& power);

    /// Zeroes the sums of `receiver`'s triangles (a mobile taken out of the light: its impacts
    /// were all subtracted, and this drops the rounding they left); its vertices count as
    /// touched.
    void clearTriangles(const ReceiverSet::Receiver& receiver);

    /// The vertices around triangles that accumulate() changed since the last call, ascending;
    /// forgets them.
    void takeTouchedVertices(std::vector<std::uint32_t>& out);

    /// W/m^2 at a vertex (global index of the ReceiverSet).
    glm::vec3 irradiance(std::uint32_t vertex) const;
    /// W of impacts on triangle t (global index of the ReceiverSet).
    glm::dvec3 trianglePower(std::uint32_t t) const { return mTrianglePower[t].value(); }
    std::size_t triangleCount() const { return mTrianglePower.size(); }
    /// The most additions any triangle's sum has taken since reset() (CompensatedSum gives the
    /// bound on its rounding error).
    std::uint32_t maxUpdates() const { return mMaxUpdates; }

private:
    /// Adds sign x power to triangle `primitive` of receiver `receiver`.
    void add(std::uint32_t triangle, const glm::vec3& power, double sign);

    std::vector<glm::uvec3> mTriangles; ///< global vertex ids
    std::vector<CompensatedSum> mTrianglePower;
    std::vector<std::uint32_t> mUpdateCount; ///< per triangle, additions since reset()
    std::uint32_t mMaxUpdates = 0;
    std::vector<float> mTriangleArea;      ///< m^2
    std::vector<double> mRingArea;         ///< per vertex: sum of incident triangle areas
    std::vector<std::uint32_t> mRingStart; ///< per vertex + 1: range in mRingTriangles
    std::vector<std::uint32_t> mRingTriangles;
    std::vector<std::uint32_t> mTouchedTriangles;
    std::vector<std::uint8_t> mTriangleTouched;
    std::vector<std::uint8_t> mVertexTouched;
};

} // namespace qgi
