// The photon update system: determinism, the quasi-static update against brute force and
// against a full re-shoot, moving lights, energy in a closed box, settings checks.
#include "systems/photon_update/PhotonUpdateSystem.h"

#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/MobileMesh.h"
#include "components/PathFollower.h"
#include "components/SpotLight.h"
#include "components/Transform.h"
#include "components/VertexIrradiance.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/scene/MeshProcessing.h"
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/detp/DiscCrossing.h"
#include "systems/photon_update/PhotonPathGrid.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonTracer.h"
#include "test_photon_scenes.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <oneapi/tbb/task_arena.h>

#include <glm/gtc/constants.hpp>
#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace qgi {
namespace {

using test::buildRayScene;
using test::buildRoom;
using test::firstUpdate;
using test::sameLayout;
using test::sameSegment;
using test::sameStore;
using test::translation;
using ::testing::HasSubstr;

const glm::vec3 kCubeRest(-0.8f, -1.25f, -0.5f);
const glm::vec3 kCrateRest(0.6f, -1.3f, -0.9f);

PhotonSettings settingsWith(std::uint32_t photons) {
    PhotonSettings s;
    s.photonCount = photons;
    s.seed = 42;
    s.gridResolution = 24;
    return s;
}

const PhotonStore& storeOf(const Registry& r) {
    return r.ctx().get<PhotonStore>();
}
const PhotonDelta& deltaOf(const Registry& r) {
    return r.ctx().get<PhotonDelta>();
}

/// A random pose inside the room: anywhere on or above the floor, turned about a random axis.
glm::mat4 randomPose(std::mt19937& rng, float half) {
    std::uniform_real_distribution<float> x(-1.9f + half, 1.9f - half), y(-1.5f + half, 0.8f);
    std::uniform_real_distribution<float> angle(-3.1f, 3.1f);
    std::normal_distribution<float> axis;
    const glm::vec3 a = glm::normalize(glm::vec3(axis(rng), axis(rng), axis(rng)) + 1e-3f);
    return translation({x(rng), y(rng), x(rng)}) * glm::mat4_cast(glm::angleAxis(angle(rng), a));
}

/// Moves several mobiles in one frame, the way the schedule does, then updates.
void moveAll(Registry& registry, PhotonUpdateSystem& system,
             const std::vector<std::pair<Entity, glm::mat4>>& moves, std::uint64_t frame) {
    for (const auto& [e, pose] : moves)
        registry.patch<WorldTransform>(e).matrix = pose;
    registry.ctx().get<RayScene>().syncMoved(registry);
    system.update(registry, FrameContext{frame, 0.0, 0.f, 0});
    registry.clearChanges();
}

/// Brute force over every stored segment: the first segment of each path that hit one of
/// `moved` (at its old pose, as recorded) or crosses it at its new pose, and that `landed`
/// (when given) does not excuse; -1 when none. Mobiles listed in `out` are inactive now: only
/// their recorded hits count.
std::vector<int> bruteForceFirstAffected(const PhotonStore& before, const RayScene& scene,
                                         const std::vector<std::pair<Entity, glm::mat4>>& moved,
                                         const std::function<bool(std::size_t)>& landed = {},
                                         const std::vector<Entity>& out = {}) {
    std::vector<int> first(before.pathCount(), -1);
    for (std::size_t p = 0; p < before.pathCount(); ++p) {
        const PhotonPath& path = before.paths[p];
        for (int k = 0; k < path.count && first[p] < 0; ++k) {
            const std::size_t s = path.first + std::size_t(k);
            const Ray ray{before.segments.origin[s], 0.f, before.segments.direction[s],
                          before.segments.length[s]};
            for (const auto& [e, pose] : moved) {
                const bool active = std::find(out.begin(), out.end(), e) == out.end();
                if ((before.segments.hitEntity[s] == e ||
                     (active && scene.intersectMobile(e, pose, ray))) &&
                    !(landed && landed(s)))
                    first[p] = k;
            }
        }
    }
    return first;
}

/// Segment equality, except that a segment that hit one of the `relabelled` entities may name
/// another triangle (a landed segment takes the neighbouring triangle of the same plane it now
/// lands on).
bool sameSegmentUpToRelabel(const PhotonSegments& a, std::size_t s, const PhotonSegments& b,
                            std::size_t t, const std::vector<Entity>& relabelled) {
    if (a.hitEntity[s] == b.hitEntity[t] &&
        std::find(relabelled.begin(), relabelled.end(), a.hitEntity[s]) != relabelled.end()) {
        PhotonSegments copy;
        copy.resize(1);
        copy.copyFrom(0, b, t, 1);
        copy.hitPrimitive[0] = a.hitPrimitive[s];
        return sameSegment(a, s, copy, 0);
    }
    return sameSegment(a, s, b, t);
}

/// Checks one frame's delta against the store before and after it and the brute-force set.
void expectExactDelta(const PhotonStore& before, const PhotonStore& after, const PhotonDelta& delta,
                      const std::vector<int>& expectedFirst,
                      const std::vector<Entity>& relabelled = {}) {
    ASSERT_FALSE(delta.full);
    ASSERT_EQ(delta.oldFirst.size(), delta.paths.size() + 1);
    ASSERT_EQ(delta.newFirst.size(), delta.paths.size() + 1);
    std::vector<int> first(before.pathCount(), -1);
    for (std::size_t i = 0; i < delta.paths.size(); ++i) {
        const std::uint32_t p = delta.paths[i];
        ASSERT_EQ(first[p], -1) << "path " << p << " listed twice";
        const PhotonPath& old = before.paths[p];
        const PhotonPath& now = after.paths[p];
        const std::size_t oldSuffix = delta.oldFirst[i + 1] - delta.oldFirst[i];
        const std::size_t newSuffix = delta.newFirst[i + 1] - delta.newFirst[i];
        ASSERT_GE(old.count, oldSuffix);
        ASSERT_GT(newSuffix, 0u);
        const std::size_t k = old.count - oldSuffix;
        first[p] = int(k);
        ASSERT_EQ(now.count, k + newSuffix);
        // (b) the prefix is bit-identical; the old suffix is what the store held.
        for (std::size_t j = 0; j < k; ++j)
            ASSERT_TRUE(sameSegmentUpToRelabel(before.segments, old.first + j, after.segments,
                                               now.first + j, relabelled));
        for (std::size_t j = 0; j < oldSuffix; ++j)
            ASSERT_TRUE(sameSegment(before.segments, old.first + k + j, delta.oldSegments,
                                    delta.oldFirst[i] + j));
        for (std::size_t j = 0; j < newSuffix; ++j)
            ASSERT_TRUE(sameSegment(after.segments, now.first + k + j, delta.newSegments,
                                    delta.newFirst[i] + j));
        // (c) the heads of both suffixes are the same ray with the same power.
        const std::size_t o = delta.oldFirst[i], n = delta.newFirst[i];
        EXPECT_EQ(delta.oldSegments.origin[o], delta.newSegments.origin[n]);
        EXPECT_EQ(delta.oldSegments.direction[o], delta.newSegments.direction[n]);
        EXPECT_EQ(delta.oldSegments.power[o], delta.newSegments.power[n]);
        EXPECT_EQ(delta.oldSegments.bounce[o], delta.newSegments.bounce[n]);
    }
    // (a) exactly the brute-force paths, each from its first affected segment; every other
    // path is untouched.
    EXPECT_EQ(first, expectedFirst);
    for (std::size_t p = 0; p < before.pathCount(); ++p) {
        if (first[p] >= 0) continue;
        ASSERT_EQ(before.paths[p].count, after.paths[p].count);
        for (std::size_t j = 0; j < before.paths[p].count; ++j)
            ASSERT_TRUE(sameSegmentUpToRelabel(before.segments, before.paths[p].first + j,
                                               after.segments, after.paths[p].first + j,
                                               relabelled));
    }
}

/// (d) Re-tracing every stored segment through the current scene finds its recorded hit, at
/// its recorded distance to within `tolerance` metres.
void expectHitsReproduce(const PhotonStore& store, const RayScene& scene, float tolerance = 0.f) {
    std::size_t checked = 0;
    for (const PhotonPath& path : store.paths)
        for (std::size_t s = path.first; s < path.first + path.count; ++s, ++checked) {
            const std::optional<Hit> hit =
                scene.intersect(Ray{store.segments.origin[s], 0.f, store.segments.direction[s],
                                    std::numeric_limits<float>::infinity()});
            ASSERT_EQ(hit.has_value(), bool(store.segments.hitEntity[s])) << "segment " << s;
            if (!hit) continue;
            ASSERT_EQ(hit->entity, store.segments.hitEntity[s]) << "segment " << s;
            ASSERT_EQ(hit->primitive, store.segments.hitPrimitive[s]) << "segment " << s;
            ASSERT_LE(std::abs(hit->t - store.segments.length[s]), tolerance) << "segment " << s;
        }
    EXPECT_GT(checked, store.pathCount());
}

// ---- determinism -------------------------------------------------------------------------------

TEST(PhotonDeltaReader, ReadsEachDeltaOnceAndSaysWhenOneWasMissed) {
    using News = PhotonDeltaReader::News;
    PhotonDeltaReader reader;
    PhotonDelta delta;
    const auto read = [&](std::uint64_t sequence, bool full = false) {
        delta.sequence = sequence;
        delta.full = full;
        return reader.read(delta);
    };
    EXPECT_EQ(read(1), News::Fresh); // the first one read, whatever its number
    EXPECT_EQ(read(1), News::Repeated);
    EXPECT_EQ(read(2), News::Fresh);
    EXPECT_EQ(read(4), News::AfterGap); // 3 was missed
    EXPECT_EQ(read(4), News::Repeated);
    EXPECT_EQ(read(0), News::Fresh); // made by hand: always new, and no number to follow
    EXPECT_EQ(read(0), News::Fresh);
    EXPECT_EQ(read(5), News::Fresh);
    EXPECT_EQ(read(5, true), News::Fresh); // a full one is never skipped
    EXPECT_EQ(read(1, true), News::Fresh); // a PhotonDelta made anew, numbered from 1
    EXPECT_EQ(read(2), News::Fresh);
    EXPECT_EQ(read(2), News::Repeated);
}

TEST(PhotonUpdate, SameSeedGivesABitIdenticalStoreAnotherSeedDoesNot) {
    const auto shoot = [](Registry& r, std::uint64_t seed) {
        buildRoom(r, kCubeRest, kCrateRest);
        buildRayScene(r);
        PhotonSettings s = settingsWith(20'000);
        s.seed = seed;
        PhotonUpdateSystem system(s);
        firstUpdate(r, system);
        return &storeOf(r);
    };
    Registry a, b, c;
    const PhotonStore& x = *shoot(a, 5);
    const PhotonStore& y = *shoot(b, 5);
    const PhotonStore& z = *shoot(c, 6);
    EXPECT_TRUE(deltaOf(a).full);
    ASSERT_EQ(x.pathCount(), 20'000u);
    EXPECT_TRUE(sameStore(x, y));
    EXPECT_TRUE(sameLayout(x, y));
    EXPECT_FALSE(sameStore(x, z));
}

// The tracer splits its rounds into more blocks the more threads it has: the store, layout
// included, must not show it. One thread, the default, and 16 threads (oversubscribed here).
TEST(PhotonUpdate, TheStoreDoesNotDependOnTheThreadCount) {
    const auto shoot = [](Registry& r, int threads) {
        tbb::task_arena arena(threads);
        arena.execute([&] {
            buildRoom(r, kCubeRest, kCrateRest);
            buildRayScene(r);
            PhotonUpdateSystem system(settingsWith(20'000));
            firstUpdate(r, system);
        });
        return &storeOf(r);
    };
    Registry a, b, c;
    const PhotonStore& one = *shoot(a, 1);
    const PhotonStore& all = *shoot(b, tbb::task_arena::automatic);
    const PhotonStore& sixteen = *shoot(c, 16);
    for (const PhotonStore* other : {&all, &sixteen}) {
        EXPECT_TRUE(sameStore(one, *other));
        EXPECT_TRUE(sameLayout(one, *other));
    }
}

TEST(PhotonUpdate, RetracingFromAnyStoredSegmentReproducesTheRestOfThePath) {
    Registry registry;
    buildRoom(registry, kCubeRest, kCrateRest);
    const RayScene& scene = buildRayScene(registry);
    const PhotonSettings settings = settingsWith(5'000);
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    const PhotonStore& store = storeOf(registry);

    // The tracer's inputs rebuilt here: albedo by entity index.
    std::vector<glm::vec3> albedo;
    registry.view<const Material>().each([&](Entity e, const Material& m) {
        if (e.index >= albedo.size()) albedo.resize(e.index + 1, glm::vec3(0.f));
        albedo[e.index] = m.baseColor;
    });
    const PhotonTracer::Surfaces surfaces{settings.seed, settings.maxBounces, albedo};
    PhotonTracer tracer;
    std::size_t longPaths = 0;
    for (std::uint32_t k = 0; k < 4; ++k) {
        std::vector<std::uint32_t> paths;
        for (std::uint32_t p = 0; p < store.pathCount(); ++p)
            if (store.paths[p].count > k) paths.push_back(p);
        if (k > 1) longPaths += paths.size();
        PhotonSegments out;
        std::vector<std::uint32_t> ends{0};
        tracer.trace(
            scene, surfaces, paths.size(),
            [&](std::size_t i) {
                const std::size_t s = store.segmentIndex(paths[i], k);
                return PhotonHead{store.segments.origin[s], store.segments.direction[s],
                                  store.segments.power[s], paths[i], store.segments.bounce[s]};
            },
            out, ends);
        for (std::size_t i = 0; i < paths.size(); ++i) {
            const PhotonPath& path = store.paths[paths[i]];
            ASSERT_EQ(ends[i + 1] - ends[i], path.count - k) << "path " << paths[i];
            for (std::size_t j = 0; j < path.count - k; ++j)
                ASSERT_TRUE(sameSegment(out, ends[i] + j, store.segments, path.first + k + j));
        }
    }
    EXPECT_GT(longPaths, 1000u); // the deeper starts were exercised
}

// ---- the quasi-static update
// ---------------------------------------------------------------------

/// The room shot from scratch with its mobiles at these poses gives `registry`'s ray set.
void expectAFreshShotsStore(const Registry& registry, const PhotonSettings& settings,
                            const glm::mat4& cubePose, const glm::mat4& cratePose) {
    Registry fresh;
    const test::Room again = buildRoom(fresh, kCubeRest, kCrateRest);
    fresh.patch<WorldTransform>(again.cube).matrix = cubePose;
    fresh.patch<WorldTransform>(again.crate).matrix = cratePose;
    buildRayScene(fresh);
    PhotonUpdateSystem full(settings);
    firstUpdate(fresh, full);
    EXPECT_TRUE(sameStore(storeOf(registry), storeOf(fresh)));
}

TEST(PhotonUpdate, RandomMovesRetraceExactlyTheAffectedPathsAndMatchAFullReshoot) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const RayScene& scene = buildRayScene(registry);
    PhotonSettings settings = settingsWith(20'000);
    settings.compactionFraction = 0.2f;
    settings.gridRefreshBudget = 1;     // and keep many paths in the grid's changed set
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);

    std::mt19937 rng(2024);
    std::size_t retraced = 0, bothMoved = 0, regions = 0;
    glm::mat4 cubePose = translation(kCubeRest), cratePose = translation(kCrateRest);
    for (std::uint64_t frame = 1; frame <= 24; ++frame) {
        std::vector<std::pair<Entity, glm::mat4>> moves;
        // Every third frame both mobiles move; otherwise one, alternately.
        if (frame % 3 == 0 || frame % 2 == 0) moves.emplace_back(room.cube, randomPose(rng, 0.45f));
        if (frame % 3 == 0 || frame % 2 == 1)
            moves.emplace_back(room.crate, randomPose(rng, 0.35f));
        bothMoved += moves.size() == 2 ? 1 : 0;
        const PhotonStore before = storeOf(registry);
        moveAll(registry, system, moves, frame);
        for (const auto& [e, pose] : moves)
            (e == room.cube ? cubePose : cratePose) = pose;
        const std::vector<int> expected = bruteForceFirstAffected(before, scene, moves);
        expectExactDelta(before, storeOf(registry), deltaOf(registry), expected);
        EXPECT_EQ(deltaOf(registry).movedMobiles.size(), moves.size());
        retraced += deltaOf(registry).paths.size();
        regions += system.lastFrame().compactedRegions;
        if (HasFatalFailure()) return;
    }
    EXPECT_GT(retraced, 2'000u);
    EXPECT_GT(bothMoved, 5u);
    EXPECT_GT(regions, 0u); // store regions compacted on the way (PhotonStoreSpace)
    expectHitsReproduce(storeOf(registry), scene);

    expectAFreshShotsStore(registry, settings, cubePose, cratePose);
}

TEST(PhotonUpdate, MobilesTakenOutAndPutBackRetraceExactlyTheirPathsAndMatchAFullShot) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const RayScene& scene = buildRayScene(registry);
    PhotonSettings settings = settingsWith(20'000);
    settings.reuseLandedPaths = false; // the seed's rule, bit for bit
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    const PhotonStore first = storeOf(registry);

    std::mt19937 rng(77);
    const std::vector<Entity> mobiles{room.cube, room.crate};
    std::map<Entity, glm::mat4> pose{{room.cube, translation(kCubeRest)},
                                     {room.crate, translation(kCrateRest)}};
    std::map<Entity, bool> active{{room.cube, true}, {room.crate, true}};
    std::size_t retraced = 0, takenOut = 0, putBack = 0;
    for (std::uint64_t frame = 1; frame <= 16; ++frame) {
        // Each mobile, with equal odds: stays, moves, is taken out or put back where it is, or
        // is taken out or put back somewhere else.
        std::vector<std::pair<Entity, glm::mat4>> changed;
        std::vector<Entity> out;
        for (const Entity e : mobiles) {
            const int action = int(rng() % 4);
            if (action == 0) continue;
            if (action != 2) {
                pose[e] = randomPose(rng, e == room.cube ? 0.45f : 0.35f);
                registry.patch<WorldTransform>(e).matrix = pose[e];
            }
            if (action >= 2) {
                active[e] = !active[e];
                registry.patch<MobileMesh>(e).active = active[e];
                (active[e] ? putBack : takenOut) += 1;
            }
            changed.emplace_back(e, pose[e]);
            if (!active[e]) out.push_back(e);
        }
        const PhotonStore before = storeOf(registry);
        registry.ctx().get<RayScene>().syncMoved(registry);
        system.update(registry, FrameContext{frame, 0.0, 0.f, 0});
        registry.clearChanges();
        expectExactDelta(before, storeOf(registry), deltaOf(registry),
                         bruteForceFirstAffected(before, scene, changed, {}, out));
        EXPECT_EQ(deltaOf(registry).movedMobiles.size(), changed.size());
        retraced += deltaOf(registry).paths.size();
        if (HasFatalFailure()) return;
    }
    EXPECT_GT(takenOut, 2u);
    EXPECT_GT(putBack, 2u);
    EXPECT_GT(retraced, 2'000u);
    // No stored segment hits an inactive mobile: the ray scene misses them.
    expectHitsReproduce(storeOf(registry), scene);

    // The same scene shot from scratch as it ended: the same ray set.
    {
        Registry fresh;
        const test::Room again = buildRoom(fresh, kCubeRest, kCrateRest);
        for (const auto& [mine, theirs] :
             {std::pair{room.cube, again.cube}, std::pair{room.crate, again.crate}}) {
            fresh.patch<WorldTransform>(theirs).matrix = pose[mine];
            fresh.get<MobileMesh>(theirs).active = active[mine];
        }
        buildRayScene(fresh);
        PhotonUpdateSystem full(settings);
        firstUpdate(fresh, full);
        EXPECT_TRUE(sameStore(storeOf(registry), storeOf(fresh)));
    }

    // Both back where they started, in one frame: the first shot again, bit for bit.
    for (const Entity e : mobiles) {
        registry.patch<WorldTransform>(e).matrix =
            translation(e == room.cube ? kCubeRest : kCrateRest);
        registry.patch<MobileMesh>(e).active = true;
    }
    registry.ctx().get<RayScene>().syncMoved(registry);
    system.update(registry, FrameContext{17, 0.0, 0.f, 0});
    EXPECT_FALSE(deltaOf(registry).full);
    EXPECT_TRUE(sameStore(storeOf(registry), first));
}

/// What bounds the rounding of incremental irradiance sums: how many segment powers they
/// added (or subtracted) and the largest power a channel of any of them carries.
struct SumRounding {
    double additions = 0.0, power = 0.0;
    /// Notes `segments`, and `extra` more additions besides (relabelled landings: two each).
    void add(const PhotonSegments& segments, double extra = 0.0) {
        additions += double(segments.size()) + extra;
        for (std::size_t s = 0; s < segments.size(); ++s)
            for (int c = 0; c < 3; ++c)
                power = std::max(power, double(segments.power[s][c]));
    }
    /// Two double sums of these additions differ by at most this much, W (each is within
    /// n^2 p 2^-53 of the exact sum).
    double sums() const { return 2.0 * additions * additions * power * 0x1p-53; }
};

/// Over the meshes: the most triangles around one vertex, and the smallest triangle's area.
struct Rings {
    double largest = 0.0, smallestTriangle = std::numeric_limits<double>::infinity();
};

Rings meshRings(const Registry& registry, const std::vector<Entity>& meshes) {
    Rings rings;
    for (const Entity e : meshes) {
        const Mesh& mesh = registry.get<Mesh>(e);
        std::vector<int> triangles(mesh.positions.size(), 0);
        for (std::size_t t = 0; t < mesh.indices.size(); t += 3) {
            const glm::dvec3 a(mesh.positions[mesh.indices[t]]);
            const glm::dvec3 b(mesh.positions[mesh.indices[t + 1]]);
            const glm::dvec3 c(mesh.positions[mesh.indices[t + 2]]);
            rings.smallestTriangle =
                std::min(rings.smallestTriangle, 0.5 * glm::length(glm::cross(b - a, c - a)));
            for (int k = 0; k < 3; ++k)
                rings.largest =
                    std::max(rings.largest, double(++triangles[mesh.indices[t + std::size_t(k)]]));
        }
    }
    return rings;
}

/// How far an incremental estimate may lie from a full one by rounding alone, W/m^2 (then one
/// rounding to float each way, 2^-23 relative, on top). DETP: the two double sums of a vertex
/// over pi r^2; impact count: the same per triangle, over a ring of at least the smallest
/// triangle's area, whose float area is within 2^-16 of the one here, as in
/// ASlidingMobileKeepsThePathsThatLandWhereTheyDid; the photon map re-estimates from scratch:
/// exact.
double roundingBound(const DetpSettings& settings, const SumRounding& rounding,
                     const Rings& rings) {
    const double r = double(settings.discRadius);
    switch (settings.estimator) {
    case IrradianceEstimator::Detp:
        return rounding.sums() / (glm::pi<double>() * r * r);
    case IrradianceEstimator::ImpactCount:
        return rings.largest * rounding.sums() / (rings.smallestTriangle * (1.0 - 0x1p-16));
    case IrradianceEstimator::PhotonMap:
        return 0.0;
    }
    return 0.0;
}

/// The VertexIrradiance of `meshes` (an incremental system's) against a fresh system's full
/// estimate over the current ray set, within `absolute` plus float rounding. The reference
/// runs without the path grid, so that it re-estimates the mobiles from every path, not from
/// the paths the grid finds near them as the incremental system does. The incremental values
/// are put back, so that the incremental system goes on from its own.
void expectIrradianceOfAFullEstimate(Registry& registry, const DetpSettings& settings,
                                     const std::vector<Entity>& meshes, double absolute,
                                     int frame) {
    std::vector<std::vector<glm::vec3>> incremental;
    for (const Entity e : meshes)
        incremental.push_back(registry.get<VertexIrradiance>(e).irradiance);
    const std::shared_ptr<PhotonPathGrid> grid = registry.ctx().take<PhotonPathGrid>();
    DetpIrradianceSystem reference(settings);
    reference.build(registry);
    reference.update(registry, FrameContext{});
    if (grid) registry.ctx().adopt(grid);
    for (std::size_t m = 0; m < meshes.size(); ++m) {
        auto& full = registry.get<VertexIrradiance>(meshes[m]).irradiance;
        for (std::size_t v = 0; v < full.size(); ++v)
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(incremental[m][v][c], full[v][c],
                            std::ldexp(double(full[v][c]), -23) + absolute)
                    << registry.get<Name>(meshes[m]).value << " vertex " << v << ", frame "
                    << frame;
        full = incremental[m];
    }
    registry.clearChanges();
}

/// Irradiance estimators following mobiles taken out and put back, frame by frame.
class MobilesTakenOut : public ::testing::TestWithParam<IrradianceEstimator> {};

TEST_P(MobilesTakenOut, IrradianceEqualsAFullEstimateEveryFrameAndAnInactiveMobileIsDark) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    // Mobiles with vertices on their faces, not only at their corners: discs photons cross.
    MeshProcessingOptions refine;
    refine.maxEdgeLength = 0.1f;
    for (const Entity mobile : {room.cube, room.crate})
        registry.get<Mesh>(mobile) = processMesh(registry.get<Mesh>(mobile), refine);
    buildRayScene(registry);
    PhotonUpdateSystem photons(settingsWith(20'000));
    photons.update(registry, FrameContext{});
    DetpSettings settings;
    settings.estimator = GetParam();
    settings.discRadius = 0.05f;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, FrameContext{});
    registry.clearChanges();
    const std::vector<Entity> meshes = registry.view<const Mesh>().entities();

    SumRounding rounding;
    rounding.add(storeOf(registry).segments);
    const Rings rings = meshRings(registry, meshes);
    const auto expectFullEstimate = [&](int frame) {
        expectIrradianceOfAFullEstimate(registry, settings, meshes,
                                        roundingBound(settings, rounding, rings), frame);
    };

    // Every case: out where it stands, moved while another is out, back elsewhere, moved
    // while out, back where it is, both out, both back, one out at the end.
    struct Step {
        Entity mobile;
        std::optional<glm::vec3> moveTo;
        std::optional<bool> active;
    };
    const glm::vec3 elsewhere(0.3f, -1.25f, 0.6f);
    // 5 cm from the cube's side: the crate's re-traced paths pass where the cube's discs are.
    const glm::vec3 nextToCube(kCubeRest.x + 0.5f, kCrateRest.y, kCubeRest.z);
    const std::vector<std::vector<Step>> frames{
        {{room.cube, {}, false}},
        {{room.crate, nextToCube, {}}},
        {{room.crate, kCrateRest + glm::vec3(0.1f, 0.f, 0.f), {}}},
        {{room.cube, elsewhere, true}},
        {{room.crate, {}, false}, {room.cube, kCubeRest, {}}},
        {{room.crate, kCrateRest + glm::vec3(-0.2f, 0.f, 0.3f), {}}},
        {{room.crate, {}, true}},
        {{room.cube, {}, false}, {room.crate, {}, false}},
        {{room.cube, {}, true}, {room.crate, kCrateRest, true}},
        {{room.crate, {}, false}}};
    std::map<Entity, bool> active{{room.cube, true}, {room.crate, true}};
    std::size_t passingOut = 0;
    for (std::size_t f = 0; f < frames.size(); ++f) {
        for (const Step& step : frames[f]) {
            if (step.moveTo)
                registry.patch<WorldTransform>(step.mobile).matrix = translation(*step.moveTo);
            if (step.active)
                registry.patch<MobileMesh>(step.mobile).active = active[step.mobile] = *step.active;
        }
        registry.ctx().get<RayScene>().syncMoved(registry);
        photons.update(registry, FrameContext{f + 1, 0.0, 0.f, 0});
        const PhotonDelta& delta = deltaOf(registry);
        ASSERT_FALSE(delta.full);
        rounding.add(delta.oldSegments);
        rounding.add(delta.newSegments, 2.0 * double(delta.relabels.size()));
        // Delta segments that cross the discs of a mobile that is out and stays put: the
        // irradiance system must not count them (checked by the darkness below).
        for (const Entity mobile : {room.cube, room.crate}) {
            const bool stays = std::none_of(frames[f].begin(), frames[f].end(),
                                            [&](const Step& s) { return s.mobile == mobile; });
            if (active[mobile] || !stays) continue;
            const Mesh& mesh = registry.get<Mesh>(mobile);
            const glm::mat4& pose = registry.get<WorldTransform>(mobile).matrix;
            for (const PhotonSegments* part : {&delta.oldSegments, &delta.newSegments})
                for (std::size_t i = 0; i < part->size(); ++i)
                    for (std::size_t v = 0; v < mesh.positions.size(); ++v)
                        passingOut +=
                            crossesDisc(part->origin[i], part->direction[i], part->length[i],
                                        glm::vec3(pose * glm::vec4(mesh.positions[v], 1.f)),
                                        glm::mat3(pose) * mesh.normals[v], 0.05f)
                                ? 1
                                : 0;
        }
        system.update(registry, FrameContext{f + 1, 0.0, 0.f, 0});
        ASSERT_FALSE(system.lastFrame().full);
        for (const Entity mobile : {room.cube, room.crate}) {
            const auto& irradiance = registry.get<VertexIrradiance>(mobile).irradiance;
            const bool dark = std::all_of(irradiance.begin(), irradiance.end(),
                                          [](const glm::vec3& e) { return e == glm::vec3(0.f); });
            EXPECT_EQ(dark, !active[mobile])
                << registry.get<Name>(mobile).value << ", frame " << f + 1;
        }
        expectFullEstimate(int(f + 1));
        if (HasFatalFailure()) return;
    }
    EXPECT_GT(passingOut, 10u);

    // The crate is out. Moving it, or patching the flag to the value it has, changes nothing
    // and costs nothing: no path re-traced, no mobile re-estimated or republished.
    ASSERT_FALSE(active[room.crate]);
    for (int step = 0; step < 2; ++step) {
        if (step == 0)
            registry.patch<WorldTransform>(room.crate).matrix = translation(elsewhere);
        else
            registry.patch<MobileMesh>(room.cube).active = true;
        registry.ctx().get<RayScene>().syncMoved(registry);
        photons.update(registry, FrameContext{100u + std::uint64_t(step), 0.0, 0.f, 0});
        registry.get<VertexIrradiance>(room.crate).dirty.clear();
        system.update(registry, FrameContext{100u + std::uint64_t(step), 0.0, 0.f, 0});
        registry.clearChanges();
        EXPECT_TRUE(deltaOf(registry).paths.empty()) << "step " << step;
        EXPECT_EQ(system.lastFrame().movedMobiles, 0u) << "step " << step;
        EXPECT_TRUE(registry.get<VertexIrradiance>(room.crate).dirty.empty()) << "step " << step;
    }
}

INSTANTIATE_TEST_SUITE_P(Estimators, MobilesTakenOut,
                         ::testing::Values(IrradianceEstimator::Detp,
                                           IrradianceEstimator::ImpactCount,
                                           IrradianceEstimator::PhotonMap),
                         [](const auto& test) {
                             return std::string(irradianceEstimatorName(test.param));
                         });

/// W of the stored segments that end on a surface (impacts), per channel, over live paths.
glm::dvec3 impactPower(const PhotonSegments& segments, std::size_t first, std::size_t count) {
    glm::dvec3 sum(0.0);
    for (std::size_t s = first; s < first + count; ++s)
        if (segments.hitEntity[s]) sum += glm::dvec3(segments.power[s]);
    return sum;
}
glm::dvec3 impactPower(const PhotonStore& store) {
    glm::dvec3 sum(0.0);
    for (const PhotonPath& path : store.paths)
        sum += impactPower(store.segments, path.first, path.count);
    return sum;
}

// A hundred frames of play through the real systems with their defaults (landed paths kept):
// the cube slides a centimetre at a time, the crate jumps and turns, both in some frames, and
// every 25 frames the light moves and is re-shot a quarter of its photons a frame, over the
// mobiles' moves. Every frame the delta accounts for every watt the store gained or lost, and
// every 10 frames DETP's incremental irradiance equals a fresh full estimate over the current
// ray set, within the rounding of its sums.
/// Each light's photons, summed at their first segments, carry its power (a dark light's, and a
/// ghost's, hold no segments); within the float rounding of each photon's share: each carries
/// fl(P / n), at most 2^-24 P / n off, and the n additions in double add at most n 2^-53 P.
void expectEachLightsPowerShot(const PhotonStore& store) {
    std::vector<glm::dvec3> sums(store.lights.size(), glm::dvec3(0.0));
    for (std::size_t p = 0; p < store.pathCount(); ++p)
        if (store.paths[p].count > 0)
            sums[store.paths[p].light] += glm::dvec3(store.segments.power[store.paths[p].first]);
    for (std::size_t l = 0; l < sums.size(); ++l)
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(sums[l][c], store.lights[l].power[c],
                        (0x1p-24 + double(store.lights[l].photonCount) * 0x1p-53) *
                            store.lights[l].power[c])
                << "light " << l << ", channel " << c;
}

/// The test room shot with 5,000 photons, updated frame by frame.
struct ShotRoom {
    Registry registry;
    test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    PhotonUpdateSystem system{settingsWith(5'000)};
    std::uint64_t frame = 1;

    ShotRoom() {
        buildRayScene(registry);
        firstUpdate(registry, system);
    }
    /// Runs `frames` updates, clearing the changes after each.
    void run(int frames) {
        for (int f = 0; f < frames; ++f) {
            system.update(registry, FrameContext{frame++, 0.0, 0.f, 0});
            registry.clearChanges();
        }
    }
};

TEST(PhotonUpdate, ALightMovedPastThePosesReachGoesDarkWithAWarningAndNothingAborts) {
    // The room's light carried to 1e20 m in play (a runaway animation, say): a photon shot
    // from there would make Embree abort. It is named, its photons are shot dark within the
    // budget, and brought back it shines again.
    ShotRoom w;
    const glm::dvec3 lit = impactPower(storeOf(w.registry));
    ASSERT_GT(lit.x, 0.0);
    const ScopedLogLevel verbose(LogLevel::Info);
    ::testing::internal::CaptureStderr();
    w.registry.patch<WorldTransform>(w.room.light).matrix = translation({0.f, 1e20f, 0.f});
    w.run(20);
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(log.find("places it more than 1e7 m away"), std::string::npos) << log;
    EXPECT_EQ(impactPower(storeOf(w.registry)), glm::dvec3(0.0));
    w.registry.patch<WorldTransform>(w.room.light).matrix = translation({0.f, 1.2f, 0.f});
    w.run(20);
    EXPECT_NEAR(impactPower(storeOf(w.registry)).x, lit.x, 1e-4 * lit.x);
}

TEST(PhotonUpdate, ALightLeftWithANanColourIsWarnedAboutOnce) {
    // NaN compares unequal to itself: the light was taken for edited, prepared and warned
    // about again every frame. Left as it is, it is the same light: one warning.
    ShotRoom w;
    const ScopedLogLevel verbose(LogLevel::Info);
    ::testing::internal::CaptureStderr();
    w.registry.patch<PointLight>(w.room.light).color = glm::vec3(std::nanf(""));
    w.run(10);
    const std::string log = ::testing::internal::GetCapturedStderr();
    const std::string warning = "is negative or not finite";
    const std::size_t first = log.find(warning);
    ASSERT_NE(first, std::string::npos) << log;
    EXPECT_EQ(log.find(warning, first + 1), std::string::npos) << log;
    EXPECT_EQ(impactPower(storeOf(w.registry)), glm::dvec3(0.0));
}

/// Parameter: DETP in hybrid mode (the lights' first segments left to the shader: a ghost must
/// keep its light's flag) or photon mode.
class HundredMoves : public ::testing::TestWithParam<bool> {};

TEST_P(HundredMoves, AndLampsKeepTheStoresPowerAccountedAndDetpEqualToAFullEstimate) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    // Vertices all over, 10 cm apart on the mobiles and 25 cm on the room: discs to cross.
    MeshProcessingOptions refine;
    refine.maxEdgeLength = 0.1f;
    for (const Entity mobile : {room.cube, room.crate})
        registry.get<Mesh>(mobile) = processMesh(registry.get<Mesh>(mobile), refine);
    refine.maxEdgeLength = 0.25f;
    for (const Entity still : {room.walls, room.pillar})
        registry.get<Mesh>(still) = processMesh(registry.get<Mesh>(still), refine);
    buildRayScene(registry);
    PhotonSettings photonSettings = settingsWith(20'000);
    photonSettings.reshootBudget = 5'000;
    ASSERT_TRUE(photonSettings.reuseLandedPaths);
    PhotonUpdateSystem photons(photonSettings);
    photons.update(registry, FrameContext{});
    DetpSettings settings;
    settings.discRadius = 0.05f;
    settings.hybrid = GetParam();
    DetpIrradianceSystem detp(settings);
    detp.build(registry);
    detp.update(registry, FrameContext{});
    registry.clearChanges();
    const std::vector<Entity> meshes = registry.view<const Mesh>().entities();
    SumRounding rounding;
    rounding.add(storeOf(registry).segments);
    const Rings rings = meshRings(registry, meshes);

    std::mt19937 rng(2024);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    glm::vec3 cube = kCubeRest;
    std::size_t retraced = 0, landed = 0, reshotWithMoves = 0, edits = 0, added = 0, reshares = 0;
    std::size_t untouched = 0;
    Entity lamp;
    for (int frame = 1; frame <= 100; ++frame) {
        const float pick = unit(rng);
        if (pick < 0.7f) { // a 1 cm slide along x or z, turning back at the room's sides
            glm::vec3 step(0.f);
            step[unit(rng) < 0.5f ? 0 : 2] = unit(rng) < 0.5f ? -0.01f : 0.01f;
            if (glm::abs(cube + step).x > 1.5f || (cube + step).z < -1.5f || (cube + step).z > 0.4f)
                step = -step;
            cube += step;
            registry.patch<WorldTransform>(room.cube).matrix = translation(cube);
        }
        if (pick > 0.5f) { // the crate anywhere on the floor in front of the pillar, turned
            // (One draw per statement: the order of a call's arguments is unspecified.)
            const float x = -1.5f + 3.f * unit(rng);
            const float z = -1.5f + 1.9f * unit(rng);
            const float turn = glm::two_pi<float>() * unit(rng);
            registry.patch<WorldTransform>(room.crate).matrix =
                glm::rotate(translation({x, kCrateRest.y, z}), turn, glm::vec3(0.f, 1.f, 0.f));
        }
        if (frame % 25 == 0) {
            const float x = -1.f + 2.f * unit(rng);
            const float y = 0.5f + 0.7f * unit(rng);
            const float z = -1.f + unit(rng);
            registry.patch<WorldTransform>(room.light).matrix = translation({x, y, z});
        }
        // Lamps added and removed in play: their photons appended and shot within the
        // budget, then re-shot empty.
        if (frame == 30) lamp = test::addPointLight(registry, {-1.f, 0.5f, 1.f}, 5.f);
        if (frame == 55) registry.destroy(lamp);
        if (frame == 75) lamp = test::addPointLight(registry, {0.5f, 0.3f, -1.f}, 3.f);
        // The room light ten times brighter: the lamp holds 8x its share, so its photons are
        // dealt anew.
        if (frame == 85) registry.patch<PointLight>(room.light).intensity *= 10.f;
        if (frame % 20 == 7) { // a surface repainted: the pillar, then the cube, in turn
            const float red = 0.2f + 0.6f * unit(rng);
            registry.patch<Material>(frame % 40 == 7 ? room.pillar : room.cube).baseColor =
                glm::vec3(red, 0.4f, 0.5f);
        }
        registry.ctx().get<RayScene>().syncMoved(registry);

        const glm::dvec3 before = impactPower(storeOf(registry));
        photons.update(registry, FrameContext{std::uint64_t(frame), 0.0, 0.f, 0});
        const PhotonDelta& delta = deltaOf(registry);
        ASSERT_FALSE(delta.full) << "frame " << frame;
        const PhotonUpdateSystem::FrameStats& stats = photons.lastFrame();
        retraced += stats.retracedPaths;
        landed += stats.landedPaths;
        if (stats.reshotPaths > 0 && stats.retracedPaths > 0) ++reshotWithMoves;
        edits += stats.editedSurfaces;
        added += stats.addedPaths;
        reshares += stats.redealtLights;
        const glm::dvec3 after = impactPower(storeOf(registry));
        const glm::dvec3 expected = before -
                                    impactPower(delta.oldSegments, 0, delta.oldSegments.size()) +
                                    impactPower(delta.newSegments, 0, delta.newSegments.size());
        // Four double sums of at most n terms of at most p W each: within 4 n^2 p 2^-53.
        SumRounding bookkeeping;
        bookkeeping.add(storeOf(registry).segments);
        bookkeeping.add(delta.oldSegments);
        bookkeeping.add(delta.newSegments);
        for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(after[c], expected[c], 2.0 * bookkeeping.sums())
                << "frame " << frame << ", channel " << c;

        rounding.add(delta.oldSegments);
        rounding.add(delta.newSegments, 2.0 * double(delta.relabels.size()));
        // Every third frame of a small delta: the static vertices whose disc (1% wider) no
        // delta segment crosses, found by brute force, keep their irradiance bit for bit.
        const bool checkUntouched =
            frame % 3 == 0 && delta.oldSegments.size() + delta.newSegments.size() <= 4'000;
        std::vector<std::vector<glm::vec3>> staticBefore;
        if (checkUntouched)
            for (const Entity still : {room.walls, room.pillar})
                staticBefore.push_back(registry.get<VertexIrradiance>(still).irradiance);
        detp.update(registry, FrameContext{std::uint64_t(frame), 0.0, 0.f, 0});
        ASSERT_FALSE(detp.lastFrame().full) << "frame " << frame;
        if (checkUntouched) {
            std::size_t m = 0;
            for (const Entity still : {room.walls, room.pillar}) {
                const Mesh& mesh = registry.get<Mesh>(still);
                const glm::mat4& pose = registry.get<WorldTransform>(still).matrix;
                const auto& now = registry.get<VertexIrradiance>(still).irradiance;
                for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
                    const glm::vec3 center(pose * glm::vec4(mesh.positions[v], 1.f));
                    const glm::vec3 normal = glm::normalize(glm::mat3(pose) * mesh.normals[v]);
                    bool crossed = false;
                    for (const PhotonSegments* part : {&delta.oldSegments, &delta.newSegments})
                        for (std::size_t i = 0; i < part->size() && !crossed; ++i)
                            crossed = crossesDisc(part->origin[i], part->direction[i],
                                                  part->length[i], center, normal,
                                                  1.01f * settings.discRadius);
                    if (crossed) continue;
                    ++untouched;
                    ASSERT_EQ(std::memcmp(&now[v], &staticBefore[m][v], sizeof(glm::vec3)), 0)
                        << registry.get<Name>(still).value << " vertex " << v << ", frame "
                        << frame;
                }
                ++m;
            }
        }
        registry.clearChanges();
        if (frame % 10 == 0) {
            expectIrradianceOfAFullEstimate(registry, settings, meshes,
                                            roundingBound(settings, rounding, rings), frame);
            if (HasFatalFailure()) return;
        }
    }
    // Every kind of change happened: paths re-traced, landings kept, the lights' re-shoots in
    // frames where mobiles moved too, repainted surfaces, lamps added (10,000 photons
    // appended at the room light's 10 W/sr per 20,000; the second lamp's 6,000 from the
    // first's), and the second lamp's photons dealt anew (757 of the 26,000 lit photons, from
    // the first lamp's photons left).
    EXPECT_GT(retraced, 10'000u);
    EXPECT_GT(landed, 1'000u);
    EXPECT_GE(reshotWithMoves, 6u);
    EXPECT_EQ(edits, 5u);
    EXPECT_EQ(reshares, 1u);
    EXPECT_EQ(added, 10'000u);
    EXPECT_EQ(storeOf(registry).pathCount(), 30'000u);
    EXPECT_EQ(storeOf(registry).lights[0].photonCount, 20'000u);
    EXPECT_EQ(storeOf(registry).lights[2].photonCount, 757u); // the second lamp
    expectEachLightsPowerShot(storeOf(registry));
    EXPECT_GT(untouched, 10'000u);
    // Every record is true of the scene now, to the landing rule's tolerance (a millionth of
    // the room's diagonal).
    expectHitsReproduce(storeOf(registry), registry.ctx().get<RayScene>(),
                        1e-6f * glm::length(glm::vec3(4.f, 3.f, 4.f)));
}

INSTANTIATE_TEST_SUITE_P(PhotonUpdate, HundredMoves, ::testing::Bool(),
                         [](const auto& test) { return test.param ? "Hybrid" : "PhotonMode"; });

TEST(PhotonUpdate, APooledMobileParkedFarAwayChangesNothing) {
    // The crate waits out of the world 50 m away; the sun's photons still spread over the room
    // alone: the ray set is the one of the room without the crate, bit for bit.
    const auto shoot = [](bool parked) {
        auto registry = std::make_unique<Registry>();
        const test::Room room = buildRoom(*registry, kCubeRest, kCrateRest);
        if (parked) {
            registry->patch<WorldTransform>(room.crate).matrix = translation({50.f, 0.f, 0.f});
            registry->get<MobileMesh>(room.crate).active = false;
        } else {
            registry->destroy(room.crate);
        }
        const Entity sun = registry->create(); // its -Z axis points down
        registry->emplace<WorldTransform>(
            sun, glm::rotate(glm::mat4(1.f), -glm::half_pi<float>(), glm::vec3(1.f, 0.f, 0.f)));
        registry->emplace<DirectionalLight>(sun, DirectionalLight{glm::vec3(1.f), 1.f});
        buildRayScene(*registry);
        PhotonUpdateSystem system(settingsWith(20'000));
        firstUpdate(*registry, system);
        return registry;
    };
    const auto parked = shoot(true);
    const auto absent = shoot(false);
    EXPECT_TRUE(sameStore(storeOf(*parked), storeOf(*absent)));
}

TEST(PhotonUpdate, LightsThatLightNothingAreWarnedAbout) {
    // The room's light as it is (inside the closed room: no warning), moved 1 km away (nearly
    // every photon leaves the scene at once), and with no power (no photon carries light).
    enum class Case { Inside, FarAway, Dark };
    for (const Case c : {Case::Inside, Case::FarAway, Case::Dark}) {
        Registry registry;
        const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
        if (c == Case::FarAway)
            registry.patch<WorldTransform>(room.light).matrix = translation({1000.f, 0.f, 0.f});
        if (c == Case::Dark) registry.patch<PointLight>(room.light).intensity = 0.f;
        buildRayScene(registry);
        PhotonUpdateSystem system(settingsWith(5'000));
        const ScopedLogLevel verbose(LogLevel::Info); // whatever an earlier test left
        ::testing::internal::CaptureStderr();
        firstUpdate(registry, system);
        const std::string log = ::testing::internal::GetCapturedStderr();
        EXPECT_EQ(log.find("leave the scene without meeting a surface") != std::string::npos,
                  c == Case::FarAway)
            << log;
        EXPECT_EQ(log.find("every light is off or has no power") != std::string::npos,
                  c == Case::Dark)
            << log;
    }
}

TEST(PhotonUpdate, IncrementalEqualsFullRecomputeEveryFrame) {
    Registry incremental, baseline;
    const test::Room a = buildRoom(incremental, kCubeRest, kCrateRest);
    const test::Room b = buildRoom(baseline, kCubeRest, kCrateRest);
    buildRayScene(incremental);
    buildRayScene(baseline);
    PhotonSettings settings = settingsWith(10'000);
    // The seed's rule, bit for bit (ASlidingMobileKeepsThePathsThatLandWhereTheyDid covers
    // the reuse of landed paths, which keeps such paths as they were up to rounding).
    settings.reuseLandedPaths = false;
    PhotonUpdateSystem fast(settings);
    settings.fullRecompute = true;
    PhotonUpdateSystem slow(settings);
    firstUpdate(incremental, fast);
    firstUpdate(baseline, slow);
    const std::uint64_t generation = storeOf(baseline).generation;
    // The cornell benchmark's motion: 1 cm per frame. Surfaces are repainted on the way: the
    // pillar, the moving cube itself, and in frame 8 the cube again while the ray scene refuses
    // its new pose (not finite), so it stays, with its hits, where it was.
    for (std::uint64_t frame = 1; frame <= 10; ++frame) {
        glm::mat4 pose = translation(kCubeRest + glm::vec3(0.01f * float(frame), 0.f, 0.f));
        if (frame == 8) pose[3].x = std::numeric_limits<float>::quiet_NaN();
        const auto repaint = [&](Registry& r, const test::Room& room) {
            const float shade = 0.1f * float(frame);
            if (frame == 3 || frame == 6)
                r.patch<Material>(room.pillar).baseColor = glm::vec3(shade);
            if (frame == 5 || frame == 8) r.patch<Material>(room.cube).baseColor = glm::vec3(shade);
        };
        repaint(incremental, a);
        repaint(baseline, b);
        test::moveAndUpdate(incremental, fast, a.cube, pose, frame);
        test::moveAndUpdate(baseline, slow, b.cube, pose, frame);
        if (frame == 3 || frame == 5 || frame == 6 || frame == 8) {
            EXPECT_EQ(fast.lastFrame().editedSurfaces, 1u) << "frame " << frame;
        }
        EXPECT_FALSE(deltaOf(incremental).full);
        EXPECT_FALSE(deltaOf(incremental).empty());
        EXPECT_TRUE(deltaOf(baseline).full);
        ASSERT_TRUE(sameStore(storeOf(incremental), storeOf(baseline))) << "frame " << frame;
    }
    EXPECT_EQ(storeOf(baseline).generation, generation + 10);
    // The baseline never builds the index of paths (it would cost more than it saves there);
    // the incremental update keeps its own up to date.
    EXPECT_FALSE(baseline.ctx().get<PhotonPathGrid>().indexes(storeOf(baseline)));
    EXPECT_EQ(baseline.ctx().get<PhotonPathGrid>().entryCount(), 0u);
    EXPECT_TRUE(incremental.ctx().get<PhotonPathGrid>().indexes(storeOf(incremental)));
}

/// The landing rule (PhotonSettings::reuseLandedPaths), by brute force, for a segment that hit
/// `mobile` (which only translated): cast again through the whole scene, it lands on the same
/// mobile at the same distance within `tolerance`, on a triangle in the same plane (normals
/// from the test's own mesh).
bool landsAgain(const PhotonStore& before, const RayScene& scene, std::size_t s, Entity mobile,
                const Mesh& mesh, float tolerance) {
    const auto normal = [&](std::uint32_t t) {
        const glm::vec3 a = mesh.positions[mesh.indices[3 * t]];
        return glm::normalize(glm::cross(mesh.positions[mesh.indices[3 * t + 1]] - a,
                                         mesh.positions[mesh.indices[3 * t + 2]] - a));
    };
    if (before.segments.hitEntity[s] != mobile) return false;
    const std::optional<Hit> again =
        scene.intersect(Ray{before.segments.origin[s], 0.f, before.segments.direction[s],
                            std::numeric_limits<float>::infinity()});
    return again && again->entity == mobile &&
           std::abs(again->t - before.segments.length[s]) <= tolerance &&
           glm::length(normal(again->primitive) - normal(before.segments.hitPrimitive[s])) < 1e-5f;
}

TEST(PhotonUpdate, SmallMovesFindTheAffectedPathsAmongTheNearPathsExactly) {
    // Both mobiles drift a centimetre or two a frame, jumping now and then: their candidates
    // come from the paths kept near them (PhotonSettings::nearPathMargin), updated from each
    // frame's re-traced paths, and must still give exactly the brute-force affected set.
    // Coarse grid cells, so that near paths are worth keeping (kNearPathsPerGridPath).
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const RayScene& scene = buildRayScene(registry);
    PhotonSettings settings = settingsWith(20'000);
    settings.gridResolution = 6;
    settings.reuseLandedPaths = false; // the brute force below is the seed's rule
    ASSERT_GT(settings.nearPathMargin, 0.f);
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);

    std::mt19937 rng(77);
    std::uniform_real_distribution<float> step(-0.02f, 0.02f);
    glm::vec3 cube = kCubeRest, crate = kCrateRest;
    std::size_t fromNearPaths = 0, made = 0, retraced = 0;
    for (std::uint64_t frame = 1; frame <= 30; ++frame) {
        std::vector<std::pair<Entity, glm::mat4>> moves;
        for (auto [e, at] : {std::pair{room.cube, &cube}, std::pair{room.crate, &crate}}) {
            if (frame % 4 == 0 && e == room.crate) continue; // the crate rests now and then
            *at += frame % 10 == 0 ? glm::vec3(0.4f, 0.f, 0.f) * (at == &cube ? 1.f : -1.f)
                                   : glm::vec3(step(rng), 0.f, step(rng));
            moves.emplace_back(e, translation(*at));
        }
        const PhotonStore before = storeOf(registry);
        moveAll(registry, system, moves, frame);
        expectExactDelta(before, storeOf(registry), deltaOf(registry),
                         bruteForceFirstAffected(before, scene, moves));
        if (HasFatalFailure()) return;
        made += system.lastFrame().nearPathsMade;
        fromNearPaths += system.lastFrame().nearPathsMade == 0 ? 1 : 0;
        retraced += deltaOf(registry).paths.size();
    }
    EXPECT_GT(fromNearPaths, 15u); // most frames made no near paths anew
    EXPECT_GE(made, 6u);           // after the jumps at least
    EXPECT_GT(retraced, 1'000u);

    expectAFreshShotsStore(registry, settings, translation(cube), translation(crate));
}

TEST(PhotonUpdate, ASlidingMobileKeepsThePathsThatLandWhereTheyDid) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const RayScene& scene = buildRayScene(registry);
    const PhotonSettings settings = settingsWith(20'000);
    ASSERT_TRUE(settings.reuseLandedPaths); // the default
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    // The room's box (walls and mobiles): the system's tolerance is a millionth of its diagonal.
    const float tolerance = 1e-6f * glm::length(glm::vec3(4.f, 3.f, 4.f));
    // Impact count follows the deltas, relabelled landings included (checked at the end).
    DetpSettings impactSettings;
    impactSettings.estimator = IrradianceEstimator::ImpactCount;
    impactSettings.discRadius = 0.05f;
    DetpIrradianceSystem impacts(impactSettings);
    impacts.build(registry);
    impacts.update(registry, FrameContext{});
    std::size_t relabels = 0;
    // For the rounding bound at the end.
    SumRounding impactSums;
    impactSums.add(storeOf(registry).segments);

    std::size_t landed = 0, retraced = 0;
    glm::mat4 pose(1.f);
    for (std::uint64_t frame = 1; frame <= 12; ++frame) {
        // Slides over the floor along x and z: every top-face landing stays where it was.
        pose =
            translation(kCubeRest + glm::vec3(0.013f * float(frame), 0.f, -0.007f * float(frame)));
        const PhotonStore before = storeOf(registry);
        test::moveAndUpdate(registry, system, room.cube, pose, frame);
        const Mesh& mesh = registry.get<Mesh>(room.cube);
        const std::vector<int> expected =
            bruteForceFirstAffected(before, scene, {{room.cube, pose}}, [&](std::size_t s) {
                return landsAgain(before, scene, s, room.cube, mesh, tolerance);
            });
        expectExactDelta(before, storeOf(registry), deltaOf(registry), expected, {room.cube});
        if (HasFatalFailure()) return;
        impacts.update(registry, FrameContext{frame});
        const PhotonDelta& delta = deltaOf(registry);
        relabels += delta.relabels.size();
        impactSums.add(delta.oldSegments);
        impactSums.add(delta.newSegments, 2.0 * double(delta.relabels.size()));
        landed += system.lastFrame().landedPaths;
        retraced += system.lastFrame().retracedPaths;
    }
    EXPECT_GT(landed, 1'000u);   // the rule was exercised ...
    EXPECT_GT(retraced, 1'000u); // ... and so was re-tracing
    EXPECT_GT(relabels, 10u);    // ... and landings slid onto the top face's other triangle
    {
        // Incremental impact count equals a full count over the final ray set, to the double
        // sums' rounding (a misplaced landing would be off by a whole photon). The bound of
        // ImpactCount.SystemIncrementalEqualsFull: per triangle, the two double sums are each
        // within n^2 p 2^-53 W of the exact one (n additions of at most p W a channel, partial
        // sums below n p; n counts the incremental side's additions, which are at least the full
        // count's); a vertex divides the sum over its ring of at most R triangles by the
        // ring's area, at least the smallest triangle's (the system's float areas, from world
        // positions rounded to 2^-23 m on edges of 0.4 m or more, are within 2^-16 of those
        // here), then rounds to float, 2^-24 relative each way; the ring sums' and divisions' own
        // double roundings and second-order terms add less than 2^-40 relative.
        std::vector<std::vector<glm::vec3>> incremental;
        const std::vector<Entity> meshes = registry.view<const Mesh>().entities();
        for (const Entity e : meshes)
            incremental.push_back(registry.get<VertexIrradiance>(e).irradiance);
        const Rings rings = meshRings(registry, meshes);
        const double absolute =
            rings.largest * impactSums.sums() / (rings.smallestTriangle * (1.0 - 0x1p-16));
        DetpIrradianceSystem reference(impactSettings);
        reference.build(registry);
        reference.update(registry, FrameContext{});
        for (std::size_t m = 0; m < meshes.size(); ++m) {
            const auto& full = registry.get<VertexIrradiance>(meshes[m]).irradiance;
            for (std::size_t v = 0; v < full.size(); ++v)
                for (int c = 0; c < 3; ++c)
                    ASSERT_NEAR(incremental[m][v][c], full[v][c],
                                (0x1p-23 + 0x1p-40) * std::abs(double(full[v][c])) + absolute)
                        << "mesh " << m << " vertex " << v;
        }
    }
    // Every record is true of the scene now, to the tolerance the rule allows.
    expectHitsReproduce(storeOf(registry), scene, tolerance);

    // A fresh shot with the cube where it ended: the same paths, bounce for bounce, on the same
    // surfaces, with the same powers and directions. A bounce direction depends only on the
    // photon's hash and the face's normal, exact for these axis-aligned boxes, so the directions
    // agree exactly. Kept segments start near the fresh ones: two rays of direction d whose
    // origins are within B meet a plane of unit normal n at points within B / |d.n| (the offset
    // projected along d onto the plane). Each side's cast is exact to 10 u D / |d.n| (u = 2^-24;
    // t is a quotient of float products of coordinates and distances below the room's diagonal
    // D), its landing point o + t d to 2 u D and the surface offset to u D; a landing on the cube
    // kept by the rule is at most the rule's tolerance further along d; the offset, 1e-4 of the
    // landing point's largest coordinate, adds 1e-4 of the landing points' difference. So
    // segment k + 1 starts within
    //   B_{k+1} = (1 + 1e-4) ((B_k + 26 u D) / |d_k.n_k| + tolerance [segment k hit the cube])
    // of the fresh one, B_0 = 0 (the same emission).
    Registry fresh;
    const test::Room again = buildRoom(fresh, kCubeRest, kCrateRest);
    fresh.patch<WorldTransform>(again.cube).matrix = pose;
    const RayScene& freshScene = buildRayScene(fresh);
    PhotonUpdateSystem full(settings);
    firstUpdate(fresh, full);
    const PhotonStore& a = storeOf(registry);
    const PhotonStore& b = storeOf(fresh);
    ASSERT_EQ(a.pathCount(), b.pathCount());
    const double rounding = 26.0 * 0x1p-24 * glm::length(glm::dvec3(4.0, 3.0, 4.0));
    std::size_t differing = 0, segments = 0, displaced = 0;
    for (std::size_t p = 0; p < a.pathCount(); ++p) {
        const PhotonPath& pa = a.paths[p];
        const PhotonPath& pb = b.paths[p];
        bool same = pa.count == pb.count;
        double bound = 0.0; // B_k
        for (std::size_t k = 0; same && k < pa.count; ++k) {
            const std::size_t s = pa.first + k, t = pb.first + k;
            same = a.segments.hitEntity[s] == b.segments.hitEntity[t] &&
                   a.segments.power[s] == b.segments.power[t] &&
                   a.segments.direction[s] == b.segments.direction[t];
            const double offset =
                glm::distance(glm::dvec3(a.segments.origin[s]), glm::dvec3(b.segments.origin[t]));
            displaced += offset > bound ? 1 : 0;
            if (!same || b.segments.hitEntity[t].isNull()) continue;
            const std::optional<Hit> hit =
                freshScene.intersect(Ray{b.segments.origin[t], 0.f, b.segments.direction[t],
                                         std::numeric_limits<float>::infinity()});
            ASSERT_TRUE(hit.has_value()) << "path " << p << " segment " << k;
            const double cosine =
                std::abs(glm::dot(glm::dvec3(hit->normal), glm::dvec3(b.segments.direction[t])));
            bound = (1.0 + 1e-4) * ((bound + rounding) / cosine +
                                    (a.segments.hitEntity[s] == room.cube ? tolerance : 0.0));
        }
        differing += same ? 0 : 1;
        segments += pa.count;
    }
    EXPECT_EQ(differing, 0u);
    EXPECT_EQ(displaced, 0u);
    EXPECT_GT(segments, a.pathCount());
}

TEST(PhotonUpdate, ALandingIsBlockedByAnotherMovedMobileInTheWay) {
    // Both mobiles slide every frame: the cube over the floor, the crate hovering above it and
    // crossing the light's rays to the cube's top face. A segment that lands on the cube where
    // it did is still re-traced when the crate's new pose is in its way, and landings on the
    // crate's faces count too. Brute force: the whole scene cast again at the new poses.
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const RayScene& scene = buildRayScene(registry);
    PhotonUpdateSystem system(settingsWith(20'000));
    firstUpdate(registry, system);
    const float tolerance = 1e-6f * glm::length(glm::vec3(4.f, 3.f, 4.f));
    const auto crateAt = [](float frame) {
        return translation(kCubeRest + glm::vec3(-0.45f + 0.06f * frame, 0.6f, 0.f));
    };

    std::size_t landed = 0, retraced = 0, blocked = 0;
    for (std::uint64_t frame = 1; frame <= 14; ++frame) {
        const glm::mat4 cubePose =
            translation(kCubeRest + glm::vec3(0.011f * float(frame), 0.f, 0.005f * float(frame)));
        const glm::mat4 cratePose = crateAt(float(frame));
        const PhotonStore before = storeOf(registry);
        registry.patch<WorldTransform>(room.cube).matrix = cubePose;
        test::moveAndUpdate(registry, system, room.crate, cratePose, frame);
        const std::vector<int> expected = bruteForceFirstAffected(
            before, scene, {{room.cube, cubePose}, {room.crate, cratePose}}, [&](std::size_t s) {
                for (const Entity mobile : {room.cube, room.crate})
                    if (landsAgain(before, scene, s, mobile, registry.get<Mesh>(mobile), tolerance))
                        return true;
                return false;
            });
        expectExactDelta(before, storeOf(registry), deltaOf(registry), expected,
                         {room.cube, room.crate});
        if (HasFatalFailure()) return;
        EXPECT_EQ(deltaOf(registry).movedMobiles.size(), 2u);
        landed += system.lastFrame().landedPaths;
        retraced += system.lastFrame().retracedPaths;
        // Segments on the cube's top face that the crate now shades: the case this test is for.
        const PhotonSegments& old = before.segments;
        for (std::size_t seg = 0; seg < old.size(); ++seg)
            if (old.hitEntity[seg] == room.cube && old.direction[seg].y < 0.f &&
                old.origin[seg].y > kCubeRest.y + 1.f &&
                scene.intersectMobile(
                    room.crate, cratePose,
                    Ray{old.origin[seg], 0.f, old.direction[seg], old.length[seg]}))
                ++blocked;
    }
    EXPECT_GT(landed, 500u);
    EXPECT_GT(retraced, 500u);
    EXPECT_GT(blocked, 50u); // the blocking case was exercised
    expectHitsReproduce(storeOf(registry), scene, tolerance);
}

TEST(PhotonUpdate, AMobileFarFromEveryPathChangesNothing) {
    // A closed room: no photon leaves it, and the crate moves about outside.
    Registry registry;
    test::addMesh(registry, test::boxMesh({2.f, 1.5f, 2.f}, true), glm::mat4(1.f), test::grey(0.7f),
                  false, "closed room");
    const Entity crate =
        test::addMesh(registry, test::boxMesh(glm::vec3(0.3f)), translation({6.f, 0.f, 0.f}),
                      test::grey(0.5f), true, "crate outside");
    test::addPointLight(registry, {0.f, 1.f, 0.f}, 5.f);
    buildRayScene(registry);
    PhotonUpdateSystem system(settingsWith(10'000));
    firstUpdate(registry, system);
    const PhotonStore before = storeOf(registry);
    for (const glm::vec3 at : {glm::vec3(6.f, 1.f, 0.f), glm::vec3(5.f, -1.f, 3.f)}) {
        test::moveAndUpdate(registry, system, crate, translation(at), 1);
        EXPECT_TRUE(deltaOf(registry).empty());
        EXPECT_EQ(system.lastFrame().movedMobiles, 1u);
        EXPECT_EQ(system.lastFrame().candidatePaths, 0u); // the index knew: no exact tests
    }
    EXPECT_TRUE(sameStore(before, storeOf(registry)));
}

TEST(PhotonUpdate, AMobileParkedPastTheRayScenesReachStaysWhereItWas) {
    // Hiding an object by moving it "far away": past kMaxPoseReach the ray scene keeps its last
    // pose (Embree aborts on rays that far out), so the photons do not change either.
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    buildRayScene(registry);
    PhotonUpdateSystem system(settingsWith(20'000));
    firstUpdate(registry, system);
    const PhotonStore before = storeOf(registry);
    {
        const ScopedLogLevel quiet(LogLevel::Quiet);
        for (const float far : {1e30f, 1e19f, 2e7f}) {
            test::moveAndUpdate(registry, system, room.crate, translation({far, 0.f, 0.f}), 1);
            EXPECT_TRUE(deltaOf(registry).empty()) << far;
            EXPECT_EQ(system.lastFrame().movedMobiles, 0u) << far;
        }
    }
    EXPECT_TRUE(sameStore(before, storeOf(registry)));
}

// ---- moving and changing lights
// ------------------------------------------------------------------

TEST(PhotonUpdate, AMovedLightIsReshotWithinTheBudgetUntilItMatchesAFullShot) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    buildRayScene(registry);
    PhotonSettings settings = settingsWith(10'000);
    settings.reshootBudget = 3'000;
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);

    const glm::vec3 moved(0.5f, 0.9f, -0.3f);
    registry.patch<WorldTransform>(room.light).matrix = translation(moved);
    registry.patch<PointLight>(room.light).intensity = 12.f;
    std::vector<std::size_t> perFrame;
    std::vector<bool> seen(10'000, false);
    for (std::uint64_t frame = 1; frame <= 5; ++frame) {
        const PhotonStore before = storeOf(registry);
        system.update(registry, FrameContext{frame, 0.0, 0.f, 0});
        registry.clearChanges();
        const PhotonDelta& delta = deltaOf(registry);
        const PhotonStore& after = storeOf(registry);
        ASSERT_FALSE(delta.full);
        perFrame.push_back(delta.paths.size());
        for (std::size_t i = 0; i < delta.paths.size(); ++i) {
            const std::uint32_t p = delta.paths[i];
            EXPECT_FALSE(seen[p]) << "photon " << p << " re-shot twice";
            seen[p] = true;
            // Whole paths: the old one as stored, the new one from the moved light.
            ASSERT_EQ(delta.oldFirst[i + 1] - delta.oldFirst[i], before.paths[p].count);
            ASSERT_EQ(delta.newFirst[i + 1] - delta.newFirst[i], after.paths[p].count);
            EXPECT_EQ(delta.newSegments.origin[delta.newFirst[i]], moved);
            EXPECT_EQ(delta.newSegments.bounce[delta.newFirst[i]], 0);
        }
    }
    EXPECT_EQ(perFrame, (std::vector<std::size_t>{3'000, 3'000, 3'000, 1'000, 0}));
    const PhotonStore& store = storeOf(registry);
    const glm::vec3 power = 4.f * glm::pi<float>() * 12.f * glm::vec3(1.f);
    EXPECT_EQ(store.lights[0].power, power);
    EXPECT_EQ(store.emittedPower, power);

    Registry fresh;
    const test::Room again = buildRoom(fresh, kCubeRest, kCrateRest);
    fresh.patch<WorldTransform>(again.light).matrix = translation(moved);
    fresh.patch<PointLight>(again.light).intensity = 12.f;
    buildRayScene(fresh);
    PhotonUpdateSystem full(settings);
    firstUpdate(fresh, full);
    EXPECT_TRUE(sameStore(store, storeOf(fresh)));
}

TEST(PhotonUpdate, ALightSwitchedOffAndOnIsReshotWithinTheBudget) {
    // A light switched off keeps its photons, re-shot empty within the budget (no full shot,
    // no frame paying for all of them); switched on again, they are re-shot from it and the
    // store is again the one a full shot gives. The other light's paths are never touched.
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const float intensity = registry.get<PointLight>(room.light).intensity;
    const Entity lamp = test::addPointLight(registry, {-1.f, 0.5f, 1.f}, intensity);
    buildRayScene(registry);
    PhotonSettings settings = settingsWith(10'000);
    settings.reshootBudget = 3'000;
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    const PhotonStore shot = storeOf(registry);
    ASSERT_EQ(shot.lights.size(), 2u);
    ASSERT_EQ(shot.lights[1].photonCount, 5'000u);
    const std::uint32_t first = 5'000; // the lamp's photons: [5000, 10000)

    // Frames until the sweep is done: each re-shoots at most the budget, lamp photons only,
    // each once; returns how many each frame re-shot.
    std::uint64_t frame = 0;
    const auto sweep = [&](bool on) {
        std::vector<std::size_t> perFrame;
        std::vector<bool> seen(10'000, false);
        for (int i = 0; i < 4; ++i) {
            const PhotonStore before = storeOf(registry);
            system.update(registry, FrameContext{++frame, 0.0, 0.f, 0});
            registry.clearChanges();
            const PhotonDelta& delta = deltaOf(registry);
            const PhotonStore& after = storeOf(registry);
            EXPECT_FALSE(delta.full);
            perFrame.push_back(delta.paths.size());
            for (std::size_t j = 0; j < delta.paths.size(); ++j) {
                const std::uint32_t p = delta.paths[j];
                EXPECT_GE(p, first);
                EXPECT_FALSE(seen[p]) << "photon " << p << " re-shot twice";
                seen[p] = true;
                EXPECT_EQ(delta.oldFirst[j + 1] - delta.oldFirst[j], before.paths[p].count);
                EXPECT_EQ(delta.newFirst[j + 1] - delta.newFirst[j], after.paths[p].count);
                EXPECT_EQ(after.paths[p].count > 0, on) << "photon " << p;
            }
        }
        return perFrame;
    };

    registry.patch<PointLight>(lamp).intensity = 0.f;
    EXPECT_EQ(sweep(false), (std::vector<std::size_t>{3'000, 2'000, 0, 0}));
    const PhotonStore& dark = storeOf(registry);
    EXPECT_EQ(dark.lights[1].power, glm::vec3(0.f));
    EXPECT_EQ(dark.emittedPower, shot.lights[0].power);
    for (std::uint32_t p = 0; p < 10'000; ++p) {
        if (p >= first) {
            ASSERT_EQ(dark.paths[p].count, 0u) << "photon " << p;
            continue;
        }
        ASSERT_EQ(dark.paths[p].count, shot.paths[p].count);
        for (std::uint32_t k = 0; k < shot.paths[p].count; ++k)
            ASSERT_TRUE(test::sameSegment(dark.segments, dark.paths[p].first + k, shot.segments,
                                          shot.paths[p].first + k));
    }

    // A mobile moved while the lamp is dark re-traces only the lit light's paths (empty ones
    // touch nothing), and back at its pose, the store is the shot's again.
    const glm::mat4 away = translation(kCubeRest + glm::vec3(0.3f, 0.2f, 0.4f));
    moveAll(registry, system, {{room.cube, away}}, ++frame);
    ASSERT_FALSE(deltaOf(registry).paths.empty());
    for (const std::uint32_t p : deltaOf(registry).paths)
        EXPECT_LT(p, first) << "a dark lamp's empty path was re-traced";
    moveAll(registry, system, {{room.cube, translation(kCubeRest)}}, ++frame);

    registry.patch<PointLight>(lamp).intensity = intensity;
    EXPECT_EQ(sweep(true), (std::vector<std::size_t>{3'000, 2'000, 0, 0}));
    EXPECT_TRUE(sameStore(storeOf(registry), shot));
    EXPECT_EQ(storeOf(registry).emittedPower, shot.emittedPower);
}

/// The room with its crate glowing (an emissive mobile), and its ray scene.
test::Room buildGlowingCrateRoom(Registry& registry) {
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    registry.get<Material>(room.crate).emission = glm::vec3(20.f);
    buildRayScene(registry);
    return room;
}

TEST(PhotonUpdate, AnEmissiveSurfaceThatCannotEmitGoesDarkWithoutAFullShot) {
    // An emissive mobile whose emission turns invalid (or a surface scaled to nothing) keeps
    // its place among the lights with no power: its photons are re-shot empty, and its
    // triangles, gone, are never sampled.
    Registry registry;
    const test::Room room = buildGlowingCrateRoom(registry);
    PhotonSettings settings = settingsWith(8'000);
    settings.reshootBudget = 100'000;
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    ASSERT_EQ(storeOf(registry).lights.size(), 2u);
    const PhotonLight crate = storeOf(registry).lights[1];
    ASSERT_GT(crate.photonCount, 0u);

    {
        const ScopedLogLevel quiet(LogLevel::Quiet); // the warning that the surface cannot emit
        registry.patch<Material>(room.crate).emission = glm::vec3(-1.f);
        system.update(registry, FrameContext{1, 0.0, 0.f, 0});
        registry.clearChanges();
    }
    EXPECT_FALSE(deltaOf(registry).full);
    EXPECT_EQ(deltaOf(registry).paths.size(), crate.photonCount);
    const PhotonStore& store = storeOf(registry);
    for (std::uint32_t p = 0; p < store.pathCount(); ++p) {
        if (store.paths[p].light == 1) {
            EXPECT_EQ(store.paths[p].count, 0u) << "photon " << p;
        }
    }
}

TEST(PhotonUpdate, AnEmissiveMobileTakenOutOrDimmedKeepsItsPhotonsUntilItShinesAgain) {
    // An emissive surface the photons were shot from stays a light while it is dark, taken out
    // of the world (MobileMesh::active) or its emission set to 0: its photons are re-shot empty
    // within the budget, not every photon shot anew, and come back when it shines again.
    Registry registry;
    const test::Room room = buildGlowingCrateRoom(registry);
    PhotonSettings settings = settingsWith(10'000);
    settings.reshootBudget = 2'000;
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    const PhotonStore shot = storeOf(registry);
    ASSERT_EQ(shot.lights.size(), 2u);
    const std::uint32_t glowing = shot.lights[1].photonCount;
    ASSERT_GT(glowing, 2'000u);

    std::uint64_t frame = 0;
    // Frames until the crate's photons are all re-shot; true when none was a full shot and
    // they ended as `empty` says.
    const auto sweep = [&](bool empty) {
        for (std::uint32_t f = 0; f <= glowing / 2'000 + 1; ++f) {
            system.update(registry, FrameContext{++frame, 0.0, 0.f, 0});
            registry.clearChanges();
            if (deltaOf(registry).full) return false;
        }
        const PhotonStore& store = storeOf(registry);
        for (std::uint32_t p = 0; p < store.pathCount(); ++p)
            if (store.paths[p].light == 1 && (store.paths[p].count == 0) != empty) return false;
        return true;
    };

    registry.patch<Material>(room.crate).emission = glm::vec3(0.f);
    EXPECT_TRUE(sweep(true));
    EXPECT_EQ(storeOf(registry).lights[1].power, glm::vec3(0.f));
    registry.patch<Material>(room.crate).emission = glm::vec3(20.f);
    EXPECT_TRUE(sweep(false));
    EXPECT_TRUE(sameStore(storeOf(registry), shot));

    // Out of the world: the paths it was in the way of are re-traced at once; its own photons
    // go dark within the budget.
    registry.patch<MobileMesh>(room.crate).active = false;
    registry.ctx().get<RayScene>().syncMoved(registry);
    EXPECT_TRUE(sweep(true));
    registry.patch<MobileMesh>(room.crate).active = true;
    registry.ctx().get<RayScene>().syncMoved(registry);
    EXPECT_TRUE(sweep(false));
    EXPECT_TRUE(sameStore(storeOf(registry), shot));
}

TEST(PhotonUpdate, ARedPhotonOnAGreenWallIsTracedOnWhenReTraced) {
    // Power can drop to zero in a path (red light, green albedo): a fresh shot traces such a
    // photon on, and a re-traced suffix must too (only photons that leave a light dark are
    // not traced).
    const auto build = [](Registry& r, const glm::mat4& cratePose) {
        const test::Room room = buildRoom(r, kCubeRest, kCrateRest);
        r.get<PointLight>(room.light).color = glm::vec3(1.f, 0.f, 0.f);
        r.get<Material>(room.walls).baseColor = glm::vec3(0.f, 0.7f, 0.f);
        r.get<WorldTransform>(room.crate).matrix = cratePose;
        buildRayScene(r);
        return room;
    };
    PhotonSettings settings = settingsWith(20'000);
    settings.reuseLandedPaths = false; // the seed's rule: bit for bit a fresh shot
    Registry registry;
    const test::Room room = build(registry, translation(kCrateRest));
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    std::size_t dark = 0;
    const PhotonStore& shot = storeOf(registry);
    for (std::size_t s = 0; s < shot.segments.size(); ++s)
        dark += shot.segments.bounce[s] > 0 && shot.segments.power[s] == glm::vec3(0.f) ? 1 : 0;
    EXPECT_GT(dark, 1000u); // the case is exercised

    const glm::mat4 moved = translation(kCrateRest + glm::vec3(0.3f, 0.5f, 0.3f));
    moveAll(registry, system, {{room.crate, moved}}, 1);
    Registry fresh;
    build(fresh, moved);
    PhotonUpdateSystem full(settings);
    firstUpdate(fresh, full);
    EXPECT_TRUE(sameStore(storeOf(registry), storeOf(fresh)));
}

/// Updates until `frames` frames have passed with no full shot; returns the paths each frame
/// re-shot (re-traced paths aside: nothing moves).
std::vector<std::size_t> reshotPerFrame(Registry& registry, PhotonUpdateSystem& system,
                                        std::uint64_t& frame, int frames) {
    std::vector<std::size_t> perFrame;
    for (int i = 0; i < frames; ++i) {
        system.update(registry, FrameContext{++frame, 0.0, 0.f, 0});
        registry.clearChanges();
        EXPECT_FALSE(deltaOf(registry).full) << "frame " << frame;
        perFrame.push_back(system.lastFrame().reshotPaths);
    }
    return perFrame;
}

TEST(PhotonUpdate, AnAddedLightGetsPhotonsAtTheSamePowerPerPhotonShotWithinTheBudget) {
    // The room's 10 W/sr light has 4,000 photons; a 5 W/sr lamp added in play gets 2,000 more,
    // appended as photons 4,000 to 5,999 and shot 800 a frame. Photon i's choices come from i
    // and its light's power per photon is unchanged, so the result is, bit for bit, the full
    // shot of 6,000 photons over both lights; a mobile moved during the sweep re-traces
    // only what it touches, the new photons included.
    PhotonSettings settings = settingsWith(4'000);
    settings.reshootBudget = 800;
    settings.reuseLandedPaths = false; // the seed's rule: bit for bit a fresh shot
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    buildRayScene(registry);
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    const PhotonStore shot = storeOf(registry);

    const glm::vec3 lampAt(-1.f, 0.5f, 1.f);
    test::addPointLight(registry, lampAt, 5.f);
    std::uint64_t frame = 0;
    EXPECT_EQ(reshotPerFrame(registry, system, frame, 1), std::vector<std::size_t>{800});
    EXPECT_EQ(system.lastFrame().addedPaths, 2'000u);
    const glm::mat4 moved = translation(kCubeRest + glm::vec3(0.4f, 0.f, 0.3f));
    moveAll(registry, system, {{room.cube, moved}}, ++frame);
    EXPECT_FALSE(deltaOf(registry).full);
    EXPECT_GT(system.lastFrame().retracedPaths, 0u);
    EXPECT_EQ(reshotPerFrame(registry, system, frame, 2), (std::vector<std::size_t>{400, 0}));

    const PhotonStore& store = storeOf(registry);
    ASSERT_EQ(store.pathCount(), 6'000u);
    ASSERT_EQ(store.lights.size(), 2u);
    EXPECT_EQ(store.lights[1].photonCount, 2'000u);
    EXPECT_EQ(store.emittedPower, shot.emittedPower * 1.5f);
    for (std::uint32_t p = 4'000; p < 6'000; ++p) {
        ASSERT_GT(store.paths[p].count, 0u) << "photon " << p;
        EXPECT_EQ(store.segments.origin[store.paths[p].first], lampAt);
    }

    Registry fresh;
    const test::Room again = buildRoom(fresh, kCubeRest, kCrateRest);
    test::addPointLight(fresh, lampAt, 5.f);
    fresh.get<WorldTransform>(again.cube).matrix = moved;
    buildRayScene(fresh);
    PhotonSettings both = settings;
    both.photonCount = 6'000;
    PhotonUpdateSystem full(both);
    firstUpdate(fresh, full);
    EXPECT_TRUE(sameStore(store, storeOf(fresh)));
}

TEST(PhotonUpdate, ARemovedLightsPhotonsGoDarkAndAreHandedOnAndTheStoreGrowsAtMostThreefold) {
    // A lamp destroyed in play keeps its photons, re-shot empty; then they are free, and a
    // light added later that fits takes them. Others are appended while the store has room
    // (three times photonCount). One that would get under a quarter of its share has the
    // photons shared anew at once: a full shot, which drops the removed lamp.
    PhotonSettings settings = settingsWith(4'000);
    settings.reshootBudget = 100'000;
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const Entity lamp = test::addPointLight(registry, {-1.f, 0.5f, 1.f}, 10.f);
    buildRayScene(registry);
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    const PhotonStore shot = storeOf(registry);
    ASSERT_EQ(shot.lights[1].photonCount, 2'000u);

    registry.destroy(lamp);
    std::uint64_t frame = 0;
    EXPECT_EQ(reshotPerFrame(registry, system, frame, 2), (std::vector<std::size_t>{2'000, 0}));
    const PhotonStore& dark = storeOf(registry);
    EXPECT_EQ(dark.lights[1].power, glm::vec3(0.f));
    EXPECT_EQ(dark.emittedPower, shot.lights[0].power);
    for (std::uint32_t p = 0; p < 4'000; ++p) {
        ASSERT_EQ(dark.paths[p].count == 0, p >= 2'000) << "photon " << p;
        if (p < 2'000) {
            ASSERT_EQ(dark.paths[p].count, shot.paths[p].count);
            for (std::uint32_t k = 0; k < shot.paths[p].count; ++k)
                ASSERT_TRUE(sameSegment(dark.segments, dark.paths[p].first + k, shot.segments,
                                        shot.paths[p].first + k));
        }
    }

    // 30 W/sr at 2,000 photons per 10 W/sr wants 6,000: more than the lamp's 2,000 free
    // photons, so appended; 10 W/sr more wants 2,000, and takes the lamp's.
    const Entity big = test::addPointLight(registry, {1.f, 0.5f, -1.f}, 30.f);
    EXPECT_EQ(reshotPerFrame(registry, system, frame, 1), std::vector<std::size_t>{6'000});
    EXPECT_EQ(storeOf(registry).pathCount(), 10'000u);
    EXPECT_EQ(storeOf(registry).lights[2].photonCount, 6'000u);
    const Entity small = test::addPointLight(registry, {0.5f, 0.5f, 0.5f}, 10.f);
    EXPECT_EQ(reshotPerFrame(registry, system, frame, 1), std::vector<std::size_t>{2'000});
    EXPECT_EQ(system.lastFrame().addedPaths, 0u);
    {
        const PhotonStore& store = storeOf(registry);
        EXPECT_EQ(store.pathCount(), 10'000u);
        ASSERT_EQ(store.lights.size(), 4u);
        EXPECT_EQ(store.lights[1].photonCount, 0u); // the removed lamp's, handed on
        EXPECT_EQ(store.lights[3].photonCount, 2'000u);
        for (std::uint32_t p = 2'000; p < 4'000; ++p) {
            ASSERT_EQ(store.paths[p].light, 3u) << "photon " << p;
            ASSERT_GT(store.paths[p].count, 0u) << "photon " << p;
        }
    }

    // 100 W/sr wants 20,000: 2,000 of room is under a quarter of that.
    const Entity huge = test::addPointLight(registry, {-0.5f, 0.5f, 0.5f}, 100.f);
    system.update(registry, FrameContext{++frame, 0.0, 0.f, 0});
    registry.clearChanges();
    EXPECT_TRUE(deltaOf(registry).full);
    const PhotonStore& store = storeOf(registry);
    EXPECT_EQ(store.pathCount(), 4'000u);
    ASSERT_EQ(store.lights.size(), 4u); // the removed lamp dropped
    const std::array<std::pair<Entity, float>, 4> lights{
        {{room.light, 10.f}, {big, 30.f}, {small, 10.f}, {huge, 100.f}}};
    std::uint32_t total = 0;
    for (std::size_t l = 0; l < lights.size(); ++l) {
        EXPECT_EQ(store.lights[l].entity, lights[l].first);
        EXPECT_NEAR(double(store.lights[l].photonCount), 4'000.0 * lights[l].second / 150.0, 1.0);
        total += store.lights[l].photonCount;
    }
    EXPECT_EQ(total, 4'000u);
}

TEST(PhotonUpdate, ALightAddedOrLitWhenTheStoreIsEmptyGetsPhotonCountPhotons) {
    // Shot with every light dark (or none at all), the store holds no photon; a light lit or
    // created later gets photonCount photons of its own, shot within the budget.
    for (const bool created : {false, true}) {
        SCOPED_TRACE(created ? "created" : "lit");
        Registry registry;
        const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
        if (created)
            registry.destroy(room.light);
        else
            registry.get<PointLight>(room.light).intensity = 0.f;
        buildRayScene(registry);
        PhotonSettings settings = settingsWith(4'000);
        settings.reshootBudget = 1'500;
        PhotonUpdateSystem system(settings);
        firstUpdate(registry, system);
        ASSERT_EQ(storeOf(registry).segments.size(), 0u);
        if (created)
            test::addPointLight(registry, {0.f, 1.2f, 0.f}, 10.f);
        else
            registry.patch<PointLight>(room.light).intensity = 10.f;
        std::uint64_t frame = 0;
        EXPECT_EQ(reshotPerFrame(registry, system, frame, 4),
                  (std::vector<std::size_t>{1'500, 1'500, 1'000, 0}));
        const PhotonStore& store = storeOf(registry);
        ASSERT_EQ(store.pathCount(), 4'000u);
        for (std::uint32_t p = 0; p < 4'000; ++p)
            ASSERT_GT(store.paths[p].count, 0u) << "photon " << p;
        expectEachLightsPowerShot(store);
    }
}

/// The index of the light shot from `e` in the store's list.
std::size_t lightOf(const PhotonStore& store, Entity e) {
    for (std::size_t l = 0; l < store.lights.size(); ++l)
        if (store.lights[l].entity == e) return l;
    ADD_FAILURE() << "no light of entity " << e.index;
    return 0;
}

/// Light l's photons: [first, end) of the store's paths, checked contiguous.
std::pair<std::uint32_t, std::uint32_t> rangeOf(const PhotonStore& store, std::size_t l) {
    std::uint32_t first = 0, end = 0;
    bool found = false;
    for (std::uint32_t p = 0; p < store.pathCount(); ++p) {
        if (store.paths[p].light != l) continue;
        if (!found) first = p;
        EXPECT_TRUE(!found || p == end) << "light " << l << " holds a second range at " << p;
        found = true;
        end = p + 1;
    }
    return {first, end};
}

TEST(PhotonUpdate, PhotonsOfRemovedLightsAreHandedOnOnlyOnceDarkAndNeighboursMerged) {
    // Four 10 W/sr lights, 1,000 photons each in photon order; the second and third destroyed.
    // A light added while their photons are still being re-shot empty may not take them: it
    // is appended, with 1,333 photons (photonCount over the 30 W/sr that shine: the lit
    // lights' 2,000 are too few). Once dark, their two ranges are one, and a 15 W/sr light
    // wanting 1,666 (at the lit lights' 3,333 per 30 W/sr) takes its start.
    PhotonSettings settings = settingsWith(4'000);
    settings.reshootBudget = 500;
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    std::array<Entity, 3> lamps;
    for (std::size_t i = 0; i < lamps.size(); ++i)
        lamps[i] = test::addPointLight(registry, {-1.f + float(i), 0.5f, 1.f}, 10.f);
    buildRayScene(registry);
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    ASSERT_EQ(rangeOf(storeOf(registry), 1),
              (std::pair<std::uint32_t, std::uint32_t>{1'000, 2'000}));
    ASSERT_EQ(rangeOf(storeOf(registry), 2),
              (std::pair<std::uint32_t, std::uint32_t>{2'000, 3'000}));

    registry.destroy(lamps[0]);
    registry.destroy(lamps[1]);
    std::uint64_t frame = 0;
    reshotPerFrame(registry, system, frame, 1); // 500 of their 2,000 photons
    const Entity early = test::addPointLight(registry, {0.f, 0.5f, -1.f}, 10.f);
    reshotPerFrame(registry, system, frame, 8); // the rest, and the new light's 1,000
    EXPECT_EQ(rangeOf(storeOf(registry), lightOf(storeOf(registry), early)),
              (std::pair<std::uint32_t, std::uint32_t>{4'000, 5'333}));
    EXPECT_EQ(system.lastFrame().reshotPaths, 0u);

    const Entity late = test::addPointLight(registry, {0.5f, 0.5f, -1.f}, 15.f);
    reshotPerFrame(registry, system, frame, 1);
    EXPECT_EQ(system.lastFrame().addedPaths, 0u);
    EXPECT_EQ(reshotPerFrame(registry, system, frame, 4),
              (std::vector<std::size_t>{500, 500, 166, 0}));
    const PhotonStore& store = storeOf(registry);
    EXPECT_EQ(store.pathCount(), 5'333u);
    EXPECT_EQ(rangeOf(store, lightOf(store, late)),
              (std::pair<std::uint32_t, std::uint32_t>{1'000, 2'666}));
    EXPECT_EQ(store.lights[lightOf(store, room.light)].photonCount, 1'000u);
    expectEachLightsPowerShot(store);
}

TEST(PhotonUpdate, TheLitPhotonsStayNearPhotonCountWhenLightsChangeOrGo) {
    // Three 10 W/sr lights, 1,000 photons each. The room light a hundred times brighter: the
    // lamps hold 34x their shares of 3,000 and are dealt 29 each; the room light, 2.9x under
    // its 2,941, is dealt anew with them. Then it is destroyed: the lamps, 29 of a share of
    // photonCount each, are dealt 1,500 each.
    PhotonSettings settings = settingsWith(3'000);
    settings.reshootBudget = 100'000;
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const Entity a = test::addPointLight(registry, {-1.f, 0.5f, 1.f}, 10.f);
    const Entity b = test::addPointLight(registry, {1.f, 0.5f, 1.f}, 10.f);
    buildRayScene(registry);
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);

    registry.patch<PointLight>(room.light).intensity = 1'000.f;
    std::uint64_t frame = 0;
    reshotPerFrame(registry, system, frame, 2);
    {
        const PhotonStore& store = storeOf(registry);
        EXPECT_EQ(store.lights[lightOf(store, room.light)].photonCount, 2'941u);
        EXPECT_EQ(store.lights[lightOf(store, a)].photonCount, 29u);
        EXPECT_EQ(store.lights[lightOf(store, b)].photonCount, 29u);
        expectEachLightsPowerShot(store);
    }
    registry.destroy(room.light);
    reshotPerFrame(registry, system, frame, 2);
    const PhotonStore& store = storeOf(registry);
    EXPECT_EQ(store.lights[lightOf(store, a)].photonCount, 1'500u);
    EXPECT_EQ(store.lights[lightOf(store, b)].photonCount, 1'500u);
    EXPECT_LE(store.pathCount(), 3u * 3'000u);
    expectEachLightsPowerShot(store);
}

// ---- random light changes: every invariant of the photon ranges -------------------------

/// Whether segment s meets the box: a slab test in double precision (infinite lengths too).
bool segmentMeetsBox(const PhotonSegments& segments, std::size_t s, const Aabb& box) {
    const glm::dvec3 o(segments.origin[s]), d(segments.direction[s]);
    double near = 0.0, far = double(segments.length[s]);
    for (int axis = 0; axis < 3; ++axis) {
        if (d[axis] == 0.0) {
            if (o[axis] < box.min[axis] || o[axis] > box.max[axis]) return false;
            continue;
        }
        const double t0 = (box.min[axis] - o[axis]) / d[axis];
        const double t1 = (box.max[axis] - o[axis]) / d[axis];
        near = std::max(near, std::min(t0, t1));
        far = std::min(far, std::max(t0, t1));
    }
    return near <= far;
}

/// After a frame: every light's range lies in the store, the ranges are disjoint and cover it,
/// each path names the light whose range holds it; once a light's sweep is done, a dark,
/// absent or ghost light holds no segments and a shining one has every photon shot, their
/// first segments carrying its power (unless its share is under a photon: it may have none); paths'
/// segments never overlap; the grid indexes the store and (with `queryGrid`) finds every path
/// through random boxes.
void expectConsistentLights(const PhotonUpdateSystem& system, const PhotonStore& store,
                            const PhotonPathGrid& grid, std::uint32_t photonCount,
                            std::uint64_t frame, bool queryGrid, std::mt19937& rng) {
    const std::vector<PhotonUpdateSystem::LightPhotons> lights = system.lightPhotons();
    ASSERT_EQ(lights.size(), store.lights.size()) << "frame " << frame;
    ASSERT_LE(store.pathCount(), std::size_t(kMaxPhotonGrowth) * photonCount);
    std::vector<std::int64_t> owner(store.pathCount(), -1);
    for (std::size_t l = 0; l < lights.size(); ++l) {
        const PhotonUpdateSystem::LightPhotons& light = lights[l];
        ASSERT_EQ(light.count, store.lights[l].photonCount) << "frame " << frame << " light " << l;
        ASSERT_LE(light.remaining, light.count) << "frame " << frame << " light " << l;
        ASSERT_TRUE(!light.ghost || light.absent);
        ASSERT_LE(std::size_t(light.first) + light.count, store.pathCount());
        for (std::uint32_t p = light.first; p < light.first + light.count; ++p) {
            ASSERT_EQ(owner[p], -1) << "frame " << frame << ": photon " << p << " of two lights";
            owner[p] = std::int64_t(l);
        }
    }
    std::vector<glm::dvec3> shot(lights.size(), glm::dvec3(0.0));
    std::vector<std::size_t> live(lights.size(), 0);
    for (std::uint32_t p = 0; p < store.pathCount(); ++p) {
        ASSERT_EQ(std::int64_t(store.paths[p].light), owner[p]) << "frame " << frame << ": " << p;
        if (store.paths[p].count == 0) continue;
        shot[store.paths[p].light] += glm::dvec3(store.segments.power[store.paths[p].first]);
        ++live[store.paths[p].light];
    }
    // A shining light left with no photons must be worth under a photon at the rate lights
    // are given them (the lit lights', at least photonCount over all that shine).
    const auto watts = [](const glm::vec3& p) { return double(p.x) + p.y + p.z; };
    double litPower = 0.0, litPhotons = 0.0, shining = 0.0;
    for (std::size_t l = 0; l < lights.size(); ++l) {
        if (lights[l].absent || !carriesPower(store.lights[l].power)) continue;
        shining += watts(store.lights[l].power);
        if (lights[l].count == 0) continue;
        litPower += watts(store.lights[l].power);
        litPhotons += lights[l].count;
    }
    const double rate = std::max(litPhotons > 0.0 ? litPhotons / litPower : 0.0,
                                 shining > 0.0 ? photonCount / shining : 0.0);
    for (std::size_t l = 0; l < lights.size(); ++l) {
        if (lights[l].remaining > 0) continue;
        const glm::vec3& power = store.lights[l].power;
        if (lights[l].absent || !carriesPower(power)) {
            ASSERT_EQ(live[l], 0u) << "frame " << frame << ": dark light " << l << " holds paths";
            continue;
        }
        ASSERT_EQ(live[l], lights[l].count) << "frame " << frame << " light " << l;
        if (lights[l].count == 0) { // a share under half a photon when it was dealt: none
            ASSERT_LT(rate * watts(power), 1.0)
                << "frame " << frame << ": light " << l << " shines with no photons";
            continue;
        }
        for (int c = 0; c < 3; ++c)
            // Each photon carries fl(P / n) (2^-24 P / n off at most); n additions in double.
            ASSERT_NEAR(shot[l][c], power[c], (0x1p-24 + double(live[l]) * 0x1p-53) * power[c])
                << "frame " << frame << " light " << l << ", channel " << c;
    }
    std::vector<std::pair<std::size_t, std::size_t>> ranges;
    for (std::uint32_t p = 0; p < store.pathCount(); ++p) {
        const PhotonPath& path = store.paths[p];
        ASSERT_LE(std::size_t(path.first) + path.count, store.segments.size());
        if (path.count > 0) ranges.emplace_back(path.first, path.first + path.count);
    }
    std::sort(ranges.begin(), ranges.end());
    for (std::size_t i = 1; i < ranges.size(); ++i)
        ASSERT_LE(ranges[i - 1].second, ranges[i].first) << "frame " << frame;
    ASSERT_TRUE(grid.indexes(store)) << "frame " << frame;
    if (!queryGrid) return;
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::vector<std::uint32_t> found;
    for (int q = 0; q < 12; ++q) {
        // (One draw per statement: the order of a call's arguments is unspecified.)
        const float x = 4.f * unit(rng) - 2.f;
        const float y = 3.f * unit(rng) - 1.5f;
        const float z = 4.f * unit(rng) - 2.f;
        const Aabb box{glm::vec3(x, y, z) - 0.3f, glm::vec3(x, y, z) + 0.3f};
        grid.pathsOverlapping(box, found);
        for (std::uint32_t p = 0; p < store.pathCount(); ++p)
            for (std::size_t k = store.paths[p].first;
                 k < std::size_t(store.paths[p].first) + store.paths[p].count; ++k) {
                if (!segmentMeetsBox(store.segments, k, box)) continue;
                ASSERT_TRUE(std::binary_search(found.begin(), found.end(), p))
                    << "frame " << frame << ": the grid misses photon " << p;
                break;
            }
    }
}

/// A room with a glowing crate (an emissive mobile) and a glowing panel drawn through a
/// stand-in bulb, run for `frames` frames of one to three random changes each: lamps (point
/// and spot) created, destroyed, their light component taken off and put back, intensities
/// scaled a hundredfold either way or switched off, the crate taken out and put back,
/// emissions scaled, albedos edited, lamps and the crate moved, the cube sliding every frame.
/// Each frame: no watt lost in the delta, expectConsistentLights, and every 5 frames DETP
/// (hybrid or not) equal to a full estimate. `trace`, when given, gets a hash of the paths'
/// owners and lengths per frame.
void runRandomLightChanges(std::uint32_t photons, std::uint32_t budget, std::uint32_t seed,
                           int frames, bool hybrid, std::vector<std::uint64_t>* trace = nullptr) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    registry.get<Material>(room.crate).emission = glm::vec3(4.f);
    Material glow = test::grey(0.f);
    glow.emission = glm::vec3(3.f);
    const Entity panel = test::addMesh(
        registry, test::quadMesh({-0.3f, 1.4f, -0.3f}, {0.6f, 0.f, 0.f}, {0.f, 0.f, 0.6f}),
        glm::mat4(1.f), glow, false, "panel");
    registry.emplace<LightStandIn>(test::addPointLight(registry, {0.f, 1.38f, 0.f}, 2.f));
    MeshProcessingOptions refine;
    refine.maxEdgeLength = 0.3f;
    for (const Entity m : {room.walls, room.pillar, room.cube, room.crate})
        registry.get<Mesh>(m) = processMesh(registry.get<Mesh>(m), refine);
    buildRayScene(registry);
    PhotonSettings photonSettings = settingsWith(photons);
    photonSettings.reshootBudget = budget;
    PhotonUpdateSystem system(photonSettings);
    system.update(registry, FrameContext{});
    DetpSettings settings;
    settings.discRadius = 0.15f;
    settings.hybrid = hybrid;
    DetpIrradianceSystem detp(settings);
    detp.build(registry);
    detp.update(registry, FrameContext{});
    registry.clearChanges();
    const std::vector<Entity> meshes = registry.view<const Mesh>().entities();
    SumRounding rounding;
    rounding.add(storeOf(registry).segments);
    const Rings rings = meshRings(registry, meshes);

    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    const auto any = [&](std::size_t n) { return std::size_t(unit(rng) * float(n)) % n; };
    std::vector<Entity> lamps;
    std::vector<std::pair<Entity, PointLight>> stripped; // light component taken off
    bool crateIn = true;
    glm::vec3 cube = kCubeRest;
    for (std::uint64_t frame = 1; frame <= std::uint64_t(frames); ++frame) {
        for (int change = 1 + int(unit(rng) * 3.f); change > 0; --change) {
            const float pick = unit(rng);
            if (pick < 0.12f) {
                const float x = 2.f * unit(rng) - 1.f;
                const float y = unit(rng) - 0.5f;
                const float z = 2.f * unit(rng) - 1.f;
                const float intensity = std::pow(10.f, 2.f * unit(rng) - 0.5f);
                if (unit(rng) < 0.7f) {
                    lamps.push_back(test::addPointLight(registry, {x, y, z}, intensity));
                } else {
                    const Entity e = registry.create();
                    registry.emplace<WorldTransform>(e, WorldTransform{translation({x, y, z})});
                    registry.emplace<SpotLight>(e,
                                                SpotLight{glm::vec3(1.f), intensity, 0.2f, 0.9f});
                    lamps.push_back(e);
                }
            } else if (pick < 0.2f && !lamps.empty()) {
                const std::size_t i = any(lamps.size());
                registry.destroy(lamps[i]);
                lamps.erase(lamps.begin() + std::ptrdiff_t(i));
            } else if (pick < 0.27f && !lamps.empty()) {
                const std::size_t i = any(lamps.size());
                if (!registry.has<PointLight>(lamps[i])) continue;
                stripped.emplace_back(lamps[i], registry.get<PointLight>(lamps[i]));
                registry.remove<PointLight>(lamps[i]);
                lamps.erase(lamps.begin() + std::ptrdiff_t(i));
            } else if (pick < 0.33f && !stripped.empty()) {
                const std::size_t i = any(stripped.size());
                registry.emplace<PointLight>(stripped[i].first, stripped[i].second);
                lamps.push_back(stripped[i].first);
                stripped.erase(stripped.begin() + std::ptrdiff_t(i));
            } else if (pick < 0.48f) {
                const float factor =
                    unit(rng) < 0.15f ? 0.f : std::pow(10.f, 4.f * unit(rng) - 2.f);
                const std::size_t i = any(lamps.size() + 1);
                const Entity e = i < lamps.size() ? lamps[i] : room.light;
                float& intensity = registry.has<PointLight>(e)
                                       ? registry.patch<PointLight>(e).intensity
                                       : registry.patch<SpotLight>(e).intensity;
                intensity = std::min((intensity == 0.f ? 1.f : intensity) * factor, 1000.f);
                if (intensity != 0.f) intensity = std::max(intensity, 1e-3f);
            } else if (pick < 0.54f) {
                crateIn = !crateIn;
                registry.patch<MobileMesh>(room.crate).active = crateIn;
            } else if (pick < 0.6f) {
                const Entity e = unit(rng) < 0.5f ? room.crate : panel;
                const float factor =
                    unit(rng) < 0.1f ? 0.f : std::pow(10.f, 3.f * unit(rng) - 1.5f);
                glm::vec3& emission = registry.patch<Material>(e).emission;
                emission =
                    glm::min((emission == glm::vec3(0.f) ? glm::vec3(1.f) : emission) * factor,
                             glm::vec3(100.f));
            } else if (pick < 0.64f) {
                const Entity e = unit(rng) < 0.5f ? room.pillar : room.cube;
                registry.patch<Material>(e).baseColor =
                    glm::vec3(0.2f + 0.7f * unit(rng), 0.5f, 0.3f);
            } else if (pick < 0.67f && !lamps.empty()) {
                const Entity e = lamps[any(lamps.size())];
                const float x = 2.f * unit(rng) - 1.f;
                const float z = 2.f * unit(rng) - 1.f;
                registry.patch<WorldTransform>(e).matrix = translation({x, 0.2f, z});
            } else if (pick < 0.7f) {
                const float x = -1.5f + 3.f * unit(rng);
                const float z = -1.5f + 1.9f * unit(rng);
                registry.patch<WorldTransform>(room.crate).matrix =
                    translation({x, kCrateRest.y, z});
            }
        }
        cube.x = std::clamp(cube.x + 0.05f * (unit(rng) - 0.5f), -1.5f, 1.5f);
        registry.patch<WorldTransform>(room.cube).matrix = translation(cube);
        registry.ctx().get<RayScene>().syncMoved(registry);

        const glm::dvec3 before = impactPower(storeOf(registry));
        system.update(registry, FrameContext{frame, 0.0, 0.f, 0});
        const PhotonDelta& delta = deltaOf(registry);
        if (delta.full) {
            rounding = SumRounding{};
            rounding.add(storeOf(registry).segments);
        } else {
            const glm::dvec3 expected =
                before - impactPower(delta.oldSegments, 0, delta.oldSegments.size()) +
                impactPower(delta.newSegments, 0, delta.newSegments.size());
            SumRounding bookkeeping;
            bookkeeping.add(storeOf(registry).segments);
            bookkeeping.add(delta.oldSegments);
            bookkeeping.add(delta.newSegments);
            const glm::dvec3 after = impactPower(storeOf(registry));
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(after[c], expected[c], 2.0 * bookkeeping.sums())
                    << "frame " << frame << ", channel " << c;
            rounding.add(delta.oldSegments);
            rounding.add(delta.newSegments, 2.0 * double(delta.relabels.size()));
        }
        detp.update(registry, FrameContext{frame, 0.0, 0.f, 0});
        registry.clearChanges();
        if (detp.lastFrame().full) {
            rounding = SumRounding{};
            rounding.add(storeOf(registry).segments);
        }
        expectConsistentLights(system, storeOf(registry), registry.ctx().get<PhotonPathGrid>(),
                               photons, frame, frame % 10 == 0, rng);
        if (::testing::Test::HasFatalFailure()) return;
        if (frame % 5 == 0) {
            expectIrradianceOfAFullEstimate(registry, settings, meshes,
                                            roundingBound(settings, rounding, rings), int(frame));
            if (::testing::Test::HasFatalFailure()) return;
        }
        if (trace) {
            const PhotonStore& store = storeOf(registry);
            std::uint64_t h = store.pathCount();
            for (std::uint32_t p = 0; p < store.pathCount(); ++p)
                h = h * 31 + store.paths[p].light * 7 + store.paths[p].count;
            trace->push_back(h);
        }
    }
}

TEST(PhotonUpdate, RandomLightChangesKeepEveryPhotonRangeAndEstimateConsistent) {
    const ScopedLogLevel quiet(
        LogLevel::Quiet); // lights that cannot emit are named on every change
    for (std::uint32_t seed = 1; seed <= 2; ++seed)
        for (const std::uint32_t photons : {300u, 1'200u, 4'000u})
            for (const bool hybrid : {true, false}) {
                SCOPED_TRACE(::testing::Message() << "seed " << seed << ", " << photons
                                                  << " photons" << (hybrid ? ", hybrid" : ""));
                // Sweeps of about nine frames, so that changes overlap them.
                runRandomLightChanges(photons, photons / 9 + 1, seed * 7919 + photons, 250, hybrid);
                if (HasFatalFailure()) break;
            }
}

TEST(PhotonUpdate, RandomLightChangesGiveTheSameStoreOnOneThreadAsOnMany) {
    std::vector<std::uint64_t> many, one;
    {
        const ScopedLogLevel quiet(LogLevel::Quiet);
        runRandomLightChanges(1'200, 150, 77, 150, true, &many);
        tbb::task_arena single(1);
        single.execute([&] { runRandomLightChanges(1'200, 150, 77, 150, true, &one); });
    }
    EXPECT_EQ(many, one);
    EXPECT_EQ(many.size(), 150u);
}

TEST(PhotonUpdate, ALightThatLightsUpWhileTheOthersAreDarkGetsPhotons) {
    // The only light with photons switched off, and one shot without photons switched on: it
    // gets photonCount photons of its own, appended, while the dark one's wait.
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const Entity lamp = test::addPointLight(registry, {-1.f, 0.5f, 1.f}, 0.f);
    buildRayScene(registry);
    PhotonUpdateSystem system(settingsWith(4'000));
    firstUpdate(registry, system);
    ASSERT_EQ(storeOf(registry).lights[1].photonCount, 0u);
    registry.patch<PointLight>(lamp).intensity = registry.get<PointLight>(room.light).intensity;
    registry.patch<PointLight>(room.light).intensity = 0.f;
    std::uint64_t frame = 0;
    reshotPerFrame(registry, system, frame, 1);
    const PhotonStore& store = storeOf(registry);
    EXPECT_EQ(store.lights[0].photonCount, 4'000u);
    EXPECT_EQ(store.lights[1].photonCount, 4'000u);
    ASSERT_EQ(store.pathCount(), 8'000u);
    for (std::uint32_t p = 0; p < 8'000; ++p)
        ASSERT_EQ(store.paths[p].count > 0, p >= 4'000) << "photon " << p;
}

TEST(PhotonUpdate, ALightThatDriftsFarFromItsPhotonShareIsSharedAnew) {
    // A lamp shot while nearly off gets no photons; brightened, it gets its share appended.
    // A drift under 4x from the shares is kept; the room's light dimmed a hundredfold holds
    // far more photons than its share: they are dealt anew, progressively (no full shot).
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    const Entity lamp = test::addPointLight(registry, {-1.f, 0.5f, 1.f}, 1e-6f);
    buildRayScene(registry);
    PhotonUpdateSystem system(settingsWith(4'000));
    firstUpdate(registry, system);
    ASSERT_EQ(storeOf(registry).lights.size(), 2u);
    EXPECT_EQ(storeOf(registry).lights[1].photonCount, 0u);

    const float roomIntensity = registry.get<PointLight>(room.light).intensity;
    registry.patch<PointLight>(lamp).intensity = roomIntensity;
    std::uint64_t frame = 0;
    reshotPerFrame(registry, system, frame, 1);
    EXPECT_EQ(storeOf(registry).lights[1].photonCount, 4'000u);

    registry.patch<PointLight>(lamp).intensity = 2.f * roomIntensity; // 4/3 of its share
    reshotPerFrame(registry, system, frame, 1);
    EXPECT_EQ(storeOf(registry).lights[1].photonCount, 4'000u);

    // Dealt anew within the budget: the room light's 4,000 photons go dark while it is given
    // its share of the lit lights' 8,000 (0.1 of 20.1 W/sr: 40) at the store's end; the lamp,
    // within 4x of its share, keeps its own.
    registry.patch<PointLight>(room.light).intensity = roomIntensity / 100.f;
    reshotPerFrame(registry, system, frame, 1);
    EXPECT_EQ(system.lastFrame().redealtLights, 1u);
    {
        const PhotonStore& store = storeOf(registry);
        EXPECT_EQ(store.pathCount(), 8'040u);
        EXPECT_EQ(store.lights[0].photonCount, 40u);
        EXPECT_EQ(store.lights[1].photonCount, 4'000u);
        for (std::uint32_t p = 0; p < 8'040; ++p) // the budget covered every photon
            ASSERT_EQ(store.paths[p].count > 0, p >= 4'000) << "photon " << p;
        expectEachLightsPowerShot(store);
    }
    // Dealt anew again (0.1 W/sr against the lamp's 0.2: a third of 4,040): the room light's
    // old 4,000 photons, dark now, hold the new ones.
    registry.patch<PointLight>(lamp).intensity = roomIntensity / 50.f;
    reshotPerFrame(registry, system, frame, 1);
    EXPECT_EQ(system.lastFrame().redealtLights, 1u);
    EXPECT_EQ(system.lastFrame().addedPaths, 0u);
    const PhotonStore& store = storeOf(registry);
    EXPECT_EQ(store.pathCount(), 8'040u);
    EXPECT_EQ(store.lights[0].photonCount, 1'347u);
    EXPECT_EQ(store.lights[0].photonCount + store.lights[1].photonCount, 5'347u);
    for (std::uint32_t p = 0; p < 8'040; ++p)
        ASSERT_EQ(store.paths[p].count > 0, p < 1'347 || (p >= 4'000 && p < 8'000))
            << "photon " << p;
    expectEachLightsPowerShot(store);
}

TEST(PhotonUpdate, AStandInAddedOrMovedAwayChangesWhatHybridModeCounts) {
    // An emissive panel is drawn by the shader only while a stand-in bulb sits at it: adding
    // one, or moving it away, changes whether its first segments count, so photons start over.
    Registry registry;
    test::addMesh(registry, test::boxMesh(glm::vec3(2.f), true), glm::mat4(1.f), test::grey(0.5f),
                  false, "room");
    Material glow = test::grey(0.f);
    glow.emission = glm::vec3(5.f);
    test::addMesh(registry,
                  test::quadMesh({-0.3f, 1.9f, -0.3f}, {0.6f, 0.f, 0.f}, {0.f, 0.f, 0.6f}),
                  glm::mat4(1.f), glow, false, "panel");
    buildRayScene(registry);
    PhotonUpdateSystem system(settingsWith(2'000));
    firstUpdate(registry, system);
    ASSERT_EQ(storeOf(registry).lights.size(), 1u);
    EXPECT_FALSE(storeOf(registry).lights[0].directDrawn);

    const Entity bulb = test::addPointLight(registry, {0.f, 1.85f, 0.f}, 3.f);
    registry.emplace<LightStandIn>(bulb);
    system.update(registry, FrameContext{1, 0.0, 0.f, 0});
    registry.clearChanges();
    EXPECT_TRUE(deltaOf(registry).full);
    ASSERT_EQ(storeOf(registry).lights.size(), 1u); // the bulb itself shoots nothing
    EXPECT_TRUE(storeOf(registry).lights[0].directDrawn);

    system.update(registry, FrameContext{2, 0.0, 0.f, 0}); // nothing changed
    registry.clearChanges();
    EXPECT_TRUE(deltaOf(registry).empty());

    registry.patch<WorldTransform>(bulb).matrix = translation({0.f, -1.5f, 0.f});
    system.update(registry, FrameContext{3, 0.0, 0.f, 0});
    registry.clearChanges();
    EXPECT_TRUE(deltaOf(registry).full);
    EXPECT_FALSE(storeOf(registry).lights[0].directDrawn);
}

// ---- energy
// --------------------------------------------------------------------------------------

/// Closed box of uniform albedo rho around a point light: every photon eventually lands, and
/// the stored incident power per emitted watt is sum_{k <= K} rho^k (1 / (1 - rho) but for the
/// bounce cap K). Each photon's total is independent of the others (its roulette draws are
/// its own), so the mean over N photons lies within a few standard errors of that.
void expectClosedBoxEnergy(const glm::vec3& rho) {
    Registry registry;
    Material material;
    material.baseColor = rho;
    test::addMesh(registry, test::boxMesh(glm::vec3(1.f), true), glm::mat4(1.f), material, false,
                  "closed box");
    test::addPointLight(registry, {0.1f, 0.2f, -0.3f}, 2.f);
    buildRayScene(registry);
    PhotonSettings settings = settingsWith(40'000);
    settings.maxBounces = 12;
    PhotonUpdateSystem system(settings);
    firstUpdate(registry, system);
    const PhotonStore& store = storeOf(registry);
    const glm::vec3 emitted = store.emittedPower;
    EXPECT_NEAR(emitted.x, 8.f * glm::pi<float>(), 1e-4f);

    const double n = double(store.pathCount());
    glm::dvec3 sum(0.0), sumSquares(0.0);
    std::size_t escaped = 0;
    for (const PhotonPath& path : store.paths) {
        glm::dvec3 landed(0.0);
        for (std::size_t s = path.first; s < path.first + path.count; ++s) {
            if (!store.segments.hitEntity[s]) ++escaped;
            landed += glm::dvec3(store.segments.power[s]) * n / glm::dvec3(emitted);
        }
        sum += landed;
        sumSquares += landed * landed;
    }
    EXPECT_EQ(escaped, 0u);
    for (int c = 0; c < 3; ++c) {
        const double mean = sum[c] / n;
        const double sd = std::sqrt(std::max(0.0, sumSquares[c] / n - mean * mean));
        double expected = 0.0;
        for (std::uint32_t k = 0; k <= settings.maxBounces; ++k)
            expected += std::pow(double(rho[c]), double(k));
        // 4.5 standard errors: a false alarm once in 150,000 runs.
        EXPECT_NEAR(mean, expected, 4.5 * sd / std::sqrt(n)) << "channel " << c;
        EXPECT_GT(sd, 0.0);
    }
}

TEST(PhotonUpdate, ClosedGreyBoxStoresOneOverOneMinusRhoTimesTheEmittedPower) {
    expectClosedBoxEnergy(glm::vec3(0.5f));
}

TEST(PhotonUpdate, ClosedColouredBoxKeepsEachChannelUnbiased) {
    expectClosedBoxEnergy({0.3f, 0.5f, 0.7f});
}

// ---- the box directional lights cover -------------------------------------------------------

/// Who follows the hoist's scripted path: nobody (game code moves the box), the box itself, or
/// a node above it (as glTF puts a mesh's primitives below the animated node).
enum class Hoist { ByGameCode, Itself, ByParent };

/// A 2 x 2 m floor lit by a sun straight down and a 0.4 m mobile box resting on it at (1, 1),
/// with a path that hoists it 3 m up: far above the rest of the scene.
struct SunLitHoist {
    Registry registry;
    Entity box;
    static constexpr float kHalf = 0.2f;
    const glm::vec3 low{1.f, kHalf, 1.f}, high{1.f, 3.f, 1.f};

    explicit SunLitHoist(Hoist hoist) {
        test::addMesh(registry,
                      test::gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 2.f}, {2.f, 0.f, 0.f}, 4),
                      glm::mat4(1.f), test::grey(0.5f), false, "floor");
        box = test::addMesh(registry, test::boxMesh(glm::vec3(kHalf)), translation(low),
                            test::grey(0.5f), true, "hoisted box");
        const PathFollower path{{{0.f, low}, {4.f, high}}};
        if (hoist == Hoist::ByParent) {
            const Entity hook = registry.create();
            registry.emplace<Transform>(hook, Transform{low});
            registry.emplace<WorldTransform>(hook, translation(low));
            registry.emplace<PathFollower>(hook, path);
            registry.emplace<Transform>(
                box, Transform{glm::vec3(0.f), {1.f, 0.f, 0.f, 0.f}, glm::vec3(1.f), hook});
        } else {
            registry.emplace<Transform>(box, Transform{low});
            if (hoist == Hoist::Itself) registry.emplace<PathFollower>(box, path);
        }
        const Entity sun = registry.create(); // its -Z axis points down
        registry.emplace<WorldTransform>(
            sun, glm::rotate(glm::mat4(1.f), -glm::half_pi<float>(), glm::vec3(1.f, 0.f, 0.f)));
        registry.emplace<DirectionalLight>(sun, DirectionalLight{glm::vec3(1.f), 1.f});
        buildRayScene(registry);
    }

    /// Photons of the first bounce that land on the box (on its top: the sun is parallel to
    /// its sides).
    std::size_t directHits() const {
        const PhotonStore& store = storeOf(registry);
        std::size_t hits = 0;
        for (const PhotonPath& path : store.paths)
            hits += path.count > 0 && store.segments.hitEntity[path.first] == box ? 1 : 0;
        return hits;
    }
};

/// With the sun's photons spread evenly over `footprint` m^2, the box's 0.16 m^2 top takes each
/// with probability p: its hits are within 4 binomial standard errors of N p (the Halton
/// emission spreads them more evenly than independent draws, never less).
void expectTopLit(std::size_t hits, std::uint32_t photons, double footprint) {
    const double p = 4.0 * SunLitHoist::kHalf * SunLitHoist::kHalf / footprint;
    const double mean = photons * p, sigma = std::sqrt(photons * p * (1.0 - p));
    EXPECT_NEAR(double(hits), mean, 4.0 * sigma);
}

TEST(PhotonUpdate, DirectionalLightsCoverTheScriptedPathsOfMobiles) {
    for (const Hoist hoist : {Hoist::Itself, Hoist::ByParent}) {
        SCOPED_TRACE(hoist == Hoist::Itself ? "the box follows the path" : "its parent does");
        SunLitHoist scene(hoist);
        PhotonUpdateSystem system(settingsWith(20'000));
        firstUpdate(scene.registry, system);
        // The rectangle the photons start on lies above the path's top, not just above the box.
        const PhotonStore& store = storeOf(scene.registry);
        float lowest = std::numeric_limits<float>::max();
        for (const PhotonPath& path : store.paths)
            lowest = std::min(lowest, store.segments.origin[path.first].y);
        EXPECT_GT(lowest, scene.high.y + SunLitHoist::kHalf);
        // The path stays over the floor, so the sun still covers 2 x 2 m.
        expectTopLit(scene.directHits(), 20'000, 4.0);

        ::testing::internal::CaptureStderr();
        test::moveAndUpdate(scene.registry, system, scene.box, translation(scene.high), 1);
        EXPECT_EQ(::testing::internal::GetCapturedStderr(), ""); // inside the box: no warning
        EXPECT_GT(system.lastFrame().retracedPaths, 0u);
        expectTopLit(scene.directHits(), 20'000, 4.0);
    }
}

TEST(PhotonUpdate, AMobileThatLeavesTheDirectionalLightsBoxIsNamedOnceAndCanBeCovered) {
    {
        SunLitHoist scene(Hoist::ByGameCode); // nothing foresees the hoist
        PhotonUpdateSystem system(settingsWith(20'000));
        firstUpdate(scene.registry, system);
        ::testing::internal::CaptureStderr();
        test::moveAndUpdate(scene.registry, system, scene.box, translation(scene.high), 1);
        test::moveAndUpdate(scene.registry, system, scene.box,
                            translation(scene.high + glm::vec3(0.f, 0.1f, 0.f)), 2);
        const std::string log = ::testing::internal::GetCapturedStderr();
        EXPECT_THAT(log, HasSubstr("'hoisted box' left the box the directional lights cover"));
        EXPECT_THAT(log, HasSubstr("directionalBounds"));
        EXPECT_EQ(log.find("left the box"), log.rfind("left the box")) << "named twice: " << log;
        // Up there it is above where the photons start: dark, and no shadow below.
        EXPECT_EQ(scene.directHits(), 0u);
    }
    {
        SunLitHoist scene(Hoist::ByGameCode);
        PhotonSettings settings = settingsWith(20'000);
        settings.directionalBounds = {{0.f, 0.f, 0.f}, {2.f, 4.f, 2.f}};
        PhotonUpdateSystem system(settings);
        firstUpdate(scene.registry, system);
        ::testing::internal::CaptureStderr();
        test::moveAndUpdate(scene.registry, system, scene.box, translation(scene.high), 1);
        EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
        expectTopLit(scene.directHits(), 20'000, 4.0);
    }
}

TEST(PhotonUpdate, AnAlbedoEditRetracesThePathsThatHitTheSurfaceFromThereAndMatchesAFreshShot) {
    // The paths that hit the edited surface are re-traced from that hit (the same ray lands
    // where it did, then reflects with the new albedo); no other path changes, and the store is
    // what a fresh shot with the new albedo gives, bit for bit. A static surface, then a mobile.
    const glm::vec3 edit(0.3f, 0.5f, 0.2f);
    for (const bool mobile : {false, true}) {
        SCOPED_TRACE(mobile ? "mobile" : "static");
        Registry registry;
        const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
        buildRayScene(registry);
        PhotonUpdateSystem system(settingsWith(10'000));
        firstUpdate(registry, system);
        const Entity target = mobile ? room.cube : room.pillar;
        const PhotonStore before = storeOf(registry);
        std::vector<int> expected(before.pathCount(), -1);
        std::size_t hitting = 0;
        for (std::uint32_t p = 0; p < before.pathCount(); ++p)
            for (std::uint32_t k = 0; k < before.paths[p].count; ++k)
                if (before.segments.hitEntity[before.segmentIndex(p, k)] == target) {
                    expected[p] = int(k);
                    ++hitting;
                    break;
                }
        ASSERT_GT(hitting, 100u);
        ASSERT_LT(hitting, before.pathCount() / 2);

        registry.patch<Material>(target).baseColor = edit;
        system.update(registry, FrameContext{1});
        EXPECT_FALSE(deltaOf(registry).full);
        EXPECT_EQ(system.lastFrame().editedSurfaces, 1u);
        EXPECT_EQ(system.lastFrame().retracedPaths, hitting);
        expectExactDelta(before, storeOf(registry), deltaOf(registry), expected);
        registry.clearChanges();

        Registry fresh;
        const test::Room same = buildRoom(fresh, kCubeRest, kCrateRest);
        fresh.get<Material>(mobile ? same.cube : same.pillar).baseColor = edit;
        buildRayScene(fresh);
        PhotonUpdateSystem reference(settingsWith(10'000));
        firstUpdate(fresh, reference);
        EXPECT_TRUE(sameStore(storeOf(registry), storeOf(fresh)));

        // Patching the same value again, or another component's field, re-traces nothing.
        registry.patch<Material>(target).baseColor = edit;
        registry.patch<Material>(room.walls).emission = glm::vec3(0.f);
        system.update(registry, FrameContext{2});
        EXPECT_TRUE(deltaOf(registry).empty());
        EXPECT_EQ(system.lastFrame().editedSurfaces, 0u);
        registry.clearChanges();

        // The walls catch nearly every path. So many paths changed for good would keep every
        // query testing their boxes while the grid re-indexed a chunk a frame: it is rebuilt
        // in the same frame, and still finds what a full index does.
        registry.patch<Material>(room.walls).baseColor = glm::vec3(0.5f);
        system.update(registry, FrameContext{3});
        EXPECT_GT(system.lastFrame().repaintedPaths, storeOf(registry).pathCount() / 2);
        EXPECT_EQ(system.lastFrame().reindexedPaths, storeOf(registry).pathCount());
        const PhotonPathGrid& grid = registry.ctx().get<PhotonPathGrid>();
        EXPECT_EQ(grid.changedPathCount(), 0u);
        EXPECT_TRUE(grid.indexes(storeOf(registry)));
        registry.clearChanges();
        fresh.patch<Material>(same.walls).baseColor = glm::vec3(0.5f);
        reference.update(fresh, FrameContext{1});
        EXPECT_TRUE(sameStore(storeOf(registry), storeOf(fresh)));
    }
}

TEST(PhotonUpdate, AnAlbedoOutsideZeroToOneIsClampedAndNamed) {
    Registry registry;
    const test::Room room = buildRoom(registry, kCubeRest, kCrateRest);
    registry.get<Material>(room.cube).baseColor = {1.5f, 0.5f, -0.2f};
    registry.get<Material>(room.crate).baseColor.y = std::numeric_limits<float>::quiet_NaN();
    buildRayScene(registry);
    PhotonUpdateSystem system(settingsWith(1'000));
    ::testing::internal::CaptureStderr();
    firstUpdate(registry, system);
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_THAT(log, HasSubstr("baseColor of 'cube' is (1.5, 0.5, -0.2), not an albedo in [0, 1]; "
                               "photons reflect (1, 0.5, 0)"));
    EXPECT_THAT(log, HasSubstr("baseColor of 'crate'"));
    EXPECT_EQ(log.find("'walls'"), std::string::npos) << log;
}

// ---- settings ------------------------------------------------------------------------------

TEST(PhotonUpdate, AbsurdSettingsAreRejectedNamingTheField) {
    const auto rejects = [](auto edit, const char* field) {
        PhotonSettings s;
        edit(s);
        try {
            PhotonUpdateSystem system(s);
            ADD_FAILURE() << field << " accepted";
        } catch (const Error& e) {
            EXPECT_THAT(e.what(), HasSubstr(field));
        }
    };
    rejects([](PhotonSettings& s) { s.photonCount = 0; }, "photonCount");
    rejects([](PhotonSettings& s) { s.photonCount = 100'000'000; }, "photonCount");
    rejects([](PhotonSettings& s) { s.maxBounces = 256; }, "maxBounces");
    rejects([](PhotonSettings& s) { s.reshootBudget = 0; }, "reshootBudget");
    rejects([](PhotonSettings& s) { s.gridResolution = 0; }, "gridResolution");
    rejects([](PhotonSettings& s) { s.gridResolution = 4096; }, "gridResolution");
    rejects([](PhotonSettings& s) { s.compactionFraction = 0.f; }, "compactionFraction");
    rejects([](PhotonSettings& s) { s.compactionFraction = NAN; }, "compactionFraction");
    rejects([](PhotonSettings& s) { s.nearPathMargin = -0.5f; }, "nearPathMargin");
    rejects([](PhotonSettings& s) { s.nearPathMargin = NAN; }, "nearPathMargin");
    rejects([](PhotonSettings& s) { s.nearPathMargin = 2.f; }, "nearPathMargin");
    rejects([](PhotonSettings& s) { s.gridRefreshBudget = 0; }, "gridRefreshBudget");
    rejects(
        [](PhotonSettings& s) {
            s.punctualLights = false;
            s.emissiveSurfaces = false;
        },
        "punctualLights");
    rejects(
        [](PhotonSettings& s) {
            s.directionalBounds = {glm::vec3(0.f), {1.f, NAN, 1.f}};
        },
        "directionalBounds");
    rejects(
        [](PhotonSettings& s) {
            s.directionalBounds = {glm::vec3(0.f), {1.f, -1.f, 1.f}};
        },
        "directionalBounds");
    rejects(
        [](PhotonSettings& s) {
            s.directionalBounds = {glm::vec3(-1e7f), glm::vec3(1e7f)};
        },
        "directionalBounds");
    rejects(
        [](PhotonSettings& s) {
            s.directionalBounds = {glm::vec3(1.f), {1.f, 1.f, 5.f}};
        },
        "directionalBounds");
    PhotonSettings flat;
    flat.directionalBounds = {glm::vec3(0.f), {10.f, 0.f, 10.f}}; // a plane is a range too
    EXPECT_NO_THROW(PhotonUpdateSystem{flat});
    EXPECT_NO_THROW(PhotonUpdateSystem{PhotonSettings{}});
}

} // namespace
} // namespace qgi
