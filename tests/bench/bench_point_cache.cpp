// Cost of the point cache (seed 003) on the atrium:
//  - Build: the whole bake at the scene's default settings (light particles, dart throwing
//    with AO, AO and soft shadows of the 12 ceiling panels for every point, query grid, DETP
//    disc index), once; counters: points, darts, AO calls;
//  - Query: CPU blends at random positions on the points' own surfaces (jittered within
//    their spacing radius), items = queries;
//  - Coverage: the share of the shaded surfaces' area no point reaches, by uniform samples;
//  - UpdateMovingMobile: the `point.cache` frame while the crate in the court moves 5 cm per
//    frame (the photon update runs untimed before it), at the default budget; counters: delta
//    segments, points queued and refreshed, and of the refreshed points' (point, light)
//    pairs those traced with shadow rays and those replayed from their recorded samples;
//  - UpdateWalkthrough: the same frame while the scene's own paths move its mobiles, as in
//    the demo's walkthrough (the first 4 s at 30 frames a second), same counters.
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointCacheShaded.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/animation/AnimationSystem.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointCacheSystem.h"
#include "systems/point_cache/PointShading.h"
#include "systems/transform/TransformSystem.h"

#include <benchmark/benchmark.h>
#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>

namespace qgi {
namespace {

struct Atrium {
    Registry registry;
    std::unique_ptr<PointCacheSystem> cache;
    std::unique_ptr<PhotonUpdateSystem> photons;
    Entity crate;
    glm::mat4 rest{1.f};
    std::uint64_t frame = 0;

    Atrium() {
        setLogLevel(LogLevel::Warning);
        buildBuiltinScene(registry, "atrium", SceneOptions{});
        registry.ctx().emplace<RayScene>().build(registry);
        registry.view<const MobileMesh, const Name>().each(
            [&](Entity e, const MobileMesh&, const Name& name) {
                if (name.value.find("crate") != std::string::npos && !crate) crate = e;
            });
        rest = registry.get<WorldTransform>(crate).matrix;
    }
    /// The cache at its default settings, built the first time it is asked for.
    const PointCache& builtCache() {
        if (!cache) {
            cache = std::make_unique<PointCacheSystem>(PointCacheSettings{});
            cache->build(registry);
        }
        return registry.ctx().get<PointCache>();
    }
};

Atrium& atrium() {
    static Atrium world;
    return world;
}

void BM_Build(benchmark::State& state) {
    Atrium& w = atrium();
    for (auto _ : state) {
        w.cache = std::make_unique<PointCacheSystem>(PointCacheSettings{});
        w.cache->build(w.registry);
    }
    const PointSetStats& s = w.cache->buildStats();
    state.counters["points"] = double(s.points);
    state.counters["darts"] = double(s.darts);
    state.counters["aoCalls"] = double(s.aoCalls);
    state.counters["sources"] = double(s.sources);
    // 0: consecutive rejections, 1: dart budget, 2: point budget (PointSetStop).
    state.counters["stop"] = double(int(s.stop));
    state.counters["gridEntries"] = double(w.registry.ctx().get<PointCache>().grid.entryCount());
}
BENCHMARK(BM_Build)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

void BM_Query(benchmark::State& state) {
    Atrium& w = atrium();
    const PointCache& cache = w.builtCache();
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    std::vector<glm::vec3> xs, ns;
    for (int i = 0; i < 65536; ++i) {
        const std::uint32_t p = std::uint32_t(rng() % cache.size());
        const glm::vec3 n = cache.normal[p];
        glm::vec3 t = glm::cross(n, glm::vec3(0.577f, 0.577f, 0.577f));
        t = glm::length(t) > 1e-3f ? glm::normalize(t) : glm::vec3(1.f, 0.f, 0.f);
        const glm::vec3 b = glm::cross(n, t);
        xs.push_back(cache.position[p] + cache.radius[p] * (u(rng) * t + u(rng) * b));
        ns.push_back(n);
    }
    std::size_t i = 0, found = 0, empty = 0;
    for (auto _ : state) {
        const PointCacheSample s = cache.sample(xs[i], ns[i]);
        found += s.count;
        empty += s.count == 0;
        benchmark::DoNotOptimize(s);
        i = (i + 1) & 65535;
    }
    state.SetItemsProcessed(std::int64_t(state.iterations()));
    state.counters["pointsPerQuery"] = double(found) / double(state.iterations());
    state.counters["emptyFraction"] = double(empty) / double(state.iterations());
}
BENCHMARK(BM_Query);

/// Coverage: positions uniform by area over every surface the cache shades (not only near its
/// points), each queried once; the share that no point reaches is where the shader falls back
/// to per-vertex irradiance (a set stopped by its dart budget is not saturated).
void BM_Coverage(benchmark::State& state) {
    Atrium& w = atrium();
    const PointCache& cache = w.builtCache();
    struct Triangle {
        glm::vec3 a, e1, e2, n;
    };
    std::vector<Triangle> triangles;
    std::vector<double> cdf;
    double area = 0.0;
    w.registry.view<const PointCacheShaded, const Mesh, const WorldTransform>().each(
        [&](Entity, const PointCacheShaded&, const Mesh& mesh, const WorldTransform& world) {
            for (std::size_t i = 0; i + 2 < mesh.indices.size(); i += 3) {
                glm::vec3 v[3];
                for (int k = 0; k < 3; ++k)
                    v[k] = glm::vec3(world.matrix *
                                     glm::vec4(mesh.positions[mesh.indices[i + k]], 1.f));
                const glm::vec3 c = glm::cross(v[1] - v[0], v[2] - v[0]);
                if (!(glm::length(c) > 0.f)) continue;
                triangles.push_back({v[0], v[1] - v[0], v[2] - v[0], glm::normalize(c)});
                area += 0.5 * double(glm::length(c));
                cdf.push_back(area);
            }
        });
    std::mt19937 rng(9);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    constexpr int kSamples = 200000;
    // Every 50th sample also gets the ceiling panels' direct light (16 shadow rays each): how
    // much of it falls where no point reaches.
    const RayScene& rays = w.registry.ctx().get<RayScene>();
    const std::vector<AreaLight>& lights = w.cache->areaLights();
    std::size_t empty = 0;
    double directAll = 0.0, directEmpty = 0.0;
    for (auto _ : state) {
        empty = 0;
        for (int k = 0; k < kSamples; ++k) {
            const auto it = std::lower_bound(cdf.begin(), cdf.end(), u(rng) * area);
            const Triangle& t = triangles[std::size_t(it - cdf.begin())];
            double a = u(rng), b = u(rng);
            if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
            const glm::vec3 x = t.a + float(a) * t.e1 + float(b) * t.e2;
            const bool none = cache.sample(x, t.n).count == 0;
            empty += none;
            if (k % 50 != 0) continue;
            double e = 0.0;
            for (std::uint32_t l = 0; l < lights.size(); ++l) {
                const glm::vec3 lit =
                    shadeAreaLight(rays, lights[l], l, x, t.n, 16, 1, std::uint32_t(k)).irradiance;
                e += double(lit.x + lit.y + lit.z);
            }
            directAll += e;
            if (none) directEmpty += e;
        }
    }
    state.counters["shadedArea"] = area;
    state.counters["emptyFraction"] = double(empty) / kSamples;
    // Binomial standard error of that fraction.
    const double p = double(empty) / kSamples;
    state.counters["emptyFractionSE"] = std::sqrt(p * (1.0 - p) / kSamples);
    state.counters["emptyShareOfDirect"] = directAll > 0.0 ? directEmpty / directAll : 0.0;
    state.counters["directSampled"] = directAll; // sum of RGB irradiance over the subsample
}
BENCHMARK(BM_Coverage)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

/// The per-frame counters of the update benchmarks, averaged over the timed frames.
struct FrameTotals {
    double segments = 0, crossings = 0, queued = 0, refreshed = 0, candidates = 0, indirectMs = 0,
           queueMs = 0, refreshMs = 0, traced = 0, replayed = 0, frames = 0;

    void add(const PointCacheSystem::FrameStats& s) {
        segments += double(s.deltaSegments);
        crossings += double(s.discCrossings);
        queued += double(s.queued);
        refreshed += double(s.refreshed);
        traced += double(s.lightsTraced);
        replayed += double(s.lightsReplayed);
        candidates += double(s.shadowCandidates);
        indirectMs += s.indirectMs;
        queueMs += s.queueMs;
        refreshMs += s.refreshMs;
        ++frames;
    }
    void report(benchmark::State& state) const {
        const double n = std::max(frames, 1.0);
        state.counters["deltaSegments"] = segments / n;
        state.counters["discCrossings"] = crossings / n;
        state.counters["queued"] = queued / n;
        state.counters["refreshed"] = refreshed / n;
        state.counters["lightsTraced"] = traced / n;
        state.counters["lightsReplayed"] = replayed / n;
        state.counters["shadowCandidates"] = candidates / n;
        state.counters["indirect_ms"] = indirectMs / n;
        state.counters["queue_ms"] = queueMs / n;
        state.counters["refresh_ms"] = refreshMs / n;
    }
};

/// The photon update, untimed, then the timed point-cache frame.
void timedFrame(benchmark::State& state, Atrium& w, FrameTotals& totals, double time = 0.0) {
    w.registry.ctx().get<RayScene>().syncMoved(w.registry);
    w.photons->update(w.registry, FrameContext{w.frame, time, 0.f, 0});
    state.ResumeTiming();
    w.cache->update(w.registry, FrameContext{w.frame++, time, 0.f, 0});
    state.PauseTiming();
    w.registry.clearChanges();
    totals.add(w.cache->lastFrame());
}

void startPhotons(Atrium& w) {
    w.builtCache();
    if (w.photons) return;
    w.photons = std::make_unique<PhotonUpdateSystem>(PhotonSettings{});
    w.photons->update(w.registry, FrameContext{w.frame, 0.0, 0.f, 0});
    w.cache->update(w.registry, FrameContext{w.frame++, 0.0, 0.f, 0});
    w.registry.clearChanges();
}

void BM_UpdateMovingMobile(benchmark::State& state) {
    Atrium& w = atrium();
    startPhotons(w);
    FrameTotals totals;
    for (auto _ : state) {
        state.PauseTiming();
        const float x = 0.05f * float(w.frame % 40 < 20 ? w.frame % 20 : 20 - w.frame % 20);
        w.registry.patch<WorldTransform>(w.crate).matrix =
            glm::translate(glm::mat4(1.f), glm::vec3(x, 0.f, 0.f)) * w.rest;
        timedFrame(state, w, totals);
        state.ResumeTiming();
    }
    totals.report(state);
}
BENCHMARK(BM_UpdateMovingMobile)->Unit(benchmark::kMillisecond)->Iterations(40);

/// The demo's walkthrough: the scene's own paths move its mobiles (the animation and
/// transform systems run untimed), 30 frames a second from the start.
void BM_UpdateWalkthrough(benchmark::State& state) {
    Atrium& w = atrium();
    startPhotons(w);
    AnimationSystem animation;
    TransformSystem transforms;
    FrameTotals totals;
    std::uint64_t step = 0;
    for (auto _ : state) {
        state.PauseTiming();
        const double time = double(step++) / 30.0;
        animation.update(w.registry, FrameContext{w.frame, time, 1.f / 30.f, 0});
        transforms.update(w.registry, FrameContext{w.frame, time, 1.f / 30.f, 0});
        timedFrame(state, w, totals, time);
        state.ResumeTiming();
    }
    totals.report(state);
}
BENCHMARK(BM_UpdateWalkthrough)->Unit(benchmark::kMillisecond)->Iterations(120);

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
