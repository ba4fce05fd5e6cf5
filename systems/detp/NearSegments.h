#pragma once

#include "runtime/ecs/Entity.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/detp/DiscIndex.h"

#include <glm/vec3.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

struct PhotonDelta;
struct PhotonStore;

/** This frame's PhotonDelta arranged by path, once for every NearSegments::apply().   */
struct DeltaByPath {
    /// Delta path indices (into PhotonDelta::paths) in increasing path order; those whose old
    /// and new suffixes are both empty are left out (nothing of theirs changed).
    std::vector<std::uint32_t> order;
    /// Per delta path: k of the first segment its suffixes replace (segment k has bounce k).
    std::vector<std::uint32_t> head;

    void arrange(const PhotonDelta& delta);
};

/** A copy of every stored segment near one mobile, kept up to date from frame to frame.
 *
 *  Re-estimating a moved mobile in full needs every stored segment that reaches its discs.
 *  Found afresh at each move, that is a path-grid query and a walk over the candidate paths'
 *  segments, scattered through a store of hundreds of MiB: the walk waits on memory, and it
 *  was most of the atrium's mobile stage. A mobile that moves a little each frame needs
 *  nearly the same segments each frame, so this copies, once, every stored segment that meets
 *  a box somewhat wider than the mobile's reach (with the same tail past the segment's end),
 *  and follows each frame's PhotonDelta: a re-traced path's replaced segments leave, its new
 *  ones that meet the box come in. While the mobile's reach stays inside the box, a move
 *  reads the copy, in order, instead of the store.
 *
 *  The copies are kept in (path, k) order, the order in which a walk over the paths in
 *  increasing order meets them, so a mobile's sums come out the same bit for bit either way.
 *  What the copy holds is what the walk that made it found (the path grid's candidates, whose
 *  cells a segment's own extent decides) and what deltas brought since: a segment that meets
 *  the box only through its tail, past its end, may be missing. None such crosses a disc, since
 *  the reach box holds the end of every segment that crosses one (DetpIrradianceSystem::
 *  discBounds), so the sums do not change. A path's light is copied too: it can change without
 *  a delta only where a light's photons are handed to a ghost, which keeps its directDrawn, or
 *  where empty ranges (no segments, nothing copied) are handed on.
 *  52 bytes per copy: a 44-byte record (origin, direction, power, length, k, a flag, light)
 *  and its key (path and k), which apply() scans alone. Not thread safe. */
class NearSegments {
public:
    /// A segment the walk found: store segment `segment`, of path `path`.
    struct Pick {
        std::uint32_t path = 0;
        std::uint32_t segment = 0;
    };

    bool valid() const { return mValid; }
    /// Whether the copy holds every stored segment that meets `box` with the copy's tail.
    bool covers(const Aabb& box) const;
    std::size_t size() const { return mKey.size(); }
    /// Whether deltas have doubled it since it was made (paths re-traced into its box while
    /// those that left stay out: a grown copy is made anew, and its worth judged again).
    bool outgrown() const { return size() > 2 * mMade + 4096; }
    /// Drops the copy and frees its memory.
    void clear();

    /// Replaces the copy: `picks` are every stored segment that meets `box` with `tail` metres
    /// added to its length, in (path, k) order. The segments that start on `mobile` (the
    /// previous segment of their path hit it) are flagged: select() may skip them. Parallel.
    void build(const PhotonStore& store, const Aabb& box, float tail, Entity mobile,
               std::span<const Pick> picks);

    /// Brings the copy up to date with this frame's delta (`byPath` arranged from it): each
    /// delta path's copies from its head on leave, and its new suffix's segments that meet the
    /// box come in. `prefixEnd` and `light`: per delta path, what its new suffix starts on (the
    /// hit of its kept prefix's last segment; null for a path shot from its light) and its
    /// light. `scratch` is working memory, swapped with this copy when anything changed.
    void apply(const PhotonDelta& delta, const DeltaByPath& byPath,
               std::span<const Entity> prefixEnd, std::span<const std::uint16_t> light,
               NearSegments& scratch);

    /// Replaces `out` with the copies (indices into rays() and power()) that meet `box` with
    /// the tail, in order, leaving out those that start on the mobile when `skipLeaving`, and
    /// the first segments of paths whose light `countsFirst(light)` says do not count.
    /// Parallel.
    template <typename CountsFirst>
    void select(const Aabb& box, bool skipLeaving, CountsFirst&& countsFirst,
                std::vector<std::uint32_t>& out) {
        const std::size_t n = mKey.size();
        mSelected.resize(n);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kSelectGrain),
                          [&](const tbb::blocked_range<std::size_t>& range) {
                              for (std::size_t i = range.begin(); i != range.end(); ++i) {
                                  const Copy& c = mCopies[i];
                                  mSelected[i] =
                                      !(skipLeaving && c.leaves) &&
                                      (c.k != 0 || countsFirst(c.light)) &&
                                      segmentMeetsBox(c.origin, c.direction, c.length + mTail, box);
                              }
                          });
        out.clear();
        for (std::size_t i = 0; i < n; ++i)
            if (mSelected[i]) out.push_back(std::uint32_t(i));
    }

    SegmentRays rays() const {
        const Copy* first = mCopies.data();
        return {{first ? &first->origin : nullptr, sizeof(Copy)},
                {first ? &first->direction : nullptr, sizeof(Copy)},
                {first ? &first->length : nullptr, sizeof(Copy)}};
    }
    Strided<glm::vec3> power() const {
        return {mCopies.empty() ? nullptr : &mCopies.data()->power, sizeof(Copy)};
    }

private:
    static constexpr std::size_t kSelectGrain = 16384;

    /// A segment's copy: what the disc queries and the sums read, and what select() tests.
    struct Copy {
        glm::vec3 origin, direction, power;
        float length = 0.f;
        std::uint8_t k = 0;      ///< the segment's place in its path (its bounce)
        std::uint8_t leaves = 0; ///< 1: the segment starts on mMobile
        std::uint16_t light = 0;
    };
    static_assert(sizeof(Copy) == 44);

    void resize(std::size_t n);
    /// Copies entries [first, first + count) of `from` to position `to` (already sized).
    void copyRange(std::size_t to, const NearSegments& from, std::size_t first, std::size_t count);

    bool mValid = false;
    std::size_t mMade = 0; ///< copies at build()
    Aabb mBox;
    float mTail = 0.f;
    Entity mMobile;
    /// Per copy: path << 8 | k, increasing.
    std::vector<std::uint64_t> mKey;
    std::vector<Copy> mCopies;
    static std::uint64_t key(std::uint32_t path, std::uint32_t k) {
        return std::uint64_t(path) << 8 | k;
    }

    /// apply(): what changes, per delta path in path order.
    struct Cut {
        std::uint32_t from = 0, to = 0; ///< its copies [from, to) leave
        std::uint32_t delta = 0;        ///< index into PhotonDelta::paths
        std::uint32_t incoming = 0;     ///< its new segments: mIncoming[incoming, next cut's)
        std::uint32_t write = 0;        ///< where the copies between the previous cut and it go
    };
    std::vector<Cut> mCuts;
    std::vector<std::uint32_t> mIncoming; ///< apply(): new-suffix segments that meet the box
    std::vector<std::uint8_t> mSelected;  ///< select(): per copy, taken
};

} // namespace qgi
