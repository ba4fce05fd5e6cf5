// PhotonStoreSpace: where re-traced paths go and how their garbage is reclaimed. A synthetic
// store whose every segment names its path and position is rewritten through place() as the
// photon update does, many frames over, and checked after each: every path still reads back
// exactly what was last written to it, no two paths share a segment, the live count is true,
// and the store stays within the bound the class promises.
#include "systems/photon_update/PhotonStoreSpace.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

namespace qgi {
namespace {

/// Segment k of a path written in `version`: its fields spell (path, version, k).
void writeSegment(PhotonSegments& s, std::size_t at, std::uint32_t path, std::uint32_t version,
                  std::uint32_t k) {
    s.origin[at] = glm::vec3(float(path), float(version), float(k));
    s.direction[at] = glm::vec3(0.f, 0.f, 1.f);
    s.length[at] = float(k);
    s.power[at] = glm::vec3(float(version));
    s.hitEntity[at] = Entity{path, version};
    s.hitPrimitive[at] = k;
    s.bounce[at] = std::uint8_t(k);
}

/// A store of `paths` paths with 1 to 5 segments, packed in path order.
PhotonStore makeStore(std::size_t paths, std::mt19937& rng) {
    PhotonStore store;
    store.paths.resize(paths);
    std::uniform_int_distribution<std::uint32_t> length(1, 5);
    std::size_t at = 0;
    for (std::size_t p = 0; p < paths; ++p) {
        store.paths[p] = PhotonPath{std::uint32_t(at), std::uint16_t(length(rng)), 0};
        at += store.paths[p].count;
    }
    store.segments.resize(at);
    for (std::size_t p = 0; p < paths; ++p)
        for (std::uint32_t k = 0; k < store.paths[p].count; ++k)
            writeSegment(store.segments, store.paths[p].first + k, std::uint32_t(p), 0, k);
    return store;
}

/// Every path reads back what was last written to it; no segment belongs to two paths; the
/// space's live count is the paths' total.
void expectIntact(const PhotonStore& store, const PhotonStoreSpace& space,
                  const std::vector<std::uint32_t>& version) {
    std::vector<std::pair<std::size_t, std::size_t>> ranges;
    std::size_t live = 0;
    for (std::uint32_t p = 0; p < store.paths.size(); ++p) {
        const PhotonPath& path = store.paths[p];
        ASSERT_LE(std::size_t(path.first) + path.count, store.segments.size()) << "path " << p;
        for (std::uint32_t k = 0; k < path.count; ++k) {
            const std::size_t s = path.first + k;
            ASSERT_EQ(store.segments.origin[s], glm::vec3(float(p), float(version[p]), float(k)))
                << "path " << p << " segment " << k;
            ASSERT_EQ(store.segments.hitEntity[s], (Entity{p, version[p]}));
            ASSERT_EQ(store.segments.bounce[s], std::uint8_t(k));
        }
        if (path.count > 0) ranges.emplace_back(path.first, std::size_t(path.first) + path.count);
        live += path.count;
    }
    std::sort(ranges.begin(), ranges.end());
    for (std::size_t i = 1; i < ranges.size(); ++i)
        ASSERT_LE(ranges[i - 1].second, ranges[i].first) << "two paths share a segment";
    EXPECT_EQ(space.liveSegments(), live);
}

/// One frame of the photon update's writes: `paths` get new lengths (place, then copy), then
/// reclaim.
PhotonStoreSpace::Reclaimed rewrite(PhotonStore& store, PhotonStoreSpace& space,
                                    std::vector<std::uint32_t>& version,
                                    const std::vector<std::uint32_t>& paths,
                                    const std::vector<std::size_t>& counts, double overflow) {
    std::vector<std::size_t> where(paths.size());
    std::size_t end = store.segments.size();
    for (std::size_t i = 0; i < paths.size(); ++i)
        where[i] = space.place(store, paths[i], counts[i], end);
    store.segments.resize(end);
    for (std::size_t i = 0; i < paths.size(); ++i) {
        const std::uint32_t p = paths[i];
        ++version[p];
        for (std::uint32_t k = 0; k < counts[i]; ++k)
            writeSegment(store.segments, where[i] + k, p, version[p], k);
        store.paths[p].first = std::uint32_t(where[i]);
        store.paths[p].count = std::uint16_t(counts[i]);
    }
    return space.reclaim(store, overflow);
}

/// A synthetic store laid out by a PhotonStoreSpace, with each path's write count.
struct LaidOut {
    PhotonStore store;
    PhotonStoreSpace space;
    std::vector<std::uint32_t> version;

    LaidOut(std::size_t paths, std::uint32_t seed, double overflow) {
        std::mt19937 rng(seed);
        store = makeStore(paths, rng);
        space.layOut(store, overflow);
        version.assign(paths, 0);
    }
};

TEST(PhotonStoreSpace, LayOutKeepsEveryPathAndLeavesRoomPerRegion) {
    std::mt19937 rng(7);
    PhotonStore store = makeStore(10'000, rng);
    std::size_t live = store.segments.size();
    PhotonStoreSpace space;
    space.layOut(store, 0.5);
    const std::vector<std::uint32_t> version(store.paths.size(), 0);
    expectIntact(store, space, version);
    // Room: kRegionSlack of each region's segments, at least kMinRoom (16) each; regions of
    // 10'000 / 64 -> 157 paths.
    const std::size_t regions = (10'000 + 156) / 157;
    EXPECT_GE(store.segments.size(),
              live + std::size_t(double(live) * PhotonStoreSpace::kRegionSlack));
    EXPECT_LE(store.segments.size(),
              live + std::size_t(double(live) * PhotonStoreSpace::kRegionSlack) + 16 * regions);
    // Room for the overflow without a reallocation.
    EXPECT_GE(store.segments.origin.capacity(), store.segments.size() + live / 2);
}

TEST(PhotonStoreSpace, ChurnIsReclaimedRegionByRegionWithinItsBound) {
    constexpr double kOverflow = 0.5;
    LaidOut laid(20'000, 11, kOverflow);
    auto& [store, space, version] = laid;
    std::mt19937 rng(11);
    const std::size_t live = space.liveSegments();

    // A tenth of the paths re-traced each frame, lengths 0 to 5 anew (so about as many grow as
    // shrink; 0: a dark light's empty path): the cornell block's churn.
    std::uniform_int_distribution<std::uint32_t> pathOf(0, 19'999);
    std::uniform_int_distribution<std::size_t> length(0, 5);
    const std::size_t laidOutSize = store.segments.size();
    std::size_t regions = 0, layOuts = 0, overflowed = 0;
    for (int frame = 0; frame < 300; ++frame) {
        std::vector<std::uint32_t> paths;
        for (int i = 0; i < 2'000; ++i)
            paths.push_back(pathOf(rng));
        std::sort(paths.begin(), paths.end());
        paths.erase(std::unique(paths.begin(), paths.end()), paths.end());
        std::vector<std::size_t> counts;
        for (std::size_t i = 0; i < paths.size(); ++i)
            counts.push_back(length(rng));
        const PhotonStoreSpace::Reclaimed done =
            rewrite(store, space, version, paths, counts, kOverflow);
        regions += done.regions;
        layOuts += done.laidOut ? 1 : 0;
        overflowed = std::max(overflowed, store.segments.size() - laidOutSize);
        expectIntact(store, space, version);
        if (HasFatalFailure()) return;
    }
    EXPECT_GT(regions, 100u);
    // Kept up with by regions alone: never laid out again, and the overflow kept to a fraction
    // of its limit.
    EXPECT_EQ(layOuts, 0u);
    EXPECT_LT(double(overflowed), 0.25 * kOverflow * double(live));
}

TEST(PhotonStoreSpace, PathsThatGrowOnTheWholeAreLaidOutAgain) {
    constexpr double kOverflow = 0.25;
    LaidOut laid(5'000, 5, kOverflow);
    auto& [store, space, version] = laid;
    // Every frame a fifth of the paths grows by two segments: the regions' room runs out, the
    // overflow fills, and the store is laid out again, with room for the longer paths.
    std::size_t layOuts = 0;
    for (int frame = 0; frame < 20; ++frame) {
        std::vector<std::uint32_t> paths;
        std::vector<std::size_t> counts;
        for (std::uint32_t p = std::uint32_t(frame % 5); p < 5'000; p += 5) {
            paths.push_back(p);
            counts.push_back(std::min<std::size_t>(store.paths[p].count + 2, 40));
        }
        layOuts += rewrite(store, space, version, paths, counts, kOverflow).laidOut ? 1 : 0;
        expectIntact(store, space, version);
        if (HasFatalFailure()) return;
        EXPECT_LE(double(store.segments.size() - space.liveSegments()),
                  double(space.liveSegments()) * (PhotonStoreSpace::kRegionSlack + kOverflow) +
                      64 * 17.0) // each region's room: at least 16, rounded up
            << "frame " << frame;
    }
    EXPECT_GT(layOuts, 0u);
}

TEST(PhotonStoreSpace, ARegionThatOutgrowsItsSpanDoesNotHoldUpTheOthers) {
    LaidOut laid(1'000, 9, 1.0); // regions of 64 paths
    auto& [store, space, version] = laid;
    // Region 0's first ten paths grow past everything its span holds (to the overflow, for
    // good); region 1's paths shrink to one segment each, enough garbage to be due.
    std::vector<std::uint32_t> paths;
    std::vector<std::size_t> counts;
    for (std::uint32_t p = 0; p < 10; ++p) {
        paths.push_back(p);
        counts.push_back(40);
    }
    for (std::uint32_t p = 64; p < 128; ++p) {
        paths.push_back(p);
        counts.push_back(1);
    }
    const std::size_t before = store.segments.size();
    const PhotonStoreSpace::Reclaimed done = rewrite(store, space, version, paths, counts, 1.0);
    EXPECT_FALSE(done.laidOut);
    EXPECT_EQ(done.regions, 1u);
    // Region 0's grown paths: one in its room, nine in the overflow for good.
    EXPECT_EQ(store.segments.size(), before + 9 * 40);
    // Region 1 packed from its first path on, in path order.
    for (std::uint32_t p = 65; p < 128; ++p)
        EXPECT_EQ(store.paths[p].first, store.paths[p - 1].first + store.paths[p - 1].count);
    expectIntact(store, space, version);
    // Every frame after, region 0 stays unpackable and nothing else is due.
    EXPECT_EQ(rewrite(store, space, version, {}, {}, 1.0).regions, 0u);
}

TEST(PhotonStoreSpace, AnEmptiedOverflowIsDropped) {
    LaidOut laid(1'000, 3, 1.0);
    auto& [store, space, version] = laid;
    const std::size_t laidOutSize = store.segments.size();
    // Path 0 grows far past its region's room: it goes to the overflow.
    rewrite(store, space, version, {0}, {200}, 1.0);
    EXPECT_GE(store.paths[0].first, laidOutSize);
    EXPECT_EQ(store.segments.size(), laidOutSize + 200);
    // Back to one segment: rewritten in place in the overflow, whose other 199 are garbage.
    rewrite(store, space, version, {0}, {1}, 1.0);
    EXPECT_EQ(store.segments.size(), laidOutSize + 200);
    // Its region is due once its garbage fills its room; shrinking its other paths to one
    // segment does that, and the compaction brings path 0 home and drops the overflow.
    std::vector<std::uint32_t> paths;
    std::vector<std::size_t> counts;
    for (std::uint32_t p = 1; p < 64; ++p) {
        paths.push_back(p);
        counts.push_back(1);
    }
    const PhotonStoreSpace::Reclaimed done = rewrite(store, space, version, paths, counts, 1.0);
    EXPECT_GE(done.regions, 1u);
    EXPECT_LT(store.paths[0].first, laidOutSize);
    EXPECT_EQ(store.segments.size(), laidOutSize);
    expectIntact(store, space, version);

    // Emptied (a dark light's photon) while in the overflow: it points inside the store, not
    // at the overflow dropped from under it.
    rewrite(store, space, version, {1}, {200}, 1.0);
    EXPECT_GE(store.paths[1].first, laidOutSize);
    rewrite(store, space, version, {1}, {0}, 1.0);
    EXPECT_EQ(store.segments.size(), laidOutSize);
    EXPECT_LE(store.paths[1].first, laidOutSize);
    expectIntact(store, space, version);
}

} // namespace
} // namespace qgi
