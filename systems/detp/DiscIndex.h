#pragma once

#include "runtime/raytrace/EmbreeHandle.h"
#include "systems/detp/DiscCrossing.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace qgi {

class EmbreeDevice;
struct PhotonSegments;

/// Read-only elements `stride` bytes apart: one field of an array of records, or a plain array.
template <typename T> struct Strided {
    const std::byte* base = nullptr;
    std::size_t stride = sizeof(T);

    Strided() = default;
    Strided(const T* first, std::size_t bytes = sizeof(T))
        : base(reinterpret_cast<const std::byte*>(first)), stride(bytes) {}
    const T& operator[](std::size_t i) const {
        return *reinterpret_cast<const T*>(base + i * stride);
    }
};

/// What a disc query reads of a set of segments: per segment its origin, unit direction and
/// length (+inf: it left the scene). A PhotonSegments converts to one, and so do the records of
/// NearSegments' copies.
struct SegmentRays {
    Strided<glm::vec3> origin, direction;
    Strided<float> length;

    SegmentRays(Strided<glm::vec3> origins, Strided<glm::vec3> directions, Strided<float> lengths)
        : origin(origins), direction(directions), length(lengths) {}
    SegmentRays(const PhotonSegments& segments); ///< implicit: every PhotonSegments is one
};

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
 *   - Plane patches: discs that lie in one plane with one normal, for which a segment needs one
 *     plane crossing, not a walk through a BVH of heavily overlapping discs. Each such plane
 *     gets a 2D grid of cells kPlaneCellRadii radii wide holding its discs, and Embree a few
 *     rectangles (two triangles each) covering the cells within one cell of a disc's,
 *     overlapping one another and across their diagonals. A segment that meets a rectangle has
 *     its crossing point looked up in the grid; the discs of the 3 x 3 cells around it (every
 *     disc within a cell's width of the point) go through crossesDisc(). Two kinds:
 *      - exact: the normal is plus or minus one axis and the centres share that axis's
 *        coordinate bit for bit (walls, floors and slabs of axis-aligned architecture: two
 *        thirds of the atrium's discs). crossesDisc() computes the same t and crossing point
 *        for every disc of the plane as the lookup does, at any angle;
 *      - tilted: any other orientation (the Cornell box's red wall and tall block, a mobile
 *        block's sides). The discs' normals and planes agree only to rounding (a refined face's
 *        vertex normals differ in their last bits), within kTiltedNormalSpread and
 *        kTiltedThicknessRadii radii. A disc's own plane then lies within a distance h of the
 *        patch's wherever the disc is (h from those spreads and the rule's float rounding), so
 *        the patch's crossing point, computed in double, lies within h / |cos| of the disc's,
 *        along the segment and across it. Where h / |cos| is at most kTiltedReachRadii radii,
 *        well inside the lookup's spare quarter radius and Embree's slack, the lookup is exact.
 *        A segment more grazing than that (|cos| below the plane's minimum cosine, about
 *        1e-3 or less) is not looked up: every disc of the plane goes through crossesDisc()
 *        when the segment meets the discs' box.
 *  Direct queries: when every disc lies in one of at most kMaxDirectPlanes planes (a room of
 *  a few walls, a block), each segment is crossed with each plane in turn and Embree is left
 *  out: Embree's fixed cost per ray is most of a query's (about 0.2 us per segment on the
 *  standard machine, with points or patches alike), and a plane costs a few nanoseconds.
 *  Tilted planes are made only for such an index: in Embree they measured slower than points
 *  (the atrium's DETP delta 9.2 -> 11.3 ms), so elsewhere tilted discs stay points.
 *  Embree's ray starts where the part of the segment that can count enters the box around the
 *  discs (computed in double), so a segment from a distant light is traced at the scene's
 *  scale. What stays is rounding, and the index is exact while it stays inside the margins:
 *   - the rule's own rounding grows with the segment origin's distance, over |cos| for a
 *     segment meeting the disc's plane at cosine cos: within Embree's 1% widening of a point
 *     disc up to about ten thousand radii from the discs, and within the quarter radius a
 *     plane's lookup has to spare up to over a hundred thousand where |cos| is 0.1 or more
 *     (a few thousand where a segment skims the plane at |cos| = 0.005);
 *   - rounding Embree's ray origin to float moves a crossing along the ray by about
 *     ulp(coordinates) / |cos| for a segment meeting a plane at cosine cos. At a segment's end
 *     the slack of kEmbreeSlack radii covers it down to |cos| of about 1e-4 at scene
 *     coordinates of a few metres and a radius of a centimetre (a photon skimming a surface at
 *     under 0.01 degrees); where two of a plane's rectangles meet, their overlap of 5% of a
 *     cell covers it down to about 1e-3. (A plane evenly covered by discs is one rectangle.)
 *  The tests check both distances, grazing landings and tilted planes, in both kinds of query.
 *
 *  Segments are traced as occlusion rays (the filter sees every candidate and nothing needs
 *  the closest hit: 15% faster than intersection rays; single rays beat 8-wide packets here
 *  by 10%), in parallel chunks of kChunkSize (oneTBB). Each chunk sorts its pairs, so the
 *  output order depends only on the input: pairs come in the order of the queried segment
 *  list, and for one segment by increasing disc. Summing per disc in output order is then
 *  deterministic whatever the thread count.
 *
 *  A moving index (a mobile's discs) groups its discs into planes again at every move(), as
 *  its faces turn and slide.
 *
 *  build() is set-up and throws; move() and collectCrossings() are for the frame, never throw
 *  and reuse their buffers (no allocation once warm, while the grouping keeps its size). Not
 *  thread safe: one query at a time. */
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
    /// Tilted planes: how far a disc's unit normal may lie from the plane's, and its centre from
    /// the plane, in radii; farther ones stay points.
    static constexpr double kTiltedNormalSpread = 1e-5;
    static constexpr double kTiltedThicknessRadii = 1e-4;
    /// Tilted planes: how far, in radii, the patch's crossing point may lie from a disc's for
    /// the lookup to be used (sets each plane's minimum cosine).
    static constexpr double kTiltedReachRadii = 0.03;
    /// Most planes a direct query crosses each segment with (see the class comment).
    static constexpr std::size_t kMaxDirectPlanes = 16;

    DiscIndex(EmbreeDevice& device, Motion motion);
    ~DiscIndex();
    DiscIndex(const DiscIndex&) = delete;
    DiscIndex& operator=(const DiscIndex&) = delete;

    /// Replaces the discs: disc i is centred on centers[i] with unit front normal normals[i].
    /// Throws qgi::Error when radius is not a positive finite number, a centre or normal is not
    /// finite, or Embree fails to build.
    void build(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
               float radius);

    /// Moves the discs built last (same count, same radius): groups them into planes anew and
    /// refits the index. Non-finite input is the caller's bug (asserted).
    void move(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals);

    /// Every pair (segment, disc) such that segment `indices[k]` of `segments` crosses the disc,
    /// in the order described in the class comment; `out` is overwritten. `beyond`, when not
    /// empty, holds one length per index: segment indices[k] then counts only the discs it
    /// crosses and a copy of it cut at length beyond[k] does not (-inf: the whole segment).
    void collectCrossings(SegmentRays segments, std::span<const std::uint32_t> indices,
                          std::vector<DiscCrossing>& out, std::span<const float> beyond = {});

    std::size_t size() const { return mCenters.size(); }
    float radius() const { return mRadius; }
    glm::vec3 center(std::uint32_t disc) const { return mCenters[disc]; }
    glm::vec3 normal(std::uint32_t disc) const { return mNormals[disc]; }
    /// Discs held in plane patches (the rest are oriented-disc points), and the patches.
    std::size_t planarDiscCount() const { return mLayout.cellDiscs.size(); }
    std::size_t planeCount() const { return mLayout.planes.size(); }
    /// Of them, the tilted ones (see the class comment).
    std::size_t tiltedPlaneCount() const;
    /// Whether queries cross each segment with the planes directly, without Embree.
    bool direct() const { return mLayout.direct; }

private:
    struct QueryContext; // RTCIntersectContext plus what the filter needs

    /// Discs sharing one plane, and the grid that holds them.
    struct Plane {
        bool tilted = false;
        // Exact planes: the normal is plus or minus `axis`.
        std::uint8_t axis = 0;     ///< the normal is plus or minus this axis
        std::uint8_t u = 1, v = 2; ///< the other two axes, the grid's columns and rows
        float coordinate = 0.f;    ///< of every centre along `axis`
        glm::vec3 normal{0.f};     ///< every one of its discs' normal, bit for bit
        // Tilted planes: x is on the plane when unitNormal . x = offset; the grid's columns and
        // rows run along uAxis and vAxis.
        glm::dvec3 unitNormal{0.0};
        double offset = 0.0;
        glm::dvec3 uAxis{0.0}, vAxis{0.0};
        /// Below this |cos| the lookup is not used: every disc is tested (see the class comment).
        double minCosine = 0.0;
        /// Around its discs, widened by a radius and Embree's slack (the grazing test).
        glm::dvec3 boxMin{0.0}, boxMax{0.0};
        // The grid, in the plane's (u, v).
        glm::dvec2 corner{0.0}; ///< (u, v) of the grid's first cell's corner
        std::uint32_t columns = 0, rows = 0;
        std::uint32_t firstCell = 0; ///< its cells' ranges start at cellStart[firstCell]
        /// Squared distance in (u, v) beyond which a disc is not tested (see considerCells).
        float reach2 = 0.f;
        std::uint32_t cellCount() const { return columns * rows; }
    };
    /// A rectangle of one plane's cells, (u, v) corners.
    struct Rectangle {
        std::uint32_t plane = 0;
        glm::dvec2 lo{0.0}, hi{0.0};
    };
    /// A direct query's first pass over the planes, all of them at once in float (one loop
    /// the compiler vectorises): which planes a segment may cross near their discs. It only
    /// leaves planes out where crossPlane() certainly finds no disc, with margins well above
    /// float rounding; crossPlane() decides on the rest as before, so the pairs are unchanged.
    /// Without it, each segment went through crossPlane() for every plane, and nine in ten of
    /// those calls ended at the facing or range test.
    struct PlaneSieve {
        static constexpr std::size_t kLanes = kMaxDirectPlanes;
        using Lanes = std::array<float, kLanes>;
        /// Each plane: its unit normal and offset (n . x = offset on the plane); the cosine at
        /// or above which no segment faces it (0: exact planes; tilted ones: `grazing`); the
        /// |cos| below which the segment is passed on untested (tilted planes test every disc
        /// there); its discs' centres' box widened by the lookup's reach.
        Lanes nx{}, ny{}, nz{}, offset{}, facing{}, grazing{};
        Lanes lowX{}, lowY{}, lowZ{}, highX{}, highY{}, highZ{};
        std::uint32_t count = 0;
        /// Bit p set: plane p may yield a disc for the segment (o, d) over t in [start, stop].
        std::uint32_t candidates(const glm::vec3& o, const glm::vec3& d, float start,
                                 float stop) const;
    };
    /// Everything derived from the discs, and the buffers Embree shares.
    struct Layout {
        /// Oriented-disc points: the disc index of each, its centre and Embree's (widened)
        /// radius, its normal (padded with one element so Embree's 16-byte loads of the last
        /// one stay inside the allocation).
        std::vector<std::uint32_t> pointIds;
        std::vector<glm::vec4> pointDiscs;
        std::vector<glm::vec3> pointNormals;
        /// Plane patches (exact ones first, then tilted ones): discs sorted by
        /// (plane, row, column), each cell's range in cellStart (one entry past the last cell),
        /// the rectangles, and Embree's triangles of them (two per rectangle; vertices in
        /// 16-byte rows).
        std::vector<Plane> planes;
        std::vector<std::uint32_t> cellStart;
        std::vector<std::uint32_t> cellDiscs;
        std::vector<glm::vec3> cellCenters;
        std::vector<glm::vec3> cellNormals;
        std::vector<glm::vec2> cellPoints; ///< (u, v) relative to the plane's grid corner
        std::vector<Rectangle> rectangles;
        std::vector<glm::vec4> patchVertices;
        std::vector<glm::uvec3> patchTriangles;
        /// Queried plane by plane, without Embree (see the class comment), planes first
        /// through the sieve.
        bool direct = false;
        PlaneSieve sieve;
        void clear();
    };
    /// What grouping uses while it works (kept to reuse its capacity).
    struct Scratch;

    /// Fills `out` from the discs: planes (tilted ones only for a direct query), their grids
    /// and (for Embree) rectangles, and the points left over.
    static void makeLayout(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
                           float radius, Layout& out, Scratch& scratch);
    /// The planes of makeLayout(), exact ones first, then tilted ones, with their grids; `out`
    /// is cleared first.
    static void groupDiscs(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
                           float radius, Layout& out, Scratch& scratch);
    /// Adds a plane holding `discs` (their (u, v) in `uv`) to `out`, with its grid; false
    /// (nothing added) when its grid would be too sparse or too large.
    static bool addPlane(Plane plane, std::span<const std::uint32_t> discs,
                         std::span<const glm::dvec2> uv, std::span<const glm::vec3> centers,
                         std::span<const glm::vec3> normals, float radius, Layout& out,
                         Scratch& scratch);
    /// The direct query's sieve over `layout`'s planes.
    static void makeSieve(float radius, Layout& layout);
    /// Embree's rectangles (and their triangles) over plane `planeIndex`'s cells near a disc.
    static void addRectangles(std::uint32_t planeIndex, float radius, Layout& out,
                              Scratch& scratch);
    /// (u, v) of a point on (or near) the plane.
    static glm::dvec2 planeCoordinates(const Plane& plane, const glm::dvec3& x);
    /// An empty Embree scene built for the index's motion.
    static SceneHandle newScene(RTCDevice device, Motion motion);
    /// Hands `layout`'s buffers to the geometries (made and attached to `scene` when null; a
    /// kind the layout has none of is left alone) and commits them and the scene.
    static void attachGeometries(RTCDevice device, RTCScene scene, Layout& layout,
                                 GeometryHandle& points, GeometryHandle& patches);
    /// Records the pair (position, disc) when segment s crosses the disc (centre, normal):
    /// the rule and the `beyond` cut, shared by both filters.
    static void consider(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                         std::uint32_t disc, const glm::vec3& center, const glm::vec3& normal);
    /// Every disc of cells [c0, c1] x [r0, r1] of a plane through consider(); with the (u, v)
    /// of the segment's crossing point, only those whose centre lies within the plane's reach
    /// of it.
    static void considerCells(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                              const Plane& plane, std::uint32_t c0, std::uint32_t c1,
                              std::uint32_t r0, std::uint32_t r1, const glm::dvec2* point);
    /// Segment s's crossing with a plane, looked up in its grid. `range`, for a direct query:
    /// the part of the segment [range[0], range[1]] that can count (Embree's ray otherwise);
    /// a tilted plane the segment grazes has every disc tested there.
    static void crossPlane(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                           const Plane& plane, const double* range);
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
    Layout mLayout;
    std::unique_ptr<Scratch> mScratch;
    /// Per chunk: the pairs it found as (position in the query << 32 | disc).
    std::vector<std::vector<std::uint64_t>> mChunkPairs;
};

} // namespace qgi
