#pragma once

#include "runtime/core/LargeArray.h"
#include "runtime/ecs/Entity.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <limits>
#include <span>
#include <utility>
#include <vector>

namespace qgi {

/// Path segments as a structure of arrays. Segment s of the store is
/// `origin[s] + t * direction[s]` for t in [0, length[s]]; it carries `power[s]` watts.
/// A segment that leaves the scene has length = +inf and a null hitEntity: DETP counts rays
/// that cross a disc and hit nothing, so those are stored too.
struct PhotonSegments {
    LargeArray<glm::vec3> origin;           ///< metres, world space
    LargeArray<glm::vec3> direction;        ///< unit, world space
    LargeArray<float> length;               ///< metres to the hit; +inf: left the scene
    LargeArray<glm::vec3> power;            ///< W, linear RGB, carried along the segment
    LargeArray<Entity> hitEntity;           ///< mesh entity hit; null: left the scene
    LargeArray<std::uint32_t> hitPrimitive; ///< triangle index in the entity's Mesh
    /// 0: leaves the light; k: after k reflections. In a PhotonStore, segment k of a path
    /// has bounce k (paths start at their light and are re-traced from a stored segment).
    LargeArray<std::uint8_t> bounce;

    /// Bytes one segment occupies across the arrays (the SoA row): 53.
    static constexpr std::size_t kBytesPerSegment = 3 * sizeof(glm::vec3) + sizeof(float) +
                                                    sizeof(Entity) + sizeof(std::uint32_t) +
                                                    sizeof(std::uint8_t);
    static_assert(kBytesPerSegment == 53, "the documents quote 53 bytes per segment");

    std::size_t size() const { return origin.size(); }
    void clear();
    void reserve(std::size_t n);
    void resize(std::size_t n);
    /// Appends segment `s` of `from`.
    void appendFrom(const PhotonSegments& from, std::size_t s);
    /// Overwrites segments [to, to + count) with segments [first, first + count) of `from`
    /// (already sized; `from` may be this object when the ranges do not overlap).
    void copyFrom(std::size_t to, const PhotonSegments& from, std::size_t first, std::size_t count);
};

/// One photon's path: segments [first, first + count) of PhotonStore::segments.
struct PhotonPath {
    std::uint32_t first = 0;
    std::uint16_t count = 0;
    std::uint16_t light = 0; ///< index into PhotonStore::lights
};

/// An emitter as the photon tracer saw it when it shot (for bookkeeping and tests).
struct PhotonLight {
    Entity entity;
    glm::vec3 power{0.f}; ///< W emitted, linear RGB
    std::uint32_t photonCount = 0;
    /// The renderer draws this light's direct light in hybrid mode, so its photons' first
    /// segments are not counted there: a point, spot or directional light, or an emissive
    /// surface with a LightStandIn at its place (see PhotonEmitter::directDrawn).
    bool directDrawn = false;
};

/** World resource: the stored photon ray set (seed 000 section 2.2).
 *  Photon i's path is `paths[i]`; its segments are contiguous in `segments` (none for a photon
 *  of a light switched off or removed). Lights given photons in play take those other lights no
 * longer need, or append them: paths (and lights) only grow between full shots. A re-traced path is
 * rewritten in place when it fits its old range, otherwise moved; what it leaves behind is garbage,
 * reclaimed a few regions a frame (PhotonStoreSpace). Segments between paths hold nothing, and
 * segment indices are not stable across frames: walk paths, and refer to segments as (path, k).
 *  Written by PhotonUpdateSystem only; everything else reads it.                         */
struct PhotonStore {
    PhotonSegments segments;
    LargeArray<PhotonPath> paths; ///< one per emitted photon, index = photon index
    std::vector<PhotonLight> lights;
    glm::vec3 emittedPower{0.f};  ///< sum of lights[].power, W
    std::uint64_t generation = 0; ///< bumped whenever the whole set is re-shot

    std::size_t pathCount() const { return paths.size(); }
    std::size_t segmentIndex(std::uint32_t path, std::uint32_t k) const {
        return std::size_t(paths[path].first) + k;
    }
};

/** Calls fn(i) for i in [begin, end), in order, while asking the memory system ahead of time
 *  for what it will read: the record of path candidates[i + 16] and the first segment's
 *  origin, direction, length and hit entity of path candidates[i + 8]. Walks over paths
 *  scattered through a store of hundreds of MiB wait on memory, not arithmetic; with the
 *  loads requested early they overlap (atrium: the moved mobiles' DETP walk 21 -> 16 ms). */
template <typename Fn>
void walkPathsPrefetched(const PhotonStore& store, std::span<const std::uint32_t> candidates,
                         std::size_t begin, std::size_t end, Fn&& fn) {
    constexpr std::size_t kRecordAhead = 16, kSegmentAhead = 8;
    for (std::size_t i = begin; i < end; ++i) {
        if (i + kRecordAhead < end) __builtin_prefetch(&store.paths[candidates[i + kRecordAhead]]);
        if (i + kSegmentAhead < end) {
            const std::size_t s = store.paths[candidates[i + kSegmentAhead]].first;
            __builtin_prefetch(&store.segments.origin[s]);
            __builtin_prefetch(&store.segments.direction[s]);
            __builtin_prefetch(&store.segments.length[s]);
            __builtin_prefetch(&store.segments.hitEntity[s]);
        }
        fn(i);
    }
}

/// A kept segment whose landing point stayed put but now lies on another triangle of the same
/// flat mobile face (it slid under it): only the triangle index changed. Segment k of `path`.
struct PhotonRelabel {
    std::uint32_t path = 0, k = 0;
    std::uint32_t oldPrimitive = 0, newPrimitive = 0;
};

/** This frame's change to the ray set (seed 000 sections 2.3-2.4): for each affected path,
 *  the suffix it had before (from its first affected segment on) and the suffix it has now.
 *  The head segments of an old and a new suffix share origin, direction and power.
 *  `full` means the whole set was (re)built this frame: consumers re-estimate everything.   */
struct PhotonDelta {
    bool full = false;
    std::vector<std::uint32_t> paths;    ///< affected path (photon) indices
    PhotonSegments oldSegments;          ///< concatenated old suffixes
    PhotonSegments newSegments;          ///< concatenated new suffixes
    std::vector<std::uint32_t> oldFirst; ///< per affected path: start in oldSegments (+1 entry)
    std::vector<std::uint32_t> newFirst; ///< per affected path: start in newSegments (+1 entry)
    std::vector<Entity> movedMobiles;    ///< the mobiles whose move caused the change
    /// Kept segments that changed only their hit triangle (estimators that count per triangle
    /// need them; geometry-based ones do not).
    std::vector<PhotonRelabel> relabels;
    /// Which photon update made it: 1, 2, ... one per update (kept by clear()); 0 for a delta
    /// made by hand. A consumer that sees the same number twice has nothing new; one that sees
    /// a number skipped missed a change and must re-estimate in full.
    std::uint64_t sequence = 0;

    bool empty() const { return !full && paths.empty() && relabels.empty(); }
    void clear();
    /// Delta path i's first replaced segment: k of the first of its old or new suffix
    /// (segment k of a stored path has bounce k); -1 when both suffixes are empty.
    std::int32_t head(std::size_t i) const {
        if (oldFirst[i] < oldFirst[i + 1]) return oldSegments.bounce[oldFirst[i]];
        if (newFirst[i] < newFirst[i + 1]) return newSegments.bounce[newFirst[i]];
        return -1;
    }
};

/// Reads each PhotonDelta once, by its sequence, for a consumer that applies deltas to sums of
/// its own: a delta seen before has nothing new (the photon update skipped a frame), and after
/// one was missed (the consumer skipped a frame) the consumer must re-estimate in full.
/// Hand-made deltas (sequence 0) are always new, and so is a full one: re-estimating in full
/// twice costs time, while skipping one (a PhotonDelta made anew, numbered from 1 again, in a
/// registry whose consumers read 1 before) would keep sums of a ray set that is gone.
class PhotonDeltaReader {
public:
    enum class News { Fresh, Repeated, AfterGap };
    News read(const PhotonDelta& delta) {
        if (delta.sequence == 0) return News::Fresh;
        const std::uint64_t last = std::exchange(mLast, delta.sequence);
        if (delta.full) return News::Fresh;
        if (delta.sequence == last) return News::Repeated;
        return last != 0 && delta.sequence != last + 1 ? News::AfterGap : News::Fresh;
    }

private:
    std::uint64_t mLast = 0; ///< the sequence last read (0: none)
};

} // namespace qgi
