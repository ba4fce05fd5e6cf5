#pragma once

#include "systems/photon_update/PhotonStore.h"

#include <oneapi/tbb/enumerable_thread_specific.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace qgi {

/** Where a PhotonStore's paths live, and the reclaiming of what re-traced paths leave behind,
 *  a little every frame instead of all at once.
 *
 *  The store is laid out in regions of consecutive paths (path order inside a region), each
 *  with room to grow by kRegionSlack of its segments. A re-traced path that fits its old range
 *  stays there; a longer one moves to its region's free room, or, when that is used up, to the
 *  overflow at the end of the store. What a path leaves is its region's garbage (or the
 *  overflow's). Each frame `reclaim` compacts the regions whose garbage and overflowed paths
 *  would fill half their room, most reclaimable first, within a budget of copied segments that
 *  grows with the garbage the frame released: a region
 *  is a megabyte or two, packed through a scratch buffer, in parallel with the others. Only
 *  when the overflow passes compactionFraction of the live segments (paths grew on the whole:
 *  a light moved, say) is the whole store laid out again, which copies all of it once.
 *
 *  So the cost of garbage is spread over frames (a compaction of the whole cornell store took
 *  50-200 ms every 45 frames, page faults of a fresh buffer included), and memory stays
 *  within (1 + kRegionSlack + compactionFraction) times the live segments.            */
class PhotonStoreSpace {
public:
    /// Room to grow per region, as a fraction of its segments at layout.
    static constexpr double kRegionSlack = 0.25;
    /// Paths per region: a 64th of the store, between these bounds.
    static constexpr std::size_t kMinRegionPaths = 64, kMaxRegionPaths = 8192;

    struct Reclaimed {
        std::size_t regions = 0; ///< regions compacted
        std::size_t copied = 0;  ///< segments moved (regions: through a scratch buffer)
        bool laidOut = false;    ///< the whole store was laid out again
    };

    /// Lays `store` out anew (any layout in, regions with room out): a freshly shot store, or
    /// one whose overflow grew too large. Copies every live segment once, in parallel, into a
    /// new buffer with capacity for `overflow` times the live segments past the regions.
    void layOut(PhotonStore& store, double overflow);
    /// Takes in the paths appended to `store` since its layout, which must be empty (a light
    /// added in play). Regions past the laid-out ones get no span: their paths live in the
    /// overflow until the next layOut gives them room.
    void addEmptyPaths(const PhotonStore& store);
    /// Forgets the layout: the store is used as traced, and `place` must not be called until
    /// the next layOut (a store re-shot every frame never needs one).
    void clear();
    bool laidOut() const { return mLaidOut; }

    /// Where path `path`'s new `count` segments go: its old range when they fit, else its
    /// region's free room, else `end` (the store's end, advanced). Books the garbage left.
    /// Serial; call for each re-traced path before writing any of them.
    std::size_t place(const PhotonStore& store, std::uint32_t path, std::size_t count,
                      std::size_t& end);
    /// The frame's reclaiming (see the class comment). `overflow` as for layOut.
    Reclaimed reclaim(PhotonStore& store, double overflow);

    /// Segments the store's paths hold.
    std::size_t liveSegments() const;

private:
    struct Region {
        std::size_t begin = 0, end = 0; ///< its span of the store
        std::size_t cursor = 0;         ///< where its free room starts
        std::size_t room = 0;           ///< room to grow it was laid out with
        std::size_t garbage = 0;        ///< segments in [begin, cursor) no path refers to
        std::size_t overflowed = 0;     ///< live segments of its paths in the overflow
        std::size_t live = 0;           ///< live segments of its paths, wherever they are
    };
    std::size_t regionOf(std::uint32_t path) const { return path / mRegionPaths; }
    std::size_t reclaimable(const Region& r) const { return r.garbage + r.overflowed; }
    static constexpr std::size_t kNotPacked = ~std::size_t(0);
    /// Packs region r's paths, overflowed ones too, at the start of its span: the segments it
    /// moved, or kNotPacked when they do not fit.
    std::size_t compactRegion(PhotonStore& store, std::size_t r, PhotonSegments& scratch);
    void release(Region& region, const PhotonPath& path, std::size_t segments);

    bool mLaidOut = false; ///< also for a store of no paths (all lights dark at the shot)
    std::size_t mRegionPaths = kMaxRegionPaths;
    std::vector<Region> mRegions;
    std::size_t mOverflowStart = 0;  ///< the overflow is [mOverflowStart, store size)
    std::size_t mReleased = 0;       ///< segments paths left since the last reclaim
    std::vector<std::size_t> mOrder; ///< per-frame: regions by what they would reclaim
    std::vector<std::size_t> mMoved; ///< per-frame: what compactRegion returned for each
    tbb::enumerable_thread_specific<PhotonSegments> mScratch;
};

} // namespace qgi
