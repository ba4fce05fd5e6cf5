#include "systems/photon_update/PhotonStoreSpace.h"

#include "runtime/core/Error.h"

#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace qgi {
namespace {

/// Room no region is laid out with less of, segments (a region of short paths still takes a
/// few longer ones before it overflows).
constexpr std::size_t kMinRoom = 16;
/// Segments reclaim copies per frame: at least this fraction of the live ones, at least two of
/// the largest regions, and more when the frame released more garbage.
constexpr std::size_t kBudgetDivisor = 32;

} // namespace

void PhotonStoreSpace::clear() {
    mLaidOut = false;
    mRegions.clear();
    mOverflowStart = mReleased = 0;
}

void PhotonStoreSpace::layOut(PhotonStore& store, double overflow) {
    mLaidOut = true;
    const std::size_t paths = store.paths.size();
    mRegionPaths = std::clamp((paths + 63) / 64, kMinRegionPaths, kMaxRegionPaths);
    const std::size_t regions = (paths + mRegionPaths - 1) / mRegionPaths;
    mRegions.assign(regions, Region{});
    tbb::parallel_for(std::size_t(0), regions, [&](std::size_t r) {
        std::size_t live = 0;
        for (std::size_t p = r * mRegionPaths; p < std::min(paths, (r + 1) * mRegionPaths); ++p)
            live += store.paths[p].count;
        mRegions[r].cursor = live; // the region's live segments, until the spans are known
    });
    std::size_t at = 0, total = 0;
    for (Region& region : mRegions) {
        const std::size_t live = region.cursor;
        region.live = live;
        region.room = std::max(kMinRoom, std::size_t(std::ceil(double(live) * kRegionSlack)));
        region.begin = at;
        region.cursor = at + live;
        region.end = at + live + region.room;
        at = region.end;
        total += live;
    }
    mOverflowStart = at;
    mReleased = 0;

    PhotonSegments packed;
    packed.reserve(at + std::size_t(double(total) * (overflow + 0.125)));
    packed.resize(at);
    tbb::parallel_for(std::size_t(0), regions, [&](std::size_t r) {
        std::size_t to = mRegions[r].begin;
        for (std::size_t p = r * mRegionPaths; p < std::min(paths, (r + 1) * mRegionPaths); ++p) {
            PhotonPath& path = store.paths[p];
            packed.copyFrom(to, store.segments, path.first, path.count);
            path.first = std::uint32_t(to);
            to += path.count;
        }
    });
    store.segments = std::move(packed);
}

void PhotonStoreSpace::addEmptyPaths(const PhotonStore& store) {
    if (!laidOut()) return;
    const std::size_t regions = (store.paths.size() + mRegionPaths - 1) / mRegionPaths;
    Region spanless;
    spanless.begin = spanless.end = spanless.cursor = mOverflowStart;
    if (mRegions.size() < regions) mRegions.resize(regions, spanless);
}

void PhotonStoreSpace::release(Region& region, const PhotonPath& path, std::size_t segments) {
    mReleased += segments;
    if (path.first >= mOverflowStart)
        region.overflowed -= segments;
    else
        region.garbage += segments;
}

std::size_t PhotonStoreSpace::place(const PhotonStore& store, std::uint32_t path, std::size_t count,
                                    std::size_t& end) {
    QGI_ASSERT(laidOut(), "PhotonStoreSpace::place before layOut");
    const PhotonPath& old = store.paths[path];
    Region& region = mRegions[regionOf(path)];
    region.live = region.live + count - old.count;
    if (count == 0) { // an empty path (a dark light's photon) points at its region's start,
        release(region, old, old.count); // never past the store's end
        return region.begin;
    }
    if (count <= old.count) { // rewritten in place; a shorter path leaves its tail
        release(region, old, old.count - count);
        return old.first;
    }
    release(region, old, old.count);
    if (region.cursor + count <= region.end) {
        const std::size_t at = region.cursor;
        region.cursor += count;
        return at;
    }
    const std::size_t at = end;
    end += count;
    region.overflowed += count;
    return at;
}

std::size_t PhotonStoreSpace::compactRegion(PhotonStore& store, std::size_t r,
                                            PhotonSegments& scratch) {
    Region& region = mRegions[r];
    const std::size_t first = r * mRegionPaths;
    const std::size_t last = std::min(store.paths.size(), first + mRegionPaths);
    const std::size_t live = region.live;
    if (live > region.end - region.begin) return kNotPacked; // its paths grew past its span

    // Paths already packed from the span's start stay; the rest go out to the scratch buffer
    // (from the span or the overflow) and back in path order.
    std::size_t moveFrom = first, to = region.begin;
    while (moveFrom < last &&
           (store.paths[moveFrom].first == to || store.paths[moveFrom].count == 0))
        to += store.paths[moveFrom++].count;
    const std::size_t start = to;
    scratch.resize(region.begin + live - start);
    std::size_t at = 0;
    for (std::size_t p = moveFrom; p < last; ++p) {
        const PhotonPath& path = store.paths[p];
        scratch.copyFrom(at, store.segments, path.first, path.count);
        at += path.count;
    }
    QGI_ASSERT(start + at == region.begin + live, "region ", r, " has ", start + at - region.begin,
               " live segments, its count says ", live);
    store.segments.copyFrom(start, scratch, 0, at);
    for (std::size_t p = moveFrom; p < last; ++p) {
        store.paths[p].first = std::uint32_t(to);
        to += store.paths[p].count;
    }
    region.cursor = to;
    region.garbage = region.overflowed = 0;
    return at;
}

std::size_t PhotonStoreSpace::liveSegments() const {
    std::size_t live = 0;
    for (const Region& region : mRegions)
        live += region.live;
    return live;
}

PhotonStoreSpace::Reclaimed PhotonStoreSpace::reclaim(PhotonStore& store, double overflow) {
    Reclaimed done;
    if (!laidOut()) return done;
    const std::size_t live = liveSegments();
    const std::size_t overflowSize = store.segments.size() - mOverflowStart;
    if (double(overflowSize) > overflow * double(live)) {
        layOut(store, overflow);
        done.laidOut = true;
        done.copied = live;
        return done;
    }
    // Due: regions whose garbage and overflowed paths would fill half their room (compacted
    // before the room runs out, their re-traced paths stay home), and while the overflow is
    // past half its limit, every region with paths there.
    const bool drainOverflow = double(overflowSize) > 0.5 * overflow * double(live);
    mOrder.clear();
    std::size_t largest = 0;
    for (std::size_t r = 0; r < mRegions.size(); ++r) {
        const Region& region = mRegions[r];
        largest = std::max(largest, region.end - region.begin);
        // Cannot be packed in place (or has no span: paths added since the layout).
        if (region.live > region.end - region.begin || region.room == 0) continue;
        if (2 * reclaimable(region) >= region.room || (drainOverflow && region.overflowed > 0))
            mOrder.push_back(r);
    }
    std::stable_sort(mOrder.begin(), mOrder.end(), [&](std::size_t a, std::size_t b) {
        return reclaimable(mRegions[a]) > reclaimable(mRegions[b]);
    });
    // Compacting a region reclaims at least half its room, kRegionSlack / 2 of its span: to
    // keep up with the garbage the frame released, copy 2 / kRegionSlack times as much, and
    // half again.
    const std::size_t keepUp = std::size_t(3.0 / kRegionSlack * double(mReleased));
    mReleased = 0;
    const std::size_t budget = std::max({live / kBudgetDivisor, 2 * largest, keepUp});
    std::size_t chosen = 0, planned = 0;
    while (chosen < mOrder.size() && (chosen == 0 || planned < budget)) {
        const Region& region = mRegions[mOrder[chosen++]];
        planned += region.end - region.begin;
    }
    mOrder.resize(chosen);

    mMoved.resize(chosen);
    tbb::parallel_for(std::size_t(0), chosen, [&](std::size_t i) {
        mMoved[i] = compactRegion(store, mOrder[i], mScratch.local());
    });
    for (const std::size_t moved : mMoved) {
        if (moved == kNotPacked) continue;
        ++done.regions;
        done.copied += moved;
    }
    // Once no path is left in the overflow, it is all garbage: drop it.
    if (store.segments.size() > mOverflowStart &&
        std::none_of(mRegions.begin(), mRegions.end(),
                     [](const Region& r) { return r.overflowed > 0; }))
        store.segments.resize(mOverflowStart);
    return done;
}

} // namespace qgi
