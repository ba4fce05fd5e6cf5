#include "systems/photon_update/PhotonPathGrid.h"

#include "runtime/core/Error.h"

#include <glm/common.hpp>
#include <glm/vector_relational.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

namespace qgi {
namespace {

// Paths per chunk: re-indexing one takes a few milliseconds.
constexpr std::size_t kChunkPaths = 4096;
// Each chunk keeps an offset per cell; chunks grow past kChunkPaths where needed to keep all
// the offsets below this many.
constexpr std::size_t kMaxChunkOffsets = std::size_t(1) << 24;
// Changed paths per task when computing their extents.
constexpr std::size_t kExtentGrain = 256;

/// Coordinate of the end of origin + t direction, t in [0, length], along one axis
/// (length +inf: the ray's limit, +-inf or the origin's own coordinate).
float endCoordinate(float origin, float direction, float length) {
    if (std::isfinite(length)) return origin + length * direction;
    if (direction == 0.f) return origin;
    return direction > 0.f ? std::numeric_limits<float>::infinity()
                           : -std::numeric_limits<float>::infinity();
}

// A segment counts as reaching beyond a side when it comes within this many cells of it:
// queries are widened by as much (pathsOverlapping), so rounding never loses a path.
constexpr float kSideSlack = 2e-3f;

bool overlaps(const Aabb& a, const Aabb& b) {
    return !a.empty() && !b.empty() && glm::all(glm::lessThanEqual(a.min, b.max)) &&
           glm::all(glm::lessThanEqual(b.min, a.max));
}

} // namespace

std::uint32_t PhotonPathGrid::Marks::nextToken() {
    if (token == std::numeric_limits<std::uint32_t>::max()) {
        std::fill(mark.begin(), mark.end(), 0u);
        token = 0;
    }
    return ++token;
}

PhotonPathGrid::Marks& PhotonPathGrid::localMarks() const {
    Marks& marks = mMarks.local();
    if (marks.mark.size() != cellCount() + kSideCells) {
        marks.mark.assign(cellCount() + kSideCells, 0u);
        marks.token = 0;
    }
    return marks;
}

/// Visits the cell of every point of the straight line from a to b, both inside the closed
/// box [0, mCells] of grid space: a 3D-DDA (Amanatides and Woo) that steps each axis exactly
/// as many times as a's and b's cells differ on it, so rounding can neither skip b's cell
/// nor run past it.
template <typename Fn>
void PhotonPathGrid::walkLine(const glm::vec3& a, const glm::vec3& b, Fn& fn) const {
    const glm::ivec3 top = mCells - 1;
    const glm::ivec3 cell = glm::clamp(glm::ivec3(glm::floor(a)), glm::ivec3(0), top);
    const glm::ivec3 end = glm::clamp(glm::ivec3(glm::floor(b)), glm::ivec3(0), top);
    std::int64_t index = cellIndex(cell);
    fn(std::uint32_t(index));
    const std::int64_t strides[3] = {1, mCells.x, std::int64_t(mCells.x) * mCells.y};
    std::int64_t stride[3] = {0, 0, 0};
    int remaining[3];
    float tMax[3], tDelta[3];
    int steps = 0;
    for (int axis = 0; axis < 3; ++axis) {
        const int n = end[axis] - cell[axis];
        remaining[axis] = std::abs(n);
        steps += remaining[axis];
        tMax[axis] = tDelta[axis] = std::numeric_limits<float>::infinity();
        if (n == 0) continue; // different cells imply a[axis] != b[axis]
        const float inverse = 1.f / std::abs(b[axis] - a[axis]);
        const float boundary = float(cell[axis] + (n > 0 ? 1 : 0));
        stride[axis] = n > 0 ? strides[axis] : -strides[axis];
        tMax[axis] = std::abs(boundary - a[axis]) * inverse;
        tDelta[axis] = inverse;
    }
    for (; steps > 0; --steps) {
        // An axis with no steps left has tMax = inf and is never chosen.
        const int axis =
            tMax[0] < tMax[1] ? (tMax[0] < tMax[2] ? 0 : 2) : (tMax[1] < tMax[2] ? 1 : 2);
        index += stride[axis];
        fn(std::uint32_t(index));
        tMax[axis] = --remaining[axis] == 0 ? std::numeric_limits<float>::infinity()
                                            : tMax[axis] + tDelta[axis];
    }
}

std::uint8_t PhotonPathGrid::sidesBeyond(float a, float b, float lo, float hi, int axis) {
    std::uint8_t sides = 0;
    if (std::min(a, b) < lo) sides |= sideBit(axis, false);
    if (std::max(a, b) > hi) sides |= sideBit(axis, true);
    return sides;
}

/// Visits the cells of segments [first, first + count): the cells their part inside the box
/// crosses, and the side cell of each side of the box a segment reaches beyond.
template <typename Fn>
void PhotonPathGrid::forEachCell(const PhotonSegments& segments, std::size_t first,
                                 std::size_t count, Fn&& fn) const {
    const glm::vec3 size(mCells);
    const float inverse = 1.f / mCellSize;
    const auto inside = [&](const glm::vec3& p) {
        return p.x >= 0.f && p.y >= 0.f && p.z >= 0.f && p.x <= size.x && p.y <= size.y &&
               p.z <= size.z;
    };
    for (std::size_t s = first; s < first + count; ++s) {
        const glm::vec3 o = (segments.origin[s] - mBounds.min) * inverse;
        const glm::vec3 d = segments.direction[s] * inverse;
        const float length = segments.length[s];
        if (std::isfinite(length)) {
            const glm::vec3 end = o + length * d;
            if (inside(o) && inside(end)) { // the common case: a bounce inside the scene
                walkLine(o, end, fn);
                continue;
            }
        }
        // Clip to the box; whatever is cut off lies beyond one side or more.
        const auto [near, far] = clipToBox(o, d, 0.f, length, glm::vec3(0.f), size);
        for (int axis = 0; axis < 3; ++axis) {
            const float end = endCoordinate(o[axis], d[axis], length);
            const std::uint8_t sides =
                sidesBeyond(o[axis], end, kSideSlack, size[axis] - kSideSlack, axis);
            for (const bool high : {false, true})
                if (sides & sideBit(axis, high)) fn(outsideCell() + sideIndex(axis, high));
        }
        if (near <= far)
            walkLine(glm::clamp(o + near * d, glm::vec3(0.f), size),
                     glm::clamp(o + far * d, glm::vec3(0.f), size), fn);
    }
}

void PhotonPathGrid::indexChunk(const PhotonStore& store, Chunk& chunk) const {
    Marks& marks = localMarks();
    const std::size_t cells = cellCount() + kSideCells;
    // One walk per path: its distinct cells, counted per cell and recorded in path order; the
    // lists are then filled from the record (walking the segments again cost a third of a build).
    chunk.offsets.assign(cells + 1, 0);
    marks.pathCells.clear();
    marks.pathEnds.clear();
    for (std::uint32_t p = chunk.first; p < chunk.end; ++p) {
        const std::uint32_t token = marks.nextToken();
        const PhotonPath& path = store.paths[p];
        forEachCell(store.segments, path.first, path.count, [&](std::uint32_t cell) {
            if (marks.mark[cell] == token) return;
            marks.mark[cell] = token;
            ++chunk.offsets[cell + 1];
            marks.pathCells.push_back(cell);
        });
        marks.pathEnds.push_back(std::uint32_t(marks.pathCells.size()));
    }
    for (std::size_t c = 0; c < cells; ++c)
        chunk.offsets[c + 1] += chunk.offsets[c];
    marks.cursor.assign(chunk.offsets.begin(), chunk.offsets.end() - 1);
    const std::size_t entries = chunk.offsets[cells];
    if (entries > chunk.ids.capacity()) chunk.ids.reserve(entries + entries / 8); // not 2x
    chunk.ids.resize(entries);
    std::size_t k = 0;
    for (std::uint32_t p = chunk.first; p < chunk.end; ++p)
        for (const std::size_t end = marks.pathEnds[p - chunk.first]; k < end; ++k)
            chunk.ids[marks.cursor[marks.pathCells[k]]++] = p;
}

void PhotonPathGrid::build(const PhotonStore& store, const Aabb& bounds, std::uint32_t resolution) {
    QGI_ASSERT(!bounds.empty() && resolution > 0, "the path grid needs a box and cells");
    // A margin keeps geometry on the box's faces strictly inside it, and the query boxes
    // around what rests on them (a mobile on the floor, its DETP discs reaching r below)
    // inside the grid too, away from the side cells (which in an open scene list nearly
    // every path).
    const glm::vec3 extent0 = bounds.extent();
    const glm::vec3 margin(0.05f * std::max({extent0.x, extent0.y, extent0.z}) + 1e-4f);
    mBounds = {bounds.min - margin, bounds.max + margin};
    const glm::vec3 extent = mBounds.extent();
    mCellSize = std::max({extent.x, extent.y, extent.z}) / float(resolution);
    mCells = glm::clamp(glm::ivec3(glm::ceil(extent / mCellSize)), glm::ivec3(1),
                        glm::ivec3(int(resolution)));
    mPathCount = store.pathCount();

    // Chunks hold whole 64-bit words of the query bitmap, so queries mark them in parallel.
    const std::size_t cells = cellCount() + kSideCells + 1;
    mChunkPaths =
        std::max(kChunkPaths, (mPathCount * cells + kMaxChunkOffsets - 1) / kMaxChunkOffsets);
    mChunkPaths = (mChunkPaths + 63) / 64 * 64;
    mChunks.resize((mPathCount + mChunkPaths - 1) / mChunkPaths); // keeps the lists' memory
    for (std::size_t k = 0; k < mChunks.size(); ++k) {
        mChunks[k].first = std::uint32_t(k * mChunkPaths);
        mChunks[k].end = std::uint32_t(std::min(mPathCount, (k + 1) * mChunkPaths));
        mChunks[k].changed = 0;
    }
    tbb::parallel_for(std::size_t(0), mChunks.size(),
                      [&](std::size_t k) { indexChunk(store, mChunks[k]); });
    mChangedSlot.assign(mPathCount, kUnchanged);
    mChanged.clear();
    mChangedExtent.clear();
    mSeen.assign((mPathCount + 63) / 64, 0);
    mBuilt = true;
    mGeneration = store.generation;
}

void PhotonPathGrid::addEmptyPaths(const PhotonStore& store) {
    QGI_ASSERT(mBuilt && mGeneration == store.generation && store.pathCount() >= mPathCount,
               "the grid indexes another store");
    const std::size_t paths = store.pathCount();
    for (std::size_t p = mPathCount; p < paths; ++p)
        QGI_ASSERT(store.paths[p].count == 0, "path ", p, " was added with segments");
    // Empty paths are in no cell's list: the last chunk takes them up to its size, and new
    // chunks with empty lists the rest.
    if (!mChunks.empty())
        mChunks.back().end = std::uint32_t(std::min(paths, mChunks.back().first + mChunkPaths));
    while (mChunks.empty() ? paths > 0 : mChunks.back().end < paths) {
        Chunk& chunk = mChunks.emplace_back();
        chunk.first = mChunks.size() == 1 ? 0u : mChunks[mChunks.size() - 2].end;
        chunk.end = std::uint32_t(std::min(paths, std::size_t(chunk.first) + mChunkPaths));
        chunk.offsets.assign(cellCount() + kSideCells + 1, 0);
    }
    mChangedSlot.resize(paths, kUnchanged);
    mSeen.resize((paths + 63) / 64, 0);
    mPathCount = paths;
}

void PhotonPathGrid::clear() {
    mBuilt = false;
    mPathCount = 0;
    // Assigning empty vectors (not clearing them) hands their memory back.
    mChunks = std::vector<Chunk>();
    mChangedSlot = LargeArray<std::uint32_t>();
    mChanged = std::vector<std::uint32_t>();
    mChangedExtent = std::vector<Extent>();
    mSeen = std::vector<std::uint64_t>();
    mPicked = std::vector<std::uint32_t>();
    mMarks.clear();
}

PhotonPathGrid::Extent PhotonPathGrid::extentOf(const PhotonStore& store, std::uint32_t p) const {
    Extent extent;
    const PhotonPath& path = store.paths[p];
    for (std::size_t s = path.first; s < std::size_t(path.first) + path.count; ++s) {
        const glm::vec3& o = store.segments.origin[s];
        const glm::vec3& d = store.segments.direction[s];
        const float length = store.segments.length[s];
        const auto [near, far] = clipToBox(o, d, 0.f, length, mBounds.min, mBounds.max);
        if (near > 0.f || far < length)
            for (int axis = 0; axis < 3; ++axis)
                extent.outside |= sidesBeyond(o[axis], endCoordinate(o[axis], d[axis], length),
                                              mBounds.min[axis] + kSideSlack * mCellSize,
                                              mBounds.max[axis] - kSideSlack * mCellSize, axis);
        if (near > far) continue;
        extent.box.extend(o + near * d);
        extent.box.extend(o + far * d);
    }
    return extent;
}

void PhotonPathGrid::markChanged(const PhotonStore& store, std::span<const std::uint32_t> paths) {
    QGI_ASSERT(store.pathCount() == mPathCount, "the grid indexes another store");
    for (const std::uint32_t p : paths) {
        if (mChangedSlot[p] != kUnchanged) continue;
        mChangedSlot[p] = std::uint32_t(mChanged.size());
        mChanged.push_back(p);
        mChangedExtent.emplace_back();
        ++mChunks[p / mChunkPaths].changed;
    }
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, paths.size(), kExtentGrain),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t i = range.begin(); i < range.end(); ++i)
                              mChangedExtent[mChangedSlot[paths[i]]] = extentOf(store, paths[i]);
                      });
}

std::size_t PhotonPathGrid::refresh(const PhotonStore& store, std::size_t budget,
                                    std::size_t idleUpTo) {
    if (mChanged.size() <= idleUpTo) return 0;
    mPicked.clear();
    for (std::uint32_t k = 0; k < mChunks.size(); ++k)
        if (mChunks[k].changed > 0) mPicked.push_back(k);
    std::stable_sort(mPicked.begin(), mPicked.end(), [&](std::uint32_t a, std::uint32_t b) {
        return mChunks[a].changed > mChunks[b].changed;
    });
    std::size_t take = 0, paths = 0;
    for (; take < mPicked.size() && (take == 0 || paths < budget); ++take)
        paths += mChunks[mPicked[take]].end - mChunks[mPicked[take]].first;
    mPicked.resize(take);
    tbb::parallel_for(std::size_t(0), take,
                      [&](std::size_t i) { indexChunk(store, mChunks[mPicked[i]]); });
    for (const std::uint32_t k : mPicked) {
        Chunk& chunk = mChunks[k];
        for (std::uint32_t p = chunk.first; p < chunk.end; ++p) {
            const std::uint32_t slot = mChangedSlot[p];
            if (slot == kUnchanged) continue;
            const std::uint32_t last = mChanged.back();
            mChanged[slot] = last;
            mChangedExtent[slot] = mChangedExtent.back();
            mChangedSlot[last] = slot;
            mChanged.pop_back();
            mChangedExtent.pop_back();
            mChangedSlot[p] = kUnchanged;
        }
        chunk.changed = 0;
    }
    return paths;
}

void PhotonPathGrid::pathsOverlapping(const Aabb& box, std::vector<std::uint32_t>& out) const {
    pathsOverlapping(std::span<const Aabb>(&box, 1), out);
}

void PhotonPathGrid::pathsOverlapping(std::span<const Aabb> boxes,
                                      std::vector<std::uint32_t>& out) const {
    out.clear();
    if (mPathCount == 0) return;
    const std::lock_guard lock(mQueryMutex);
    const auto see = [&](std::uint32_t path) {
        mSeen[path >> 6] |= std::uint64_t(1) << (path & 63);
    };
    // Widened by a sliver of a cell: the walk may put a point that lies within rounding
    // distance of a cell face into the neighbouring cell.
    const float widen = 1e-3f * mCellSize;
    const glm::ivec3 top = mCells - 1;
    const auto cellOf = [&](const glm::vec3& p) {
        const glm::vec3 g =
            glm::clamp((p - mBounds.min) / mCellSize, glm::vec3(-1.f), glm::vec3(mCells) + 1.f);
        return glm::clamp(glm::ivec3(glm::floor(g)), glm::ivec3(0), top);
    };
    mQueries.clear();
    for (const Aabb& box : boxes) {
        if (box.empty()) continue;
        Query& q = mQueries.emplace_back();
        q.wide = {box.min - widen, box.max + widen};
        for (int axis = 0; axis < 3; ++axis)
            q.outside |= sidesBeyond(q.wide.min[axis], q.wide.max[axis], mBounds.min[axis],
                                     mBounds.max[axis], axis);
        q.lo = cellOf(q.wide.min);
        q.hi = cellOf(q.wide.max);
    }
    // The ranges of cells to read in every chunk: a row along x (consecutive cells) per (y, z)
    // of each query box, and the side cells it reaches; merged, so that a cell two boxes share
    // (a mobile's old and new boxes share nearly all) is read once.
    mRanges.clear();
    for (const Query& q : mQueries) {
        for (int z = q.lo.z; z <= q.hi.z; ++z)
            for (int y = q.lo.y; y <= q.hi.y; ++y)
                mRanges.push_back({cellIndex({q.lo.x, y, z}), cellIndex({q.hi.x, y, z}) + 1});
        for (int side = 0; side < int(kSideCells); ++side)
            if (q.outside & (1u << side))
                mRanges.push_back({outsideCell() + side, outsideCell() + side + 1});
    }
    std::sort(mRanges.begin(), mRanges.end());
    std::size_t merged = 0;
    for (const auto& range : mRanges) {
        if (merged > 0 && range.first <= mRanges[merged - 1].second)
            mRanges[merged - 1].second = std::max(mRanges[merged - 1].second, range.second);
        else
            mRanges[merged++] = range;
    }
    mRanges.resize(merged);
    // Chunks cover whole words of mSeen: one task per chunk, no two write the same word.
    // Isolated: while it waits, this thread (holding the lock) must not pick up an outer
    // task that queries again.
    tbb::this_task_arena::isolate([&] {
        tbb::parallel_for(std::size_t(0), mChunks.size(), [&](std::size_t k) {
            const Chunk& chunk = mChunks[k];
            for (const auto& [first, end] : mRanges)
                for (std::uint32_t e = chunk.offsets[first]; e < chunk.offsets[end]; ++e)
                    see(chunk.ids[e]);
        });
    });
    for (std::size_t i = 0; i < mChanged.size(); ++i)
        for (const Query& q : mQueries)
            if ((q.outside & mChangedExtent[i].outside) != 0 ||
                overlaps(mChangedExtent[i].box, q.wide)) {
                see(mChanged[i]);
                break;
            }
    for (std::size_t w = 0; w < mSeen.size(); ++w) {
        for (std::uint64_t bits = mSeen[w]; bits != 0; bits &= bits - 1)
            out.push_back(std::uint32_t(w * 64 + std::size_t(std::countr_zero(bits))));
        mSeen[w] = 0;
    }
}

std::size_t PhotonPathGrid::entryCount() const {
    std::size_t entries = 0;
    for (const Chunk& chunk : mChunks)
        entries += chunk.ids.size();
    return entries;
}

std::size_t PhotonPathGrid::memoryBytes() const {
    std::size_t bytes = mChangedSlot.capacity() * sizeof(std::uint32_t) +
                        mChanged.capacity() * sizeof(std::uint32_t) +
                        mChangedExtent.capacity() * sizeof(Extent) +
                        mSeen.capacity() * sizeof(std::uint64_t);
    for (const Chunk& chunk : mChunks)
        bytes += (chunk.offsets.capacity() + chunk.ids.capacity()) * sizeof(std::uint32_t);
    for (const Marks& marks : mMarks)
        bytes += (marks.mark.capacity() + marks.cursor.capacity() + marks.pathCells.capacity() +
                  marks.pathEnds.capacity()) *
                 sizeof(std::uint32_t);
    return bytes;
}

} // namespace qgi
