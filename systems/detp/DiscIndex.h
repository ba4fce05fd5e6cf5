#pragma once

#include "runtime/raytrace/EmbreeHandle.h"
#include "systems/detp/DiscCrossing.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

class EmbreeDevice;
struct PhotonSegments;

/** Finds every (segment, disc) pair that crossesDisc() accepts, for many discs of one radius
 *  (seed 000 section 2.7, disc indexing), with Embree.
 *
 *  Two kinds of primitive share one Embree scene, each with a filter that applies the exact
 *  crossesDisc() rule to every candidate, records the pair and rejects the hit so traversal goes
 *  on. The result is therefore exactly the brute-force set.
 *   - Oriented-disc points, one per disc. Embree sees each disc 1% wider and each segment
 *     kEmbreeSlack radii longer at both ends, so rounding in its own disc test can only add
 *     candidates, never lose one. Discs are two-sided in Embree: the front-side rule is the
 *     filter's.
 *   - Plane patches (Motion::Static only). Discs whose normal is exactly plus or minus one axis
 *     and whose centres share that axis's coordinate bit for bit (walls, floors and slabs of
 *     axis-aligned architecture: two thirds of the atrium's discs) lie in one plane. For those,
 *     crossesDisc() computes the same t and crossing point for every disc of the plane, so a
 *     segment needs one plane crossing, not a walk through a BVH of heavily overlapping discs.
 *     Each such plane gets a 2D grid of cells kPlaneCellRadii radii wide holding its discs, and
 *     Embree a few rectangles (two triangles each) covering the cells within one cell of a
 *     disc's, overlapping one another and across their diagonals. A segment that
 *     meets a rectangle has its crossing point looked up in the grid; the discs of the 3 x 3
 *     cells around it (every disc within a cell's width of the point) go through crossesDisc().
 *  Embree's ray starts where the part of the segment that can count enters the box around the
 *  discs (computed in double), so a segment from a distant light is traced at the scene's
 *  scale. What stays is rounding, and the index is exact while it stays inside the margins:
 *   - the rule's own rounding grows with the segment origin's distance: within Embree's 1%
 *     widening of a point disc up to about ten thousand radii from the discs, and within the
 *     quarter radius a plane's lookup has to spare up to over a hundred thousand;
 *   - rounding Embree's ray origin to float moves a crossing along the ray by about
 *     ulp(coordinates) / |cos| for a segment meeting a plane at cosine cos. At a segment's end
 *     the slack of kEmbreeSlack radii covers it down to |cos| of about 1e-4 at scene
 *     coordinates of a few metres and a radius of a centimetre (a photon skimming a surface at
 *     under 0.01 degrees); where two of a plane's rectangles meet, their overlap of 5% of a
 *     cell covers it down to about 1e-3. (A plane evenly covered by discs is one rectangle.)
 *  The tests check both distances and grazing landings.
 *
 *  Segments are traced as occlusion rays (the filter sees every candidate and nothing needs
 *  the closest hit: 15% faster than intersection rays; single rays beat 8-wide packets here
 *  by 10%), in parallel chunks of kChunkSize (oneTBB). Each chunk sorts its pairs, so the
 *  output order depends only on the input: pairs come in the order of the queried segment
 *  list, and for one segment by increasing disc. Summing per disc in output order is then
 *  deterministic whatever the thread count.
 *
 *  build() is set-up and throws; move() and collectCrossings() are for the frame, never throw
 *  and reuse their buffers (no allocation once warm). Not thread safe: one query at a time. */
class DiscIndex {
public:
    enum class Motion {
        Static, ///< built once: the best BVH Embree can make
        Moving, ///< moved every few frames (a mobile's discs): fast rebuilds
    };

    /// Longest chunk of segments one task traces.
    static constexpr std::size_t kChunkSize = 256;
    /// Extension of each Embree segment at both ends, in disc radii (see the class comment).
    static constexpr float kEmbreeSlack = 0.05f;
    /// Width of a plane patch's grid cell, in disc radii: more than one, so that the 3 x 3
    /// cells around a crossing point hold every disc within a radius of it, with a quarter
    /// radius to spare for rounding.
    static constexpr float kPlaneCellRadii = 1.25f;
    /// Fewest discs a plane needs to become a patch; fewer stay oriented-disc points.
    static constexpr std::size_t kMinPlaneDiscs = 16;

    DiscIndex(EmbreeDevice& device, Motion motion);
    DiscIndex(const DiscIndex&) = delete;
    DiscIndex& operator=(const DiscIndex&) = delete;

    /// Replaces the discs: disc i is centred on centers[i] with unit front normal normals[i].
    /// Throws qgi::Error when radius is not a positive finite number, a centre or normal is not
    /// finite, or Embree fails to build.
    void build(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
               float radius);

    /// Moves the discs built last (same count, same radius) and refits the index. Non-finite
    /// input is the caller's bug (asserted).
    void move(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals);

    /// Every pair (segment, disc) such that segment `indices[k]` of `segments` crosses the disc,
    /// in the order described in the class comment; `out` is overwritten. `beyond`, when not
    /// empty, holds one length per index: segment indices[k] then counts only the discs it
    /// crosses and a copy of it cut at length beyond[k] does not (-inf: the whole segment).
    void collectCrossings(const PhotonSegments& segments, std::span<const std::uint32_t> indices,
                          std::vector<DiscCrossing>& out,
                          std::span<const float> beyond = {});

    std::size_t size() const { return mCenters.size(); }
    float radius() const { return mRadius; }
    glm::vec3 center(std::uint32_t disc) const { return mCenters[disc]; }
    glm::vec3 normal(std::uint32_t disc) const { return mNormals[disc]; }
    /// Discs held in plane patches (the rest are oriented-disc points), and the patches.
    std::size_t planarDiscCount() const { return mCellDiscs.size(); }
    std::size_t planeCount() const { return mPlanes.size(); }

private:
    struct QueryContext; // RTCIntersectContext plus what the filter needs

    /// Discs sharing one axis-aligned plane, and the grid that holds them.
    struct Plane {
        std::uint8_t axis = 0;     ///< the normal is plus or minus this axis
        std::uint8_t u = 1, v = 2; ///< the other two axes, the grid's columns and rows
        float coordinate = 0.f;    ///< of every centre along `axis`
        glm::vec3 normal{0.f};     ///< every one of its discs' normal, bit for bit
        glm::vec2 corner{0.f};     ///< (u, v) of the grid's first cell's corner
        std::uint32_t columns = 0, rows = 0;
        std::uint32_t firstCell = 0; ///< its cells' ranges start at mCellStart[firstCell]
    };
    /// A rectangle of one plane's cells, (u, v) corners.
    struct Rectangle {
        std::uint32_t plane = 0;
        glm::vec2 lo{0.f}, hi{0.f};
    };
    /// What build() makes before anything is committed (so a failure changes nothing).
    struct Layout;

    static void splitIntoPlanes(std::span<const glm::vec3> centers,
                                std::span<const glm::vec3> normals, float radius, Layout& out);
    /// Records the pair (position, disc) when segment s crosses the disc (centre, normal):
    /// the rule and the `beyond` cut, shared by both filters.
    static void consider(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                         std::uint32_t disc, const glm::vec3& center, const glm::vec3& normal);
    static void recordCrossings(const RTCFilterFunctionNArguments* args);
    static void recordPlaneCrossings(const RTCFilterFunctionNArguments* args);
    void traceChunk(const QueryContext& query, std::size_t chunk);
    /// mBoxMin/mBoxMax from the centres (build(), move()).
    void updateBox();

    EmbreeDevice& mDevice;
    Motion mMotion;
    SceneHandle mScene;
    GeometryHandle mGeometry;      ///< oriented-disc points
    GeometryHandle mPlaneGeometry; ///< the patches' rectangles (triangles)
    float mRadius = 0.f;
    /// Around every disc, with room for the widening and the segments' slack (traceChunk).
    glm::dvec3 mBoxMin{0.0}, mBoxMax{0.0};
    std::vector<glm::vec3> mCenters; ///< every disc, by disc index
    std::vector<glm::vec3> mNormals;
    /// Embree's buffers, shared: centre and Embree's (widened) radius of each point disc;
    /// normals padded with one element so Embree's 16-byte loads of the last one stay inside
    /// the allocation; the disc index of each point.
    std::vector<glm::vec4> mPointDiscs;
    std::vector<glm::vec3> mPointNormals;
    std::vector<std::uint32_t> mPointIds;
    /// Plane patches: discs sorted by (plane, row, column), each cell's range in
    /// mCellStart (one entry past the last cell), the rectangles, and Embree's triangles of
    /// them (two per rectangle; vertices in 16-byte rows).
    std::vector<Plane> mPlanes;
    std::vector<std::uint32_t> mCellStart;
    std::vector<std::uint32_t> mCellDiscs;
    std::vector<glm::vec3> mCellCenters;
    std::vector<Rectangle> mRectangles;
    std::vector<glm::vec4> mPatchVertices;
    std::vector<glm::uvec3> mPatchTriangles;
    /// Per chunk: the pairs it found as (position in the query << 32 | disc).
    std::vector<std::vector<std::uint64_t>> mChunkPairs;
};

} // namespace qgi
