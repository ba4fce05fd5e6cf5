// Point cache (seed 003): stored soft shadows against an independent reference, the cache
// file, the per-frame update.
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/raytrace/RayScene.h"
#include "systems/frame/FrameSchedule.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointCacheFile.h"
#include "systems/point_cache/PointCacheSystem.h"
#include "systems/point_cache/PointShading.h"
#include "test_meshes.h"
#include "test_photon_scenes.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace qgi {
namespace {

using test::addMesh;
using test::grey;
using test::gridMesh;
using test::translation;

// Geometry of the soft-shadow scene, metres: a floor at y = 0, a square blocker at kBlockerY,
// a square light of radiance kRadiance facing down at kLightY.
constexpr float kLightHalf = 0.5f, kLightY = 1.5f;
constexpr float kBlockerHalf = 0.3f, kBlockerY = 0.75f;
constexpr float kRadiance = 10.f;

struct ShadowScene {
    Registry registry;
    Entity blocker;
    explicit ShadowScene(bool withBlocker = true, bool blockerMobile = false,
                         bool withCeiling = false) {
        addMesh(registry, gridMesh({-6.f, 0.f, 6.f}, {12.f, 0.f, 0.f}, {0.f, 0.f, -12.f}, 1),
                glm::mat4(1.f), grey(0.5f), false, "floor");
        if (withCeiling) // darts from the floor land on it and back: points all over the floor
            addMesh(registry, gridMesh({-6.f, 3.f, -6.f}, {12.f, 0.f, 0.f}, {0.f, 0.f, 12.f}, 1),
                    glm::mat4(1.f), grey(0.5f), false, "ceiling");
        if (withBlocker)
            blocker =
                addMesh(registry,
                        gridMesh({-kBlockerHalf, 0.f, -kBlockerHalf},
                                 {2.f * kBlockerHalf, 0.f, 0.f}, {0.f, 0.f, 2.f * kBlockerHalf}, 1),
                        translation({0.f, kBlockerY, 0.f}), grey(0.5f), blockerMobile, "blocker");
        Material light = grey(0.5f);
        light.emission = glm::vec3(kRadiance);
        // cross(u, v) = -y: the light faces the floor.
        addMesh(registry,
                gridMesh({-kLightHalf, kLightY, -kLightHalf}, {2.f * kLightHalf, 0.f, 0.f},
                         {0.f, 0.f, 2.f * kLightHalf}, 1),
                glm::mat4(1.f), light, false, "light");
        test::buildRayScene(registry);
    }
};

/// Irradiance at a floor point x (normal +y) from the light, by an n x n midpoint rule over the
/// light with the blocker tested analytically (no ray tracing), plus what a Monte Carlo
/// estimate with uniform area samples needs: the per-sample variance, and a bound on the
/// rule's own error (cells whose corners disagree on visibility count in full).
struct Reference {
    double irradiance = 0.0, sampleVariance = 0.0, quadratureBound = 0.0;
};

Reference reference(const glm::vec3& x, int n, bool withBlocker,
                    const glm::vec3& blockerOffset = glm::vec3(0.f)) {
    const double side = 2.0 * kLightHalf, cell = side / n, area = side * side;
    const auto visible = [&](double lx, double lz) {
        if (!withBlocker) return true;
        const double t = (kBlockerY + blockerOffset.y - x.y) / (kLightY - x.y);
        const double bx = x.x + t * (lx - x.x) - blockerOffset.x;
        const double bz = x.z + t * (lz - x.z) - blockerOffset.z;
        return !(std::abs(bx) < kBlockerHalf && std::abs(bz) < kBlockerHalf);
    };
    const auto f = [&](double lx, double lz) {
        const glm::dvec3 w(lx - x.x, kLightY - x.y, lz - x.z);
        const double d2 = glm::dot(w, w);
        return (w.y / std::sqrt(d2)) * (w.y / std::sqrt(d2)) / d2; // cos_x = cos_light = w.y / d
    };
    double sum = 0.0, sum2 = 0.0, cut = 0.0, fMax = 0.0;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            const double lx = -kLightHalf + (i + 0.5) * cell, lz = -kLightHalf + (j + 0.5) * cell;
            const double v = visible(lx, lz) ? f(lx, lz) : 0.0;
            sum += v;
            sum2 += v * v;
            fMax = std::max(fMax, f(lx, lz));
            const double x0 = lx - 0.5 * cell, x1 = lx + 0.5 * cell;
            const double z0 = lz - 0.5 * cell, z1 = lz + 0.5 * cell;
            const bool a = visible(x0, z0), b = visible(x1, z0), c = visible(x0, z1),
                       d = visible(x1, z1);
            if (a != b || a != c || a != d) cut += 1.0;
        }
    Reference r;
    const double dA = cell * cell;
    r.irradiance = kRadiance * sum * dA;
    // One uniform sample estimates L A f V: variance L^2 A^2 E[(fV)^2] - E^2.
    r.sampleVariance = std::max(0.0, kRadiance * kRadiance * area * area * (sum2 / (n * n)) -
                                         r.irradiance * r.irradiance);
    // Smooth part: the midpoint rule on f (|f''| over a cell is tiny at these distances) is
    // bounded generously by 1e-4 relative; cells cut by the shadow edge by their full weight.
    r.quadratureBound = kRadiance * (cut * fMax * dA) + 1e-4 * r.irradiance;
    return r;
}

/// Lambert's closed form for the unoccluded irradiance of a polygon of uniform radiance:
/// E = L/2 sum_i angle_i (n . unit(v_i x v_{i+1})), v_i = corner_i - x.
double lambertPolygon(const glm::dvec3& x, const glm::dvec3& n, const glm::dvec3 (&corners)[4]) {
    double sum = 0.0;
    for (int i = 0; i < 4; ++i) {
        const glm::dvec3 a = glm::normalize(corners[i] - x),
                         b = glm::normalize(corners[(i + 1) % 4] - x);
        const glm::dvec3 c = glm::cross(a, b);
        sum += std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0)) * glm::dot(n, glm::normalize(c));
    }
    return 0.5 * kRadiance * std::abs(sum);
}

TEST(PointCacheShading, UnoccludedLightMatchesLambertsClosedForm) {
    ShadowScene scene(false);
    const std::vector<AreaLight> lights = findAreaLights(scene.registry, Aabb{});
    ASSERT_EQ(lights.size(), 1u);
    EXPECT_NEAR(lights[0].area, 1.f, 1e-6f);
    const glm::dvec3 corners[4] = {
        {-0.5, 1.5, -0.5}, {0.5, 1.5, -0.5}, {0.5, 1.5, 0.5}, {-0.5, 1.5, 0.5}};
    const std::uint32_t samples = 64;
    for (const glm::vec3 x :
         {glm::vec3(0.f), glm::vec3(0.6f, 0.f, 0.2f), glm::vec3(2.f, 0.f, -1.f)}) {
        const double exact = lambertPolygon(glm::dvec3(x), {0.0, 1.0, 0.0}, corners);
        const Reference ref = reference(x, 400, false);
        EXPECT_NEAR(ref.irradiance, exact, 1e-3 * exact); // the quadrature itself
        const LightSample s = shadeAreaLight(scene.registry.ctx().get<RayScene>(), lights[0], 0, x,
                                             {0.f, 1.f, 0.f}, samples, 1, 17);
        const double se = std::sqrt(ref.sampleVariance / samples);
        EXPECT_NEAR(s.irradiance.x, exact, 4.0 * se + 1e-5 * exact) << x.x;
        EXPECT_FLOAT_EQ(s.visibility, 1.f);
    }
}

TEST(PointCacheShading, SoftShadowBehindABlockerMatchesTheReference) {
    ShadowScene scene;
    const std::vector<AreaLight> lights = findAreaLights(scene.registry, Aabb{});
    ASSERT_EQ(lights.size(), 1u);
    const std::uint32_t samples = 64;
    int penumbra = 0;
    // Umbra, penumbra and lit points along a line and off it.
    for (const glm::vec3 x :
         {glm::vec3(0.f), glm::vec3(0.3f, 0.f, 0.f), glm::vec3(0.45f, 0.f, 0.1f),
          glm::vec3(0.6f, 0.f, 0.f), glm::vec3(0.5f, 0.f, 0.5f), glm::vec3(0.8f, 0.f, -0.3f),
          glm::vec3(2.f, 0.f, 0.f)}) {
        const Reference ref = reference(x, 400, true);
        const LightSample s = shadeAreaLight(scene.registry.ctx().get<RayScene>(), lights[0], 0, x,
                                             {0.f, 1.f, 0.f}, samples, 1, 99);
        const double se = std::sqrt(ref.sampleVariance / samples);
        EXPECT_NEAR(s.irradiance.x, ref.irradiance, 4.0 * se + ref.quadratureBound)
            << "at " << x.x << ", " << x.z;
        EXPECT_GE(s.visibility, 0.f);
        EXPECT_LE(s.visibility, 1.f);
        const double open = reference(x, 400, false).irradiance;
        if (ref.irradiance > 0.05 * open && ref.irradiance < 0.95 * open) ++penumbra;
    }
    EXPECT_GE(penumbra, 2); // the test does look at the soft edge
}

TEST(PointCacheShading, StoredPointShadowsMatchTheReference) {
    ShadowScene scene;
    PointCacheSettings settings;
    settings.rMin = 0.06f;
    settings.rMax = 0.25f;
    settings.shadowSamples = 64;
    settings.particleCount = 512;
    settings.stopAfterRejections = 2000;
    PointCacheSystem system(settings);
    system.build(scene.registry);
    const PointCache& cache = scene.registry.ctx().get<PointCache>();
    std::size_t checked = 0, shadowed = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p];
        if (!(std::abs(x.y) < 1e-4f && cache.normal[p].y > 0.99f && std::abs(x.x) < 1.2f &&
              std::abs(x.z) < 1.2f))
            continue;
        const Reference ref = reference(x, 160, true);
        const double se = std::sqrt(ref.sampleVariance / settings.shadowSamples);
        // 5 standard errors: a few hundred points are compared.
        EXPECT_NEAR(cache.direct[p].x, ref.irradiance, 5.0 * se + ref.quadratureBound) << p;
        ++checked;
        if (cache.visibility[p] < 0.5f) ++shadowed;
    }
    EXPECT_GT(checked, 50u);
    EXPECT_GT(shadowed, 5u);
}

// ---- the cache file --------------------------------------------------------------------------

std::filesystem::path scratch(const char* name) {
    const auto dir =
        std::filesystem::temp_directory_path() / ("qgi_point_cache_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    return dir / name;
}

PointCacheSettings smallSettings(const std::string& file) {
    PointCacheSettings s;
    s.rMin = 0.1f;
    s.rMax = 0.3f;
    s.particleCount = 256;
    s.stopAfterRejections = 500;
    s.cacheFile = file;
    return s;
}

TEST(PointCacheFile, AnUnwritableFileStillGivesTheBuiltCache) {
    // The file's folder is a regular file: no one, root included, can write there.
    const std::filesystem::path blocker = scratch("not_a_folder");
    { std::ofstream(blocker) << 'x'; }
    ShadowScene scene;
    PointCacheSystem system(smallSettings((blocker / "cache.qpc").string()));
    EXPECT_NO_THROW(system.build(scene.registry));
    EXPECT_FALSE(system.loadedFromFile());
    EXPECT_GT(scene.registry.ctx().get<PointCache>().size(), 20u);
    std::filesystem::remove(blocker);
}

TEST(PointCacheFile, SomebodysFileAtThePathIsNeverOverwritten) {
    // Not a cache: the build works without a file and leaves it as it was.
    const std::filesystem::path notes = scratch("notes.txt");
    { std::ofstream(notes) << "my notes"; }
    ShadowScene scene;
    PointCacheSystem system(smallSettings(notes.string()));
    EXPECT_NO_THROW(system.build(scene.registry));
    EXPECT_FALSE(system.loadedFromFile());
    std::ifstream in(notes);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(text, "my notes");
    EXPECT_THROW(writePointCacheFile(notes.string(), 1, scene.registry.ctx().get<PointCache>()),
                 Error);
    std::filesystem::remove(notes);
}

TEST(PointCacheFile, RoundTripsAndIsLoadedOnTheNextStart) {
    const std::string file = scratch("roundtrip.qpc").string();
    std::filesystem::remove(file);
    ShadowScene scene;
    PointCacheSystem first(smallSettings(file));
    first.build(scene.registry);
    EXPECT_FALSE(first.loadedFromFile());
    ASSERT_TRUE(std::filesystem::exists(file));
    const PointCache built = scene.registry.ctx().get<PointCache>();
    ASSERT_GT(built.size(), 20u);

    PointCacheSystem second(smallSettings(file));
    second.build(scene.registry);
    EXPECT_TRUE(second.loadedFromFile());
    const PointCache& loaded = scene.registry.ctx().get<PointCache>();
    ASSERT_EQ(loaded.size(), built.size());
    const auto same = [](const auto& a, const auto& b) {
        return a.size() == b.size() &&
               std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0;
    };
    EXPECT_TRUE(same(loaded.position, built.position));
    EXPECT_TRUE(same(loaded.normal, built.normal));
    EXPECT_TRUE(same(loaded.radius, built.radius));
    EXPECT_TRUE(same(loaded.ao, built.ao));
    EXPECT_TRUE(same(loaded.direct, built.direct));
    EXPECT_TRUE(same(loaded.visibility, built.visibility));
    EXPECT_TRUE(same(loaded.dart, built.dart));
    std::filesystem::remove_all(std::filesystem::path(file).parent_path());
}

TEST(PointCacheFile, CorruptTruncatedAndStaleFilesAreRejectedAndRebuilt) {
    const std::string file = scratch("corrupt.qpc").string();
    std::filesystem::remove(file);
    ShadowScene scene;
    PointCacheSystem first(smallSettings(file));
    first.build(scene.registry);
    const PointCache built = scene.registry.ctx().get<PointCache>();
    const std::uint64_t key = pointCacheKey(scene.registry, built.settings);
    const auto size = std::filesystem::file_size(file);
    const auto expectError = [&](const char* phrase) {
        PointCache into;
        try {
            readPointCacheFile(file, key, into);
            ADD_FAILURE() << "no error; expected '" << phrase << "'";
        } catch (const Error& error) {
            EXPECT_NE(std::string(error.what()).find(phrase), std::string::npos) << error.what();
        }
        EXPECT_EQ(into.size(), 0u); // nothing half-read
    };
    // One flipped byte in the middle of the data.
    {
        std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
        f.seekg(std::streamoff(size / 2));
        char c = 0;
        f.read(&c, 1);
        c = char(c ^ 0x5a);
        f.seekp(std::streamoff(size / 2));
        f.write(&c, 1);
    }
    expectError("corrupt");
    PointCacheSystem again(smallSettings(file));
    again.build(scene.registry); // reports, rebuilds, rewrites
    EXPECT_FALSE(again.loadedFromFile());
    EXPECT_EQ(std::memcmp(scene.registry.ctx().get<PointCache>().direct.data(), built.direct.data(),
                          built.size() * sizeof(glm::vec3)),
              0);
    PointCache reread;
    EXPECT_NO_THROW(readPointCacheFile(file, key, reread));

    std::filesystem::resize_file(file, size - 7);
    expectError("truncated");
    std::filesystem::resize_file(file, 10);
    expectError("truncated");
    {
        std::ofstream f(file, std::ios::binary | std::ios::trunc);
        f << "not a cache file at all, just some text that is long enough";
    }
    expectError("bad magic");

    // Stale: the same file read with the key of other settings or another scene.
    again.build(scene.registry);
    PointCacheSettings other = built.settings;
    other.seed = 99;
    PointCache into;
    EXPECT_THROW(readPointCacheFile(file, pointCacheKey(scene.registry, other), into), Error);
    test::addPointLight(scene.registry, {1.f, 1.f, 1.f}, 1.f);
    EXPECT_NE(pointCacheKey(scene.registry, built.settings), key);
    PointCacheSystem stale(smallSettings(file));
    stale.build(scene.registry);
    EXPECT_FALSE(stale.loadedFromFile());
    EXPECT_THROW(readPointCacheFile("/nonexistent/dir/x.qpc", key, into), Error);
    std::filesystem::remove_all(std::filesystem::path(file).parent_path());
}

// ---- per-frame update ---------------------------------------------------------------------------

TEST(PointCacheUpdate, BudgetIsRespectedFarPointsStayAndTheQueueDrainsToFreshValues) {
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true);
    // The mobile blocker starts low and to the side: its shadow falls on part of the floor.
    const glm::vec3 blockerOld(2.f, 0.3f, 0.f);
    scene.registry.patch<WorldTransform>(scene.blocker).matrix = translation(blockerOld);
    RayScene& rays = scene.registry.ctx().get<RayScene>();
    rays.syncMoved(scene.registry);
    scene.registry.clearChanges();
    PointCacheSettings settings;
    settings.rMin = 0.06f;
    settings.rMax = 0.25f;
    settings.particleCount = 512;
    settings.stopAfterRejections = 2000;
    settings.updateBudget = 40;
    PointCacheSystem system(settings);
    system.build(scene.registry);
    PointCache& cache = scene.registry.ctx().get<PointCache>();
    system.update(scene.registry, FrameContext{});
    scene.registry.clearChanges();
    const PointCache before = cache;

    // Identical frames change nothing.
    system.update(scene.registry, FrameContext{1});
    EXPECT_EQ(system.lastFrame().refreshed, 0u);
    EXPECT_EQ(
        std::memcmp(cache.direct.data(), before.direct.data(), cache.size() * sizeof(glm::vec3)),
        0);

    // Move the blocker 0.4 m along x.
    const glm::vec3 offset(0.4f, 0.f, 0.f);
    scene.registry.patch<WorldTransform>(scene.blocker).matrix = translation(blockerOld + offset);
    rays.syncMoved(scene.registry);
    system.update(scene.registry, FrameContext{2});
    scene.registry.clearChanges();
    const auto stats = system.lastFrame();
    // The queue is exactly what testing every point would give (the system culls by blocks and
    // cells of its grid first): the points with a light above their horizon whose segment to
    // it passes within (blocker's bounding sphere + light's) of the blocker, old or new pose.
    {
        Aabb box;
        for (const glm::vec3& v : scene.registry.get<Mesh>(scene.blocker).positions)
            box.extend(v);
        const float radius = 0.5f * glm::length(box.extent());
        std::size_t expected = 0;
        for (std::size_t p = 0; p < cache.size(); ++p) {
            const glm::vec3 x = cache.position[p];
            bool hit = false;
            for (const AreaLight& l : system.areaLights()) {
                if (glm::dot(cache.normal[p], l.centre - x) < -l.boundRadius) continue;
                for (const glm::vec3 at : {blockerOld, blockerOld + offset}) {
                    const glm::vec3 c = at + box.center(), ab = l.centre - x;
                    const float t = std::clamp(glm::dot(c - x, ab) / glm::dot(ab, ab), 0.f, 1.f);
                    hit = hit || glm::length(x + t * ab - c) < radius + l.boundRadius;
                }
            }
            expected += hit ? 1 : 0;
        }
        EXPECT_EQ(stats.queued, expected);
        EXPECT_LT(stats.shadowCandidates, cache.size()); // the culling culled something
        EXPECT_GE(stats.shadowCandidates, stats.queued);
    }
    ASSERT_GT(stats.queued, settings.updateBudget);
    EXPECT_EQ(stats.refreshed, settings.updateBudget);
    EXPECT_EQ(stats.pending, stats.queued - settings.updateBudget);

    // Points whose segment to the light passes nowhere near the blocker (old or new) kept their
    // value bit for bit; the refreshed ones are the nearest to the blocker.
    const glm::vec3 blockerNew = blockerOld + offset;
    const float reach = std::sqrt(2.f) * kBlockerHalf + std::sqrt(2.f) * kLightHalf;
    std::size_t far = 0, changed = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p];
        const glm::vec3 light(0.f, kLightY, 0.f);
        const auto dist = [&](const glm::vec3& c) {
            const glm::vec3 ab = light - x;
            const float t = std::clamp(glm::dot(c - x, ab) / glm::dot(ab, ab), 0.f, 1.f);
            return glm::length(x + t * ab - c);
        };
        const bool same = std::memcmp(&cache.direct[p], &before.direct[p], sizeof(glm::vec3)) == 0;
        if (dist(blockerOld) > 1.01f * reach && dist(blockerNew) > 1.01f * reach) {
            ++far;
            EXPECT_TRUE(same) << p;
        }
        changed += same ? 0 : 1;
    }
    EXPECT_GT(far, 50u);
    EXPECT_LE(changed, settings.updateBudget);

    // Drain the queue: every point then holds exactly the value a fresh shading gives.
    for (std::uint64_t f = 3; f < 200 && system.lastFrame().pending > 0; ++f) {
        system.update(scene.registry, FrameContext{f});
        EXPECT_LE(system.lastFrame().refreshed, settings.updateBudget);
    }
    EXPECT_EQ(system.lastFrame().pending, 0u);
    const auto& light = system.areaLights()[0];
    std::size_t mismatches = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const LightSample s =
            shadeAreaLight(rays, light, 0, cache.position[p], cache.normal[p],
                           cache.settings.shadowSamples, cache.settings.seed, cache.dart[p]);
        mismatches += std::memcmp(&s.irradiance, &cache.direct[p], sizeof(glm::vec3)) != 0;
    }
    EXPECT_EQ(mismatches, 0u);
    // Shading updates never touch the point set itself.
    ASSERT_EQ(cache.size(), before.size());
    EXPECT_EQ(std::memcmp(cache.position.data(), before.position.data(),
                          cache.size() * sizeof(glm::vec3)),
              0);
    EXPECT_EQ(cache.radius, before.radius);
    EXPECT_EQ(cache.ao, before.ao);
}

TEST(PointCacheUpdate, ABlockerTakenOutAndPutBackDrainsToFreshShadows) {
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true);
    PointCacheSettings settings;
    settings.rMin = 0.06f;
    settings.rMax = 0.25f;
    settings.particleCount = 512;
    settings.stopAfterRejections = 2000;
    settings.updateBudget = 40;
    PointCacheSystem system(settings);
    system.build(scene.registry);
    const PointCache& cache = scene.registry.ctx().get<PointCache>();
    system.update(scene.registry, FrameContext{});
    scene.registry.clearChanges();
    const PointCache before = cache;
    RayScene& rays = scene.registry.ctx().get<RayScene>();

    // Each switch queues the points it may shadow; once drained, every point holds what a
    // fresh shading of the scene as it is gives: the light unblocked, then the first values.
    std::uint64_t frame = 1;
    for (const bool active : {false, true}) {
        scene.registry.patch<MobileMesh>(scene.blocker).active = active;
        rays.syncMoved(scene.registry);
        system.update(scene.registry, FrameContext{frame++});
        scene.registry.clearChanges();
        EXPECT_GT(system.lastFrame().queued, settings.updateBudget);
        while (system.lastFrame().pending > 0 && frame < 400)
            system.update(scene.registry, FrameContext{frame++});
        ASSERT_EQ(system.lastFrame().pending, 0u);
        std::size_t mismatches = 0, unchanged = 0;
        for (std::size_t p = 0; p < cache.size(); ++p) {
            const LightSample s =
                shadeAreaLight(rays, system.areaLights()[0], 0, cache.position[p], cache.normal[p],
                               cache.settings.shadowSamples, cache.settings.seed, cache.dart[p]);
            mismatches += std::memcmp(&s.irradiance, &cache.direct[p], sizeof(glm::vec3)) != 0;
            unchanged += cache.direct[p] == before.direct[p] ? 1 : 0;
        }
        EXPECT_EQ(mismatches, 0u) << (active ? "put back" : "taken out");
        if (active)
            EXPECT_EQ(unchanged, cache.size());
        else
            EXPECT_GT(cache.size() - unchanged, 10u); // its shadow went
    }
}

TEST(PointCacheUpdate, IndirectFollowsThePhotonDeltaExactly) {
    Registry registry;
    const test::Room room = test::buildRoom(registry, {-1.f, -1.25f, 0.5f}, {0.5f, -1.3f, -1.f});
    test::buildRayScene(registry);
    PhotonSettings photons;
    photons.photonCount = 20'000;
    PhotonUpdateSystem photonSystem(photons);
    PointCacheSettings settings;
    settings.rMin = 0.08f;
    settings.rMax = 0.3f;
    settings.detpRadius = 0.3f; // discs small enough that some miss every delta segment
    settings.particleCount = 512;
    settings.stopAfterRejections = 1000;
    PointCacheSystem system(settings);
    system.build(registry);
    test::firstUpdate(registry, photonSystem);
    system.update(registry, FrameContext{});
    EXPECT_TRUE(system.lastFrame().fullIndirect);
    PointCache& cache = registry.ctx().get<PointCache>();
    double total = 0.0;
    for (const glm::vec3& e : cache.indirect)
        total += e.x;
    EXPECT_GT(total, 0.0);
    // DETP written out: every stored segment after a bounce that crosses a point's disc
    // (crossesDisc, the rule DiscIndex is checked against), over pi r^2.
    {
        const PhotonStore& store = registry.ctx().get<PhotonStore>();
        const float r = cache.settings.detpRadius;
        const auto& s = store.segments;
        for (std::size_t p = 0; p < cache.size(); p += 7) {
            glm::dvec3 sum(0.0);
            for (const PhotonPath& path : store.paths)
                for (std::uint32_t k = 0; k < path.count; ++k) {
                    const std::size_t i = path.first + k;
                    if (s.bounce[i] == 0) continue;
                    if (crossesDisc(s.origin[i], s.direction[i], s.length[i], cache.position[p],
                                    cache.normal[p], r))
                        sum += glm::dvec3(s.power[i]);
                }
            const glm::dvec3 expected = sum / (glm::pi<double>() * double(r) * double(r));
            // Both sum in double; the published float differs by its rounding (2^-24
            // relative), where one missed crossing would change it by a whole photon's power.
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(cache.indirect[p][c], expected[c], 1.2e-7 * expected[c] + 1e-9) << p;
        }
    }
    const std::vector<glm::vec3> before = cache.indirect;

    // Move the cube; the incremental value must equal a full re-estimate over the new set.
    test::moveAndUpdate(registry, photonSystem, room.cube, translation({-0.6f, -1.25f, 0.3f}), 1);
    system.update(registry, FrameContext{1});
    EXPECT_FALSE(system.lastFrame().fullIndirect);
    EXPECT_GT(system.lastFrame().deltaSegments, 0u);
    EXPECT_LT(system.lastFrame().indirectWritten, cache.size());
    const std::vector<glm::vec3> incremental = cache.indirect;
    std::size_t untouched = 0;
    for (std::size_t p = 0; p < cache.size(); ++p)
        untouched += std::memcmp(&incremental[p], &before[p], sizeof(glm::vec3)) == 0;
    EXPECT_GE(untouched, cache.size() - system.lastFrame().indirectWritten);

    registry.ctx().get<PhotonDelta>().full = true;
    system.update(registry, FrameContext{2});
    EXPECT_TRUE(system.lastFrame().fullIndirect);
    // Exactly up to the final rounding: the double sums differ by about 2^-53 of their largest
    // partial sum, far below the float's half ulp, so the floats agree to one ulp (2^-23).
    for (std::size_t p = 0; p < cache.size(); ++p)
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(incremental[p][c], cache.indirect[p][c],
                        1.2e-7f * cache.indirect[p][c] + 1e-9f)
                << p;
}

TEST(PointCacheSchedule, RunsAsTheTimedPointCachePhase) {
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true);
    FrameSettings settings;
    settings.photons->photonCount = 5000;
    settings.irradiance.discRadius = 0.2f;
    settings.render.reset();
    settings.pointCache = PointCacheSettings{};
    settings.pointCache->rMin = 0.1f;
    settings.pointCache->rMax = 0.3f;
    settings.pointCache->stopAfterRejections = 500;
    settings.pointCache->particleCount = 512;
    settings.pointCache->updateBudget = 7;
    FrameSchedule frame(scene.registry, settings);
    ASSERT_NE(frame.pointCache(), nullptr);
    bool listed = false;
    for (const Schedule::Entry* entry : frame.schedule().entries())
        listed |= entry->name == "point.cache";
    EXPECT_TRUE(listed);
    FrameProfiler& profiler = scene.registry.ctx().get<FrameProfiler>();
    for (std::uint64_t f = 0; f < 3; ++f) { // Schedule::run opens and closes the profiler frame
        if (f == 2)                         // the blocker moves: the budget bounds the refresh
            scene.registry.patch<WorldTransform>(scene.blocker).matrix =
                translation({0.3f, kBlockerY, 0.f});
        frame.run(scene.registry, FrameContext{f});
    }
    EXPECT_EQ(frame.pointCache()->lastFrame().refreshed, 7u);
    EXPECT_GT(frame.pointCache()->lastFrame().pending, 0u);
    bool timed = false;
    for (const ProfileStats& stats : profiler.statistics())
        timed |= stats.name == "point.cache" && stats.count == 3;
    EXPECT_TRUE(timed);
    EXPECT_GT(scene.registry.ctx().get<PointCache>().size(), 20u);
}

} // namespace
} // namespace qgi
