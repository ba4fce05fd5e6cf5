#pragma once

#include "runtime/core/LargeArray.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonStore.h"

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <oneapi/tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <cstdint>
#include <mutex>
#include <span>
#include <utility>
#include <vector>

namespace qgi {

/// A moving object's neighbourhood box reaches at least this many of its last move past what
/// it needs now (neighbourhoodBox).
inline constexpr float kNeighbourhoodMotionFrames = 8.f;

/// What is kept near a moving object (neighbourhoodBox) is dropped once it has been still for
/// this many frames.
inline constexpr std::uint32_t kNearIdleFrames = 16;

/** The box a moving object keeps what lies near it over (DETP's NearSegments, the photon
 *  update's near paths), so that the frames that follow need no path-grid query while what
 *  they need stays inside it: `need` widened on every side by `share` of its largest side, or
 *  by kNeighbourhoodMotionFrames times `lastMove` (the object's last displacement) when that
 *  is more but no more than the largest side (a longer jump is not steady motion).        */
inline Aabb neighbourhoodBox(const Aabb& need, float share, const glm::vec3& lastMove) {
    const glm::vec3 size = need.extent();
    const float largest = std::max({size.x, size.y, size.z});
    float margin = share * largest;
    const float motion = kNeighbourhoodMotionFrames * glm::length(lastMove);
    if (motion <= largest) margin = std::max(margin, motion);
    Aabb box = need;
    box.min -= glm::vec3(margin);
    box.max += glm::vec3(margin);
    return box;
}

/** World resource: which photon paths pass through which part of space, so that finding the
 *  paths a moved mobile may touch costs in proportion to the paths near it, not to the ray set.
 *
 *  A uniform grid of cubic cells over the scene box (enlarged by a margin); each cell lists
 *  the paths with a segment crossing it (a 3D-DDA walk of each segment, one entry per path and
 *  cell). Six more cells stand for what lies outside the box, one per side of each axis: the
 *  side cell "below y" lists the paths with a segment reaching below the box's bottom face
 *  (escaping photons, light from outside), and a query box that pokes below that face gets it
 *  too, so queries are supersets anywhere in space. One cell per side rather than one for all
 *  outside: in an open scene nearly every path escapes through the sky, and a mobile resting
 *  on the floor near the box's bottom face must not be handed all of them.
 *
 *  Re-traced paths: walking a re-traced path's old and new cells every frame costs more than
 *  re-tracing it, so a path that changes is only marked *changed*, with the bounding box of
 *  its new segments: queries return it when its box overlaps, whatever the cells say. The
 *  paths are indexed in fixed chunks (consecutive path ids, each chunk its own cell lists);
 *  refresh() re-indexes the chunks holding the most of them within a per-frame budget, and
 *  their paths become unchanged again. No frame ever rebuilds the whole grid.
 *
 *  Memory: 4 bytes per (path, cell) entry; 4 bytes per cell and chunk (chunks are sized at
 *  build so that this stays below 64 MiB; paths added since add chunks of that size, up to
 *  kMaxPhotonGrowth times as many); 32 bytes per changed path and 4 per path; one bit per path
 *  and, per thread, 4 bytes per cell of working marks and 4 per entry of the chunk it
 *  indexes. Queries are thread safe (they serialise on a mutex); build, markChanged and
 *  refresh are not.                                                                         */
class PhotonPathGrid {
public:
    /// Indexes every path of `store` over `bounds` with `resolution` cells along its longest
    /// axis. Parallel.
    void build(const PhotonStore& store, const Aabb& bounds, std::uint32_t resolution);

    /// Empties the grid and frees its memory: it then indexes no store (indexes() is false).
    void clear();

    /// Whether the grid indexes `store`'s current ray set: built from it since its last full
    /// shot (PhotonStore::generation), and kept up to date since (markChanged and
    /// addEmptyPaths: the photon update, the store's only writer, reports every path it
    /// changes or adds). A consumer that finds
    /// it false must treat every path as a candidate.
    bool indexes(const PhotonStore& store) const {
        return mBuilt && mGeneration == store.generation && mPathCount == store.pathCount();
    }

    /// Takes in the paths appended to `store` since the grid last saw it, which must still be
    /// empty (no segments): a light added in play, whose photons are shot later and marked
    /// changed then. Costs in proportion to the new paths.
    void addEmptyPaths(const PhotonStore& store);

    /// Marks `paths` changed (their segments in `store` are new): until their chunk is
    /// re-indexed, queries test them by the bounding box of their current segments.
    void markChanged(const PhotonStore& store, std::span<const std::uint32_t> paths);

    /// When more than `idleUpTo` paths are changed, re-indexes the chunks with the most
    /// changed paths, about `budget` paths in all (at least one chunk). Parallel. Returns the
    /// paths re-indexed.
    std::size_t refresh(const PhotonStore& store, std::size_t budget, std::size_t idleUpTo);

    /// Every path that may have a segment intersecting `box` (a superset), each once, in
    /// increasing order; replaces the contents of `out`.
    void pathsOverlapping(const Aabb& box, std::vector<std::uint32_t>& out) const;
    /// The same for the union of several boxes.
    void pathsOverlapping(std::span<const Aabb> boxes, std::vector<std::uint32_t>& out) const;

    const Aabb& bounds() const { return mBounds; }
    glm::ivec3 resolution() const { return mCells; }
    float cellSize() const { return mCellSize; }
    std::size_t pathCount() const { return mPathCount; }
    std::size_t changedPathCount() const { return mChanged.size(); }
    std::size_t entryCount() const;
    std::size_t memoryBytes() const;

private:
    /// Paths [first, end) with their own cell lists: cell c's paths are
    /// ids[offsets[c], offsets[c + 1]), in increasing order.
    struct Chunk {
        std::uint32_t first = 0, end = 0;
        std::uint32_t changed = 0; ///< of its paths, how many are marked changed
        std::vector<std::uint32_t> offsets;
        LargeArray<std::uint32_t> ids;
    };
    /// One thread's scratch for walking paths.
    struct Marks {
        std::vector<std::uint32_t> mark; ///< per cell: token of the last path that saw it
        std::vector<std::uint32_t> cursor;
        /// indexChunk: each path's distinct cells in path order, and where each path's end.
        std::vector<std::uint32_t> pathCells, pathEnds;
        std::uint32_t token = 0;
        std::uint32_t nextToken();
    };
    /// A query box, widened, with its range of cells.
    struct Query {
        Aabb wide;
        glm::ivec3 lo{0}, hi{0};
        std::uint8_t outside = 0; ///< the sides of the grid box it reaches beyond (sideBit)
    };
    /// A changed path's segments' extent: clipped to the grid box, plus the sides of the box
    /// that any part of them reaches beyond (sideBit).
    struct Extent {
        Aabb box;
        std::uint8_t outside = 0;
    };
    /// Bit of side (axis, high) in the masks above; its cell is outsideCell() + that index.
    static constexpr int sideIndex(int axis, bool high) { return 2 * axis + (high ? 1 : 0); }
    static constexpr std::uint8_t sideBit(int axis, bool high) {
        return std::uint8_t(1u << sideIndex(axis, high));
    }
    /// Sides of the box [lo, hi] that the coordinate range [a, b] (either order; infinite
    /// ends allowed) reaches beyond along `axis`.
    static std::uint8_t sidesBeyond(float a, float b, float lo, float hi, int axis);

    template <typename Fn>
    void forEachCell(const PhotonSegments& segments, std::size_t first, std::size_t count,
                     Fn&& fn) const;
    template <typename Fn> void walkLine(const glm::vec3& a, const glm::vec3& b, Fn& fn) const;
    void indexChunk(const PhotonStore& store, Chunk& chunk) const;
    Extent extentOf(const PhotonStore& store, std::uint32_t path) const;
    std::uint32_t cellIndex(const glm::ivec3& c) const {
        return std::uint32_t((c.z * mCells.y + c.y) * mCells.x + c.x);
    }
    /// Cells of the box; the six side cells come after them.
    std::size_t cellCount() const { return std::size_t(mCells.x) * mCells.y * mCells.z; }
    static constexpr std::size_t kSideCells = 6;
    std::uint32_t outsideCell() const { return std::uint32_t(cellCount()); }
    Marks& localMarks() const;

    static constexpr std::uint32_t kUnchanged = 0xffffffffu;

    bool mBuilt = false;
    std::uint64_t mGeneration = 0; ///< PhotonStore::generation of the store it indexes
    Aabb mBounds;
    glm::ivec3 mCells{0};
    float mCellSize = 1.f;
    std::size_t mPathCount = 0;
    std::size_t mChunkPaths = 1;
    std::vector<Chunk> mChunks;
    LargeArray<std::uint32_t> mChangedSlot;  ///< per path: its index in mChanged, or kUnchanged
    std::vector<std::uint32_t> mChanged;     ///< the changed paths
    std::vector<Extent> mChangedExtent;      ///< and their extents
    std::vector<std::uint32_t> mPicked;      ///< refresh's working list of chunks

    mutable tbb::enumerable_thread_specific<Marks> mMarks;
    mutable std::mutex mQueryMutex;
    mutable std::vector<std::uint64_t> mSeen; ///< one bit per path, clear between queries
    /// A query's ranges of cells [first, end), merged; the same in every chunk.
    mutable std::vector<std::pair<std::uint32_t, std::uint32_t>> mRanges;
    mutable std::vector<Query> mQueries;
};

} // namespace qgi
