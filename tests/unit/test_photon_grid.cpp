// The path index: every query returns a superset of the brute-force answer, before and after
// incremental updates, and on a fresh build no more than the paths within a cell of the box.
#include "systems/photon_update/PhotonPathGrid.h"

#include "test_photon_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

namespace qgi {
namespace {

/// Whether origin + t direction, t in [0, length], meets the box (in double precision).
bool meets(const glm::dvec3& o, const glm::dvec3& d, double length, const Aabb& box) {
    double near = 0.0, far = length;
    for (int a = 0; a < 3; ++a) {
        if (d[a] == 0.0) {
            if (o[a] < box.min[a] || o[a] > box.max[a]) return false;
            continue;
        }
        double t0 = (box.min[a] - o[a]) / d[a], t1 = (box.max[a] - o[a]) / d[a];
        if (t0 > t1) std::swap(t0, t1);
        near = std::max(near, t0);
        far = std::min(far, t1);
    }
    return near <= far;
}

std::vector<std::uint32_t> bruteForce(const PhotonStore& store, const Aabb& box) {
    std::vector<std::uint32_t> out;
    for (std::uint32_t p = 0; p < store.pathCount(); ++p) {
        const PhotonPath& path = store.paths[p];
        for (std::size_t s = path.first; s < path.first + path.count; ++s)
            if (meets(glm::dvec3(store.segments.origin[s]), glm::dvec3(store.segments.direction[s]),
                      double(store.segments.length[s]), box)) {
                out.push_back(p);
                break;
            }
    }
    return out;
}

Aabb randomBox(std::mt19937& rng, const Aabb& region, float maxSize) {
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    const glm::vec3 c = region.min + glm::vec3(unit(rng), unit(rng), unit(rng)) * region.extent();
    const glm::vec3 half = 0.5f * maxSize * glm::vec3(unit(rng), unit(rng), unit(rng));
    return {c - half, c + half};
}

bool isSubset(const std::vector<std::uint32_t>& small, const std::vector<std::uint32_t>& big) {
    return std::includes(big.begin(), big.end(), small.begin(), small.end());
}

struct GridWorld {
    Registry registry;
    test::Room room;
    PhotonUpdateSystem system;

    explicit GridWorld(std::uint32_t refreshBudget = 8192)
        : system([&] {
              PhotonSettings s;
              s.photonCount = 20'000; // five chunks
              s.gridResolution = 20;
              s.gridRefreshBudget = refreshBudget;
              return s;
          }()) {
        room = test::buildRoom(registry, {-0.8f, -1.25f, -0.5f}, {0.6f, -1.3f, -0.9f});
        test::buildRayScene(registry);
        test::firstUpdate(registry, system);
    }
    const PhotonStore& store() const { return registry.ctx().get<PhotonStore>(); }
    const PhotonPathGrid& grid() const { return registry.ctx().get<PhotonPathGrid>(); }
};

/// Checks random boxes: every answer is a superset of brute force; with `precise`, boxes well
/// inside the grid get no path that passes farther than a cell from them.
void expectQueries(const GridWorld& w, std::uint32_t seed, bool precise) {
    const PhotonPathGrid& grid = w.grid();
    const Aabb& bounds = grid.bounds();
    const Aabb outside{bounds.min - 3.f, bounds.max + 3.f}; // escaping photons are out there
    std::mt19937 rng(seed);
    std::vector<std::uint32_t> found;
    std::size_t nonTrivial = 0;
    for (int i = 0; i < 150; ++i) {
        const bool far = i % 3 == 0;
        const Aabb box = randomBox(rng, far ? outside : bounds, far ? 3.f : 0.8f);
        grid.pathsOverlapping(box, found);
        ASSERT_TRUE(std::is_sorted(found.begin(), found.end()));
        ASSERT_TRUE(std::adjacent_find(found.begin(), found.end()) == found.end());
        const std::vector<std::uint32_t> exact = bruteForce(w.store(), box);
        ASSERT_TRUE(isSubset(exact, found)) << "box " << i << " missed a path";
        nonTrivial += !exact.empty() && exact.size() < w.store().pathCount() / 2 ? 1 : 0;
        // Inside the grid, a listed cell overlaps the box, so its paths pass within one cell.
        const float cell = grid.cellSize() * 1.001f;
        const Aabb wide{box.min - cell, box.max + cell};
        if (precise && !far && glm::all(glm::greaterThan(wide.min, bounds.min)) &&
            glm::all(glm::lessThan(wide.max, bounds.max))) {
            ASSERT_TRUE(isSubset(found, bruteForce(w.store(), wide))) << "box " << i;
        }
    }
    EXPECT_GT(nonTrivial, 50u);
}

TEST(PhotonPathGrid, QueriesAreSupersetsOfBruteForceAndNoWiderThanACell) {
    GridWorld w;
    ASSERT_EQ(w.grid().pathCount(), w.store().pathCount());
    EXPECT_EQ(w.grid().changedPathCount(), 0u);
    expectQueries(w, 11, true);
}

TEST(PhotonPathGrid, ABoxPokingThroughTheFloorIsNotHandedThePathsThatLeaveThroughTheTop) {
    // The room is open at the top only: many paths escape upwards, none reaches below the
    // floor. A box around a crate resting on the floor pokes below the grid's bottom face;
    // it must get the paths near it, not every escaping one.
    GridWorld w;
    const PhotonPathGrid& grid = w.grid();
    const Aabb& bounds = grid.bounds();
    const Aabb box{{-0.3f, bounds.min.y - 0.2f, -0.3f}, {0.3f, bounds.min.y + 0.3f, 0.3f}};
    std::vector<std::uint32_t> found;
    grid.pathsOverlapping(box, found);
    const std::vector<std::uint32_t> exact = bruteForce(w.store(), box);
    ASSERT_TRUE(isSubset(exact, found));
    const float cell = grid.cellSize() * 1.001f;
    EXPECT_TRUE(isSubset(found, bruteForce(w.store(), {box.min - cell, box.max + cell})));
    const Aabb sky{{bounds.min.x, bounds.max.y, bounds.min.z},
                   {bounds.max.x, bounds.max.y + 10.f, bounds.max.z}};
    EXPECT_GT(bruteForce(w.store(), sky).size(), 5 * found.size()); // many escape upwards
    EXPECT_FALSE(exact.empty());
}

TEST(PhotonPathGrid, ChangedPathsAreFoundUntilTheirChunkIsReindexed) {
    GridWorld w(1); // one chunk re-indexed per frame
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> step(-0.3f, 0.3f);
    glm::vec3 at(-0.8f, -1.25f, -0.5f);
    std::size_t mostChanged = 0, refreshes = 0;
    for (std::uint64_t frame = 1; frame <= 6; ++frame) {
        at = glm::clamp(at + glm::vec3(step(rng), 0.5f * step(rng), step(rng)),
                        glm::vec3(-1.6f, -1.25f, -1.6f), glm::vec3(1.6f, 0.5f, 1.6f));
        test::moveAndUpdate(w.registry, w.system, w.room.cube, test::translation(at), frame);
        // Past 1/64 of the paths and twice the frame's re-traced paths changed, a chunk a
        // frame (the budget rounds up to one). A mobile that keeps moving re-traces much the
        // same paths every frame, so the grid idles here.
        const std::size_t reindexed = w.system.lastFrame().reindexedPaths;
        EXPECT_TRUE(reindexed == 0 || reindexed == 4096) << reindexed;
        refreshes += reindexed > 0 ? 1 : 0;
        mostChanged = std::max(mostChanged, w.grid().changedPathCount());
        expectQueries(w, std::uint32_t(frame), false);
        if (HasFatalFailure()) return;
    }
    EXPECT_GT(mostChanged, 200u);
    // Still frames re-trace nothing: past 1/64 of the paths changed, the grid catches up a
    // chunk a frame, and the queries stay exact meanwhile.
    for (std::uint64_t frame = 7; frame <= 9; ++frame) {
        test::moveAndUpdate(w.registry, w.system, w.room.cube, test::translation(at), frame);
        EXPECT_EQ(w.system.lastFrame().retracedPaths, 0u);
        refreshes += w.system.lastFrame().reindexedPaths > 0 ? 1 : 0;
        expectQueries(w, std::uint32_t(frame), false);
        if (HasFatalFailure()) return;
    }
    EXPECT_GT(refreshes, 0u);
    // Re-indexing every chunk with a changed path: the index is cell-precise again.
    PhotonPathGrid& grid = w.registry.ctx().get<PhotonPathGrid>();
    EXPECT_GT(grid.refresh(w.store(), w.store().pathCount(), 0), 0u);
    EXPECT_EQ(grid.changedPathCount(), 0u);
    expectQueries(w, 99, true);

    // Several boxes at once: the union, each path once.
    const Aabb a{glm::vec3(-1.f), glm::vec3(-0.5f)}, b{glm::vec3(0.2f), glm::vec3(0.9f)};
    std::vector<std::uint32_t> ofA, ofB, both;
    w.grid().pathsOverlapping(a, ofA);
    w.grid().pathsOverlapping(b, ofB);
    const Aabb boxes[] = {a, b};
    w.grid().pathsOverlapping(boxes, both);
    std::vector<std::uint32_t> merged;
    std::set_union(ofA.begin(), ofA.end(), ofB.begin(), ofB.end(), std::back_inserter(merged));
    EXPECT_EQ(both, merged);
}

TEST(PhotonPathGrid, PathsOfALightAddedInPlayAreFoundAndIndexed) {
    // A lamp as bright as the room's light: 20,000 photons appended (the last chunk filled up,
    // new chunks after it), shot in one frame and marked changed; queries find them at once,
    // and once re-indexed, cell-precisely.
    GridWorld w(1);
    test::addPointLight(w.registry, {-1.f, 0.5f, 1.f}, 10.f);
    w.system.update(w.registry, FrameContext{1, 0.0, 0.f, 0});
    w.registry.clearChanges();
    ASSERT_EQ(w.system.lastFrame().addedPaths, 20'000u);
    ASSERT_EQ(w.store().pathCount(), 40'000u);
    EXPECT_EQ(w.grid().pathCount(), 40'000u);
    EXPECT_TRUE(w.grid().indexes(w.store()));
    EXPECT_EQ(w.grid().changedPathCount(), 20'000u);
    expectQueries(w, 21, false);
    PhotonPathGrid& grid = w.registry.ctx().get<PhotonPathGrid>();
    // The chunks holding new paths: the last one shot, filled up to 4,096 paths (photons
    // 16,384 to 20,479), four more of 4,096 and one of 3,136.
    EXPECT_EQ(grid.refresh(w.store(), w.store().pathCount(), 0), 23'616u);
    EXPECT_EQ(grid.changedPathCount(), 0u);
    expectQueries(w, 22, true);
}

} // namespace
} // namespace qgi
