// Point cache (seed 003): construction and query (shading, the cache file and the per-frame
// update are in test_point_cache_shading.cpp).
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/Distance.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/detp/DiscIndex.h"
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointCacheFile.h"
#include "systems/point_cache/PointCacheSettings.h"
#include "systems/point_cache/PointCacheSystem.h"
#include "systems/point_cache/PointSetBuilder.h"
#include "systems/point_cache/PointShading.h"
#include "systems/point_cache/ShadowCandidates.h"
#include "test_meshes.h"
#include "test_photon_scenes.h"

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/matrix.hpp>
#include <gtest/gtest.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <random>

namespace qgi {
namespace {

using test::addMesh;
using test::addPointLight;
using test::boxMesh;
using test::grey;
using test::translation;

/// A closed 4 x 2 x 4 m room (inward faces) with a 0.4 m pillar from floor to ceiling and a
/// point light under the ceiling: the digest's "box with a pillar on a floor".
struct PillarRoom {
    Registry registry;
    Entity pillar;
    PillarRoom() {
        addMesh(registry, boxMesh({2.f, 1.f, 2.f}, true), glm::mat4(1.f), grey(0.7f), false,
                "room");
        pillar = addMesh(registry, boxMesh({0.2f, 1.f, 0.2f}), glm::mat4(1.f), grey(0.7f), false,
                         "pillar");
        addPointLight(registry, {1.2f, 0.8f, 1.2f}, 20.f);
        test::buildRayScene(registry);
    }
};

PointCacheSettings roomSettings() {
    PointCacheSettings s;
    s.rMin = 0.03f;
    s.rMax = 0.12f;
    s.aoDistance = 0.3f;
    s.particleCount = 512;
    s.stopAfterRejections = 3000;
    return s;
}

PointCache buildSet(Registry& registry, const PointCacheSettings& settings, PointSetStats* stats) {
    PointCache cache;
    cache.settings = resolvePointCacheSettings(settings, staticBounds(registry));
    const PointSetStats st = buildPointSet(registry, registry.ctx().get<RayScene>(), cache.settings,
                                           staticBounds(registry), cache);
    if (stats) *stats = st;
    return cache;
}

// ---- settings and the radius map -----------------------------------------------------------

TEST(PointCacheSettings, AbsurdValuesAreRejected) {
    const auto rejects = [](auto change) {
        PointCacheSettings s;
        change(s);
        EXPECT_THROW(validate(s), Error);
        EXPECT_THROW(PointCacheSystem{s}, Error);
    };
    rejects([](PointCacheSettings& s) { s.particleCount = 0; });
    rejects([](PointCacheSettings& s) { s.rMin = -1.f; });
    rejects([](PointCacheSettings& s) { s.rMax = std::nanf(""); });
    rejects([](PointCacheSettings& s) { s.rMin = 2.f, s.rMax = 1.f; });
    rejects([](PointCacheSettings& s) { s.aoRays = 0; });
    rejects([](PointCacheSettings& s) { s.aoDistance = INFINITY; });
    rejects([](PointCacheSettings& s) { s.searchScale = 0.5f; });
    rejects([](PointCacheSettings& s) { s.falloffExponent = 4; });
    rejects([](PointCacheSettings& s) { s.minNormalCosine = 2.f; });
    rejects([](PointCacheSettings& s) { s.planeTolerance = 0.f; });
    rejects([](PointCacheSettings& s) { s.shadowSamples = 0; });
    rejects([](PointCacheSettings& s) { s.updateBudget = 0; });
    rejects([](PointCacheSettings& s) { s.maxDarts = 0; });
    rejects([](PointCacheSettings& s) { s.stopAfterRejections = 0; });
    EXPECT_NO_THROW(validate(PointCacheSettings{}));
    // Scene defaults need a scene.
    EXPECT_THROW(resolvePointCacheSettings(PointCacheSettings{}, Aabb{}), Error);
}

TEST(PointCacheSettings, DefaultsScaleWithTheScene) {
    Aabb box;
    box.extend(glm::vec3(0.f));
    box.extend(glm::vec3(8.f, 0.f, 6.f)); // diagonal 10 m
    const PointCacheSettings s = resolvePointCacheSettings(PointCacheSettings{}, box);
    EXPECT_FLOAT_EQ(s.rMax, 10.f / kRMaxPerDiagonal);
    EXPECT_FLOAT_EQ(s.rMin, s.rMax / kRMaxPerRMin);
    EXPECT_FLOAT_EQ(s.aoDistance, 2.f * s.rMax);
    EXPECT_FLOAT_EQ(s.detpRadius, 3.f * s.rMax);
    // A spacing finer than the bake's grid can index (it would overflow its cell keys).
    PointCacheSettings fine;
    fine.rMin = fine.rMax = 1e-6f;
    EXPECT_THROW(resolvePointCacheSettings(fine, box), Error);
    fine.rMin = fine.rMax = 2e-5f;
    EXPECT_NO_THROW(resolvePointCacheSettings(fine, box));
}

TEST(PointCacheSettings, RadiusMapIsBoundedAndMonotone) {
    const float rMin = 0.05f, rMax = 0.4f;
    EXPECT_EQ(spacingRadius(0.f, rMin, rMax), rMax);
    EXPECT_EQ(spacingRadius(1.f, rMin, rMax), rMin);
    float previous = rMax;
    for (int i = 0; i <= 1000; ++i) {
        const float r = spacingRadius(float(i) / 1000.f, rMin, rMax);
        EXPECT_GE(r, rMin);
        EXPECT_LE(r, rMax);
        EXPECT_LE(r, previous);
        previous = r;
    }
    EXPECT_EQ(spacingRadius(-3.f, rMin, rMax), rMax);
    EXPECT_EQ(spacingRadius(7.f, rMin, rMax), rMin);
    EXPECT_EQ(spacingRadius(std::nanf(""), rMin, rMax), rMin);
}

// ---- construction ----------------------------------------------------------------------------

TEST(PointSetBuild, EveryPointKeepsItsRadiusFromEarlierPoints) {
    PillarRoom room;
    PointSetStats stats;
    const PointCache cache = buildSet(room.registry, roomSettings(), &stats);
    ASSERT_GT(cache.size(), 500u);
    EXPECT_EQ(stats.stop, PointSetStop::Rejections);
    for (std::size_t j = 0; j < cache.size(); ++j) {
        EXPECT_GE(cache.radius[j], cache.settings.rMin);
        EXPECT_LE(cache.radius[j], cache.settings.rMax);
        for (std::size_t i = 0; i < j; ++i) {
            const float d = glm::length(cache.position[i] - cache.position[j]);
            ASSERT_GE(d, cache.radius[j]) << "points " << i << " and " << j;
            ASSERT_GE(d, cache.settings.rMin);
        }
    }
}

TEST(PointSetBuild, PointsOnAxisAlignedFacesLieOnTheirPlaneExactlyAndGroupIntoDiscPlanes) {
    // The room's and pillar's faces are the planes x, z = +-2, +-0.2 and y = +-1. A crate turned
    // 30 degrees about y keeps its top and bottom in planes of constant y, not its sides.
    Registry registry;
    addMesh(registry, boxMesh({2.f, 1.f, 2.f}, true), glm::mat4(1.f), grey(0.7f), false, "room");
    addMesh(registry, boxMesh({0.2f, 1.f, 0.2f}), glm::mat4(1.f), grey(0.7f), false, "pillar");
    addPointLight(registry, {1.2f, 0.8f, 1.2f}, 20.f);
    const float turn = glm::radians(30.f);
    const glm::mat4 crateWorld =
        translation({-1.2f, -0.7f, 1.1f}) * glm::rotate(glm::mat4(1.f), turn, {0.f, 1.f, 0.f});
    addMesh(registry, boxMesh(glm::vec3(0.3f)), crateWorld, grey(0.5f), false, "crate");
    test::buildRayScene(registry);
    const PointCache cache = buildSet(registry, roomSettings(), nullptr);
    ASSERT_GT(cache.size(), 500u);
    const float crateTop = glm::vec3(crateWorld * glm::vec4(0.f, 0.3f, 0.f, 1.f)).y;
    std::size_t onCrateSides = 0, onCrateTop = 0;
    std::vector<glm::vec3> axisCentres, axisNormals;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p], n = cache.normal[p];
        const glm::vec3 local = glm::vec3(glm::inverse(crateWorld) * glm::vec4(x, 1.f));
        const bool onCrate =
            std::max({std::abs(local.x), std::abs(local.y), std::abs(local.z)}) < 0.3f + 1e-4f;
        if (onCrate && std::abs(local.y) < 0.3f - 1e-4f) {
            // A side: its normal is the turned one, left as the ray scene gave it.
            ++onCrateSides;
            EXPECT_NE(n.x, 0.f) << "point " << p;
            EXPECT_NE(n.z, 0.f) << "point " << p;
            continue;
        }
        int axis = -1;
        for (int a = 0; a < 3; ++a)
            if (std::abs(n[a]) == 1.f && n[(a + 1) % 3] == 0.f && n[(a + 2) % 3] == 0.f) axis = a;
        ASSERT_GE(axis, 0) << "point " << p << " normal " << n.x << " " << n.y << " " << n.z;
        axisCentres.push_back(x);
        axisNormals.push_back(n);
        const float c = x[axis];
        if (onCrate) {
            ++onCrateTop;
            EXPECT_EQ(c, crateTop) << "point " << p;
        } else if (axis == 1)
            EXPECT_TRUE(c == 1.f || c == -1.f) << "point " << p << " y " << c;
        else
            EXPECT_TRUE(c == 2.f || c == -2.f || c == 0.2f || c == -0.2f)
                << "point " << p << " axis " << axis << " at " << c;
    }
    EXPECT_GT(onCrateSides, 5u);
    ASSERT_GE(onCrateTop, DiscIndex::kMinPlaneDiscs); // enough to make a plane of their own
    // Then the discs of those points group into the index's exact planes, every one of them.
    DiscIndex discs(registry.ctx().get<RayScene>().device(), DiscIndex::Motion::Static);
    discs.build(axisCentres, axisNormals, cache.settings.detpRadius);
    EXPECT_EQ(discs.planarDiscCount(), axisCentres.size());
    EXPECT_EQ(discs.tiltedPlaneCount(), 0u);
}

TEST(PointSetBuild, TrivialTestsChangeOnlyTheAoCallCount) {
    PillarRoom room;
    PointCacheSettings fast = roomSettings();
    PointCacheSettings slow = fast;
    slow.trivialTests = false;
    PointSetStats fastStats, slowStats;
    const PointCache a = buildSet(room.registry, fast, &fastStats);
    const PointCache b = buildSet(room.registry, slow, &slowStats);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.position.data(), b.position.data(), a.size() * sizeof(glm::vec3)), 0);
    EXPECT_EQ(std::memcmp(a.normal.data(), b.normal.data(), a.size() * sizeof(glm::vec3)), 0);
    EXPECT_EQ(a.radius, b.radius);
    EXPECT_EQ(fastStats.darts, slowStats.darts);
    EXPECT_EQ(slowStats.aoCalls, slowStats.darts - slowStats.misses);
    EXPECT_LT(fastStats.aoCalls, slowStats.aoCalls);
    EXPECT_GT(fastStats.trivialAccepts, 0u);
    EXPECT_GT(fastStats.trivialRejects, 0u);
    EXPECT_EQ(fastStats.aoCalls + fastStats.trivialAccepts + fastStats.trivialRejects +
                  fastStats.misses,
              fastStats.darts);
}

TEST(PointSetBuild, SameSeedSameSetOtherSeedOtherSet) {
    PillarRoom room;
    const PointCache a = buildSet(room.registry, roomSettings(), nullptr);
    const PointCache b = buildSet(room.registry, roomSettings(), nullptr);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.position.data(), b.position.data(), a.size() * sizeof(glm::vec3)), 0);
    PointCacheSettings other = roomSettings();
    other.seed = 2;
    const PointCache c = buildSet(room.registry, other, nullptr);
    EXPECT_TRUE(c.size() != a.size() ||
                std::memcmp(a.position.data(), c.position.data(), a.size() * sizeof(glm::vec3)));
    // Nor does the set depend on how many threads build it.
    PointCache single;
    {
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        single = buildSet(room.registry, roomSettings(), nullptr);
    }
    ASSERT_EQ(single.size(), a.size());
    EXPECT_EQ(std::memcmp(a.position.data(), single.position.data(), a.size() * sizeof(glm::vec3)),
              0);
    EXPECT_EQ(a.radius, single.radius);
    EXPECT_EQ(a.ao, single.ao);
}

TEST(PointSetBuild, DensityIsHigherAtTheCreaseThanOnTheOpenFloor) {
    PillarRoom room;
    const PointCache cache = buildSet(room.registry, roomSettings(), nullptr);
    // Floor points (y = -1, facing up), by Chebyshev distance from the pillar's axis.
    double creaseCount = 0, openCount = 0, creaseRadius = 0, openRadius = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p];
        if (!(std::abs(x.y + 1.f) < 1e-3f && cache.normal[p].y > 0.99f)) continue;
        const float c = std::max(std::abs(x.x), std::abs(x.z));
        if (c > 0.2f && c <= 0.3f) {
            ++creaseCount;
            creaseRadius += cache.radius[p];
        } else if (c >= 0.8f && c <= 1.3f) {
            ++openCount;
            openRadius += cache.radius[p];
        }
    }
    const double creaseArea = 0.6 * 0.6 - 0.4 * 0.4, openArea = 2.6 * 2.6 - 1.6 * 1.6;
    ASSERT_GT(creaseCount, 5);
    ASSERT_GT(openCount, 50);
    EXPECT_GT(creaseCount / creaseArea, 1.3 * openCount / openArea);
    EXPECT_LT(creaseRadius / creaseCount, openRadius / openCount);
}

TEST(PointSetBuild, AmbientOcclusionBesideAWallMatchesItsClosedForm) {
    // A floor point a distance s from a wall that stands far above and beside it, AO distance
    // D. Cosine-weighted directions project uniformly onto the unit disc of the floor
    // (Malley's method), and a direction meets the wall within D when its horizontal
    // component toward the wall is at least a = s / D: the disc's segment beyond the chord
    // at a, AO = (acos a - a sqrt(1 - a^2)) / pi. Uniform directions, or no distance limit
    // (AO 1/2 everywhere), would fail.
    Registry registry;
    addMesh(registry, test::gridMesh({-10.f, 0.f, 10.f}, {20.f, 0.f, 0.f}, {0.f, 0.f, -20.f}, 1),
            glm::mat4(1.f), grey(0.5f), false, "floor");
    // The wall x = 0, 10 m high and 20 m wide: every ray that reaches x = 0 within D = 1 m
    // meets it.
    addMesh(registry, test::gridMesh({0.f, 0.f, 10.f}, {0.f, 10.f, 0.f}, {0.f, 0.f, -20.f}, 1),
            glm::mat4(1.f), grey(0.5f), false, "wall");
    test::buildRayScene(registry);
    const RayScene& scene = registry.ctx().get<RayScene>();
    constexpr float kDistance = 1.f;
    constexpr std::uint32_t kRays = 256, kKeys = 256;
    for (const double a : {0.05, 0.25, 0.5, 0.8}) {
        const double expected = (std::acos(a) - a * std::sqrt(1.0 - a * a)) / std::acos(-1.0);
        double sum = 0.0;
        for (std::uint32_t key = 0; key < kKeys; ++key)
            sum += ambientOcclusion(scene, {-float(a) * kDistance, 0.f, 0.f}, {0.f, 1.f, 0.f},
                                    kRays, kDistance, 7, key);
        // Every ray is an independent Bernoulli trial (its own hashed numbers): 5 standard
        // errors of the binomial proportion, a one-in-a-million miss.
        const double n = double(kRays) * kKeys;
        EXPECT_NEAR(sum / kKeys, expected, 5.0 * std::sqrt(expected * (1.0 - expected) / n))
            << "s / D = " << a;
    }
}

TEST(PointSetBuild, NoPointsWhereLightCannotReach) {
    Registry registry;
    // A lit room; inside it a hollow closed box (faces inward and outward alike: rays hit both
    // sides) with no light inside; the room's own outside faces the dark.
    addMesh(registry, boxMesh({2.f, 1.f, 2.f}, true), glm::mat4(1.f), grey(0.7f), false, "room");
    const glm::vec3 boxCentre(0.8f, -0.5f, -0.8f);
    addMesh(registry, boxMesh(glm::vec3(0.3f), true), translation(boxCentre), grey(0.7f), false,
            "closed box");
    addPointLight(registry, {-1.f, 0.5f, 1.f}, 20.f);
    test::buildRayScene(registry);
    const PointCache cache = buildSet(registry, roomSettings(), nullptr);
    ASSERT_GT(cache.size(), 200u);
    std::size_t onBox = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p], n = cache.normal[p];
        // Inside the room, never outside it, and facing into it.
        EXPECT_LE(std::abs(x.x), 2.f + 1e-4f);
        EXPECT_LE(std::abs(x.y), 1.f + 1e-4f);
        EXPECT_LE(std::abs(x.z), 2.f + 1e-4f);
        const glm::vec3 local = x - boxCentre;
        const bool onClosedBox =
            std::max({std::abs(local.x), std::abs(local.y), std::abs(local.z)}) < 0.3f + 1e-4f;
        if (onClosedBox) {
            ++onBox;
            EXPECT_GT(glm::dot(n, local), 0.f) << "a point inside the closed box";
        } else {
            EXPECT_LT(glm::dot(n, x), 0.f) << "a point on the outside of the room";
        }
    }
    EXPECT_GT(onBox, 10u); // the box's outside is lit and does receive points

    Registry dark;
    addMesh(dark, boxMesh({2.f, 1.f, 2.f}, true), glm::mat4(1.f), grey(0.7f), false, "room");
    test::buildRayScene(dark);
    PointSetStats stats;
    EXPECT_EQ(buildSet(dark, roomSettings(), &stats).size(), 0u);
    EXPECT_EQ(stats.stop, PointSetStop::NoSources);
}

// ---- query -----------------------------------------------------------------------------------

/// Points on the plane y = 0 facing up, a few on its underside facing down, a tilted patch.
PointCache syntheticCache(std::uint32_t count, std::uint32_t seed, std::uint32_t falloff = 1) {
    PointCache cache;
    cache.settings.rMin = 0.05f;
    cache.settings.rMax = 0.2f;
    cache.settings.falloffExponent = falloff;
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (std::uint32_t i = 0; i < count; ++i) {
        const float kind = u(rng);
        glm::vec3 p(4.f * u(rng) - 2.f, 0.f, 4.f * u(rng) - 2.f), n(0.f, 1.f, 0.f);
        if (kind < 0.15f) {
            p.y = -0.02f; // the underside of a 2 cm slab
            n = glm::vec3(0.f, -1.f, 0.f);
        } else if (kind < 0.3f) {
            n = glm::normalize(glm::vec3(u(rng) - 0.5f, 1.f, u(rng) - 0.5f));
        }
        cache.position.push_back(p);
        cache.normal.push_back(n);
        cache.radius.push_back(0.05f + 0.15f * u(rng));
        cache.dart.push_back(i);
        cache.ao.push_back(u(rng));
        cache.direct.push_back(glm::vec3(u(rng), 2.f * u(rng), 3.f * u(rng)));
        cache.indirect.push_back(glm::vec3(u(rng)));
    }
    cache.buildGrid();
    return cache;
}

struct Query {
    glm::vec3 x, n;
};

std::vector<Query> randomQueries(std::uint32_t count, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<Query> out;
    for (std::uint32_t i = 0; i < count; ++i) {
        const glm::vec3 x(5.f * u(rng) - 2.5f, 0.3f * u(rng) - 0.15f, 5.f * u(rng) - 2.5f);
        const float k = u(rng);
        const glm::vec3 n =
            k < 0.2f   ? glm::vec3(0.f, -1.f, 0.f)
            : k < 0.4f ? glm::normalize(glm::vec3(u(rng) - .5f, u(rng) - .5f, u(rng) - .5f))
                       : glm::vec3(0.f, 1.f, 0.f);
        out.push_back({x, n});
    }
    return out;
}

/// The in-range rule, written out independently of PointGrid.
std::vector<std::uint32_t> bruteForce(const PointCache& c, const Query& q) {
    std::vector<std::uint32_t> out;
    for (std::uint32_t p = 0; p < c.size(); ++p) {
        const float R = c.settings.searchScale * c.radius[p];
        const glm::vec3 d = q.x - c.position[p];
        if (glm::length(d) < R && glm::dot(c.normal[p], q.n) >= c.settings.minNormalCosine &&
            std::abs(glm::dot(c.normal[p], d)) <= c.settings.planeTolerance * R)
            out.push_back(p);
    }
    return out;
}

TEST(PointCacheQuery, GridFindsExactlyWhatBruteForceFinds) {
    for (const float cell : {0.f, 0.07f, 0.9f}) {
        PointCache cache = syntheticCache(3000, 7);
        cache.settings.gridCellSize = cell;
        cache.buildGrid();
        std::size_t nonEmpty = 0;
        for (const Query& q : randomQueries(3000, 11)) {
            std::vector<std::uint32_t> found;
            cache.grid.forEachInRange(q.x, q.n,
                                      [&](std::uint32_t p, float) { found.push_back(p); });
            const std::vector<std::uint32_t> expected = bruteForce(cache, q);
            ASSERT_EQ(found, expected) << "cell " << cell;
            nonEmpty += expected.empty() ? 0 : 1;
        }
        EXPECT_GT(nonEmpty, 1000u);
        // The cell holding a point lists it (the shadow queue walks points by that cell), and
        // a position outside the grid has no cell.
        for (std::uint32_t p = 0; p < cache.size(); ++p) {
            const std::int64_t c = cache.grid.cellOf(cache.position[p]);
            ASSERT_GE(c, 0) << "point " << p;
            const std::span<const std::uint32_t> listed = cache.grid.candidates(cache.position[p]);
            ASSERT_TRUE(std::find(listed.begin(), listed.end(), p) != listed.end())
                << "point " << p << " cell " << cell;
        }
        EXPECT_EQ(cache.grid.cellOf(cache.grid.origin() - glm::vec3(1.f)), -1);
    }
}

TEST(ShadowCandidates, TheCulledWalkFindsExactlyWhatTestingEveryPointFinds) {
    // Random area-light balls (one below the floor, behind every point's horizon) and random
    // mobile steps, short (one ball holds both poses) and long, over the synthetic points at
    // three grid cell sizes: the walk over blocks and cells must give every point exactly the
    // (move, light) pairs mayShadow() gives it, in that order, while testing fewer points.
    std::mt19937 rng(23);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const auto in = [&](float lo, float hi) { return lo + (hi - lo) * u(rng); };
    // The same scene 10 km off the origin too, where float rounding is a hundredth of a cell.
    std::size_t found = 0, culled = 0, mergedMoves = 0;
    for (const glm::vec3 offset : {glm::vec3(0.f), glm::vec3(1e4f, -3e3f, 7e3f)})
        for (const float cellSize : {0.f, 0.07f, 0.9f}) {
            PointCache cache = syntheticCache(3000, 7);
            for (glm::vec3& p : cache.position)
                p += offset;
            cache.settings.gridCellSize = cellSize;
            cache.buildGrid();
            for (int trial = 0; trial < 40; ++trial) {
                std::vector<AreaLight> lights(4);
                for (AreaLight& l : lights) {
                    l.centre = offset + glm::vec3(in(-3.f, 3.f), in(0.8f, 3.f), in(-3.f, 3.f));
                    l.boundRadius = in(0.05f, 1.f);
                }
                lights[3].centre.y = offset.y - 1.5f;
                lights[3].boundRadius = 0.5f;
                std::vector<MobileMove> moves;
                for (int m = 0, count = 1 + trial % 3; m < count; ++m) {
                    const glm::vec3 before =
                        offset + glm::vec3(in(-2.f, 2.f), in(0.05f, 1.f), in(-2.f, 2.f));
                    const float radius = in(0.05f, 0.4f);
                    const float step = (trial + m) % 2 == 0 ? in(0.f, 2.f * radius) : in(1.f, 3.f);
                    const glm::vec3 direction =
                        glm::normalize(glm::vec3(in(-1.f, 1.f), in(-0.3f, 0.3f), in(-1.f, 1.f)));
                    moves.push_back(MobileMove::make(before, radius, before + step * direction,
                                                     radius * in(0.8f, 1.2f)));
                    const MobileMove& mm = moves.back();
                    if (mm.merged) {
                        ++mergedMoves;
                        // The one ball holds both poses' balls.
                        EXPECT_LE(glm::length(mm.middle - mm.before) + mm.radiusBefore,
                                  mm.radiusBoth);
                        EXPECT_LE(glm::length(mm.middle - mm.after) + mm.radiusAfter,
                                  mm.radiusBoth);
                    }
                }
                const float raySlack = 1e-3f;
                std::vector<std::vector<std::uint64_t>> got(cache.size());
                const std::size_t tested = forEachShadowedPair(
                    cache.grid, cache.position, cache.normal, lights, moves, raySlack,
                    [&](std::uint32_t p, std::uint32_t m, std::uint32_t l) {
                        got[p].push_back(std::uint64_t(m) << 32 | l);
                    });
                std::size_t pairs = 0;
                for (std::uint32_t p = 0; p < cache.size(); ++p) {
                    std::vector<std::uint64_t> expected;
                    for (std::uint32_t m = 0; m < moves.size(); ++m)
                        for (std::uint32_t l = 0; l < lights.size(); ++l)
                            if (mayShadow(moves[m], cache.position[p], cache.normal[p], lights[l],
                                          raySlack))
                                expected.push_back(std::uint64_t(m) << 32 | l);
                    ASSERT_EQ(got[p], expected)
                        << "point " << p << ", cell " << cellSize << ", trial " << trial;
                    pairs += expected.size();
                }
                found += pairs;
                culled += tested < cache.size() ? 1 : 0;
                EXPECT_GE(tested,
                          std::size_t(std::count_if(got.begin(), got.end(),
                                                    [](const auto& g) { return !g.empty(); })));
            }
        }
    EXPECT_GT(found, 2000u);      // the moves do shadow points
    EXPECT_GT(culled, 120u);      // and the walk leaves points untested
    EXPECT_GT(mergedMoves, 100u); // both kinds of move were drawn
}

TEST(ShadowCandidates, PointsOnBoxCornersAtTheRulesThresholdAreFound) {
    // The culling's margins, tested where they matter: 10 km off the origin (float rounding a
    // few hundredths of a 5 cm cell), points exactly on grid corners (on the edge of the cells
    // and blocks that hold them), and for each such point a box of 1, 2, 4 or 8 cells around
    // it, a mobile just beyond the point on the line from the box's centre through it, a small
    // light on the other side, and the mobile's radius the smallest float for which
    // mayShadow() holds: the walk must still find the point.
    const glm::vec3 offset(1e4f, 1e4f, 1e4f);
    const float cellSize = 0.05f;
    std::mt19937 rng(31);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    PointGrid::Params params;
    params.cellSize = cellSize;
    std::vector<glm::vec3> positions, normals;
    std::vector<float> radii;
    const float extent = 64.f * cellSize;
    for (int i = 0; i < 1000; ++i) {
        positions.push_back(offset + extent * glm::vec3(u(rng), u(rng), u(rng)));
        normals.emplace_back(0.f, 1.f, 0.f);
        radii.push_back(0.5f * cellSize);
    }
    PointGrid first;
    first.build(positions, normals, radii, params);
    // Corner points inside the first grid's box keep its origin and cells.
    const std::size_t firstCorner = positions.size();
    for (int i = 0; i < 2000; ++i) {
        glm::ivec3 k(1 + int(u(rng) * float(first.dims().x - 3)),
                     1 + int(u(rng) * float(first.dims().y - 3)),
                     1 + int(u(rng) * float(first.dims().z - 3)));
        if (i % 2) k = glm::max(k / 8 * 8, glm::ivec3(8)); // a block's corner
        k = glm::min(k, first.dims() - 2);
        positions.push_back(first.origin() + glm::vec3(k) * first.cellSize());
        normals.emplace_back(0.f, 1.f, 0.f);
        radii.push_back(0.5f * cellSize);
    }
    PointGrid grid;
    grid.build(positions, normals, radii, params);
    ASSERT_EQ(grid.origin(), first.origin());
    ASSERT_EQ(grid.cellSize(), first.cellSize());
    const float raySlack = 1e-4f;
    std::size_t checked = 0;
    for (int trial = 0; trial < 800; ++trial) {
        const std::uint32_t p = std::uint32_t(firstCorner + std::size_t(u(rng) * 2000.f) % 2000);
        const glm::vec3 x = positions[p];
        const std::int64_t c = grid.cellOf(x);
        const glm::ivec3 dims = grid.dims();
        const glm::ivec3 cell(int(c % dims.x), int(c / dims.x % dims.y),
                              int(c / (std::int64_t(dims.x) * dims.y)));
        const int side = 1 << (trial % 4);
        const glm::ivec3 lo = cell / side * side, hi = glm::min(lo + side, dims);
        const glm::vec3 q = grid.origin() + (glm::vec3(lo) + 0.5f * glm::vec3(hi - lo)) * cellSize;
        const glm::dvec3 away = glm::normalize(glm::dvec3(x) - glm::dvec3(q));
        AreaLight light;
        light.centre = glm::vec3(glm::dvec3(x) - away * double(24.f * cellSize));
        light.boundRadius = 0.01f * cellSize;
        if (glm::dot(normals[p], light.centre - x) < -light.boundRadius) continue;
        const glm::vec3 centre =
            glm::vec3(glm::dvec3(x) + away * double(cellSize * (0.5f + 3.f * u(rng))));
        // The smallest radius that shadows x, by float steps from the distance.
        const auto shadows = [&](float R) {
            const MobileMove m =
                MobileMove::make(centre, R, centre + glm::vec3(100.f * cellSize), R);
            return mayShadow(m, x, normals[p], light, raySlack);
        };
        float R = float(distanceBeyondCone(centre, x, light.centre, light.boundRadius));
        for (int step = 0; step < 4096 && !shadows(R); ++step)
            R = std::nextafter(R, 1e30f);
        for (int step = 0; step < 4096 && R > 0.f && shadows(std::nextafter(R, 0.f)); ++step)
            R = std::nextafter(R, 0.f);
        if (!shadows(R)) continue;
        const std::vector<MobileMove> moves = {
            MobileMove::make(centre, R, centre + glm::vec3(100.f * cellSize), R)};
        const std::vector<AreaLight> lights = {light};
        std::atomic<bool> found{false}; // visits come from several tasks
        forEachShadowedPair(grid, positions, normals, lights, moves, raySlack,
                            [&](std::uint32_t point, std::uint32_t, std::uint32_t) {
                                if (point == p) found = true;
                            });
        EXPECT_TRUE(found) << "point " << p << " in a box of " << side << " cells";
        ++checked;
    }
    EXPECT_GT(checked, 400u); // the rest have the light below their horizon
}

TEST(PointCacheQuery, BlendIsTheFalloffWeightedMeanOfThePointsInRange) {
    // Seed 003's blend, written out in double over the brute-force set: w = (1 - d / R)^k,
    // value = sum w v / sum w, for direct, indirect and AO alike.
    for (const std::uint32_t k : {1u, 2u, 3u}) {
        PointCache cache = syntheticCache(2000, 5, k);
        EXPECT_EQ(cache.weight(0.5f, 1.f), std::pow(0.5f, float(k))); // exact in float
        EXPECT_EQ(cache.weight(1.f, 1.f), 0.f);
        std::size_t blended = 0;
        for (const Query& q : randomQueries(1000, 9)) {
            const PointCacheSample s = cache.sample(q.x, q.n);
            double wSum = 0.0, ao = 0.0;
            glm::dvec3 direct(0.0), indirect(0.0);
            const std::vector<std::uint32_t> in = bruteForce(cache, q);
            for (const std::uint32_t p : in) {
                const double d = glm::length(glm::dvec3(q.x) - glm::dvec3(cache.position[p]));
                const double w = std::pow(1.0 - d / double(cache.searchRadius(p)), double(k));
                wSum += w;
                direct += w * glm::dvec3(cache.direct[p]);
                indirect += w * glm::dvec3(cache.indirect[p]);
                ao += w * double(cache.ao[p]);
            }
            if (!(wSum > 0.0)) continue;
            ++blended;
            // The code takes d in float (relative error a few u), so each weight is off by at
            // most k x 4u; with values in [0, 3] (syntheticCache) the blend moves by at most that
            // times count x 3 / sum w, plus the final float rounding.
            const double bound =
                4.0 * k * 0x1p-24 * double(in.size()) * 3.0 / wSum + 4.0 * 0x1p-24 * 3.0;
            for (int c = 0; c < 3; ++c) {
                EXPECT_NEAR(s.direct[c], direct[c] / wSum, bound);
                EXPECT_NEAR(s.indirect[c], indirect[c] / wSum, bound);
            }
            EXPECT_NEAR(s.ao, ao / wSum, bound);
        }
        EXPECT_GT(blended, 500u);
    }
}

TEST(PointCacheQuery, BlendIsAConvexCombinationAndReproducesAConstant) {
    for (const std::uint32_t k : {1u, 2u, 3u}) {
        PointCache cache = syntheticCache(2000, 3, k);
        PointCache constant = cache;
        std::fill(constant.direct.begin(), constant.direct.end(), glm::vec3(0.3f, 1.7f, 42.f));
        std::fill(constant.ao.begin(), constant.ao.end(), 0.25f);
        for (const Query& q : randomQueries(1000, 5)) {
            const PointCacheSample s = cache.sample(q.x, q.n);
            const std::vector<std::uint32_t> in = bruteForce(cache, q);
            std::size_t positive = 0;
            glm::vec3 low(INFINITY), high(-INFINITY);
            for (const std::uint32_t p : in) {
                if (cache.weight(glm::length(q.x - cache.position[p]), cache.searchRadius(p)) > 0.f)
                    ++positive;
                low = glm::min(low, cache.direct[p]);
                high = glm::max(high, cache.direct[p]);
            }
            ASSERT_EQ(s.count, positive);
            if (s.count == 0) continue;
            // The blend sums in double (n 2^-53 off, far below 2^-24 for these counts) and
            // rounds once to float (2^-24): within 2^-23 of the exact blend, relative.
            constexpr double kBlendRounding = 0x1p-23;
            for (int c = 0; c < 3; ++c) {
                EXPECT_GE(s.direct[c], low[c] * (1.0 - kBlendRounding));
                EXPECT_LE(s.direct[c], high[c] * (1.0 + kBlendRounding));
            }
            const PointCacheSample sc = constant.sample(q.x, q.n);
            EXPECT_NEAR(sc.direct.x, 0.3f, 0.3 * kBlendRounding);
            EXPECT_NEAR(sc.direct.y, 1.7f, 1.7 * kBlendRounding);
            EXPECT_NEAR(sc.direct.z, 42.f, 42.0 * kBlendRounding);
            EXPECT_NEAR(sc.ao, 0.25f, 0.25 * kBlendRounding);
        }
    }
}

TEST(PointCacheQuery, WeightsArePositiveAndStrictlyDecreasing) {
    PointCache cache;
    for (const std::uint32_t k : {1u, 2u, 3u}) {
        cache.settings.falloffExponent = k;
        float previous = cache.weight(0.f, 1.f);
        EXPECT_EQ(previous, 1.f);
        for (int i = 1; i < 100; ++i) {
            const float w = cache.weight(float(i) / 100.f, 1.f);
            EXPECT_GT(w, 0.f);
            EXPECT_LT(w, previous);
            previous = w;
        }
        EXPECT_EQ(cache.weight(1.f, 1.f), 0.f);
        EXPECT_EQ(cache.weight(2.f, 1.f), 0.f);
    }
}

TEST(PointCacheQuery, SinglePointReturnsItsValueAndNothingBeyondItsRadius) {
    PointCache cache;
    cache.position = {glm::vec3(1.f, 2.f, 3.f)};
    cache.normal = {glm::vec3(0.f, 0.f, 1.f)};
    cache.radius = {0.1f};
    cache.dart = {0};
    cache.ao = {0.4f};
    cache.direct = {glm::vec3(5.f, 6.f, 7.f)};
    cache.indirect = {glm::vec3(0.5f)};
    cache.buildGrid();
    const glm::vec3 n(0.f, 0.f, 1.f);
    for (const float d : {0.f, 0.05f, 0.15f, 0.1999f}) {
        const PointCacheSample s = cache.sample(glm::vec3(1.f + d, 2.f, 3.f), n);
        ASSERT_EQ(s.count, 1u) << d;
        EXPECT_FLOAT_EQ(s.direct.x, 5.f);
        EXPECT_FLOAT_EQ(s.direct.z, 7.f);
        EXPECT_FLOAT_EQ(s.indirect.y, 0.5f);
        EXPECT_FLOAT_EQ(s.ao, 0.4f);
    }
    EXPECT_EQ(cache.sample(glm::vec3(1.2f, 2.f, 3.f), n).count, 0u);
    // Facing away (the other side of a thin wall) and behind the plane do not count.
    EXPECT_EQ(cache.sample(glm::vec3(1.f, 2.f, 3.f), -n).count, 0u);
    EXPECT_EQ(cache.sample(glm::vec3(1.f, 2.f, 3.f - 0.15f), n).count, 0u);
}

TEST(PointCacheQuery, EmptyNeighbourhoodFallsBackWithoutNan) {
    const PointCache cache = syntheticCache(200, 1);
    PointCache empty;
    empty.buildGrid();
    const glm::vec3 up(0.f, 1.f, 0.f);
    for (const PointCacheSample& s :
         {cache.sample(glm::vec3(50.f, 0.f, 50.f), up), empty.sample(glm::vec3(0.f), up),
          cache.sample(glm::vec3(std::nanf("")), up), cache.sample(glm::vec3(0.f), glm::vec3(NAN)),
          cache.sample(glm::vec3(INFINITY, 0.f, 0.f), up)}) {
        EXPECT_EQ(s.count, 0u);
        EXPECT_EQ(s.direct, glm::vec3(0.f));
        EXPECT_EQ(s.indirect, glm::vec3(0.f));
        EXPECT_EQ(s.ao, 0.f);
    }
}

TEST(PointCacheQuery, ConcurrentQueriesGiveTheSerialResults) {
    // The renderer and the systems query one cache from many threads: sample() is const and
    // keeps no state, so queries run in parallel (each query many times over, interleaved)
    // give what they give one at a time. A built cache is also the same from the same input.
    const PointCache a = syntheticCache(2000, 9);
    const PointCache b = syntheticCache(2000, 9);
    ASSERT_TRUE(std::equal(a.grid.cellPoints().begin(), a.grid.cellPoints().end(),
                           b.grid.cellPoints().begin(), b.grid.cellPoints().end()));
    const std::vector<Query> queries = randomQueries(500, 2);
    std::vector<PointCacheSample> serial;
    for (const Query& q : queries)
        serial.push_back(b.sample(q.x, q.n));
    constexpr std::size_t kRounds = 16;
    std::vector<PointCacheSample> parallel(queries.size() * kRounds);
    tbb::parallel_for(std::size_t(0), parallel.size(), [&](std::size_t i) {
        const Query& q = queries[i % queries.size()];
        parallel[i] = a.sample(q.x, q.n);
    });
    for (std::size_t i = 0; i < parallel.size(); ++i)
        ASSERT_EQ(std::memcmp(&parallel[i], &serial[i % queries.size()], sizeof serial[0]), 0)
            << "query " << i % queries.size();
}

} // namespace
} // namespace qgi
