// Cost of the point cache (seed 003) on the atrium:
//  - Build: the whole bake at the scene's default settings (light particles, dart throwing
//    with AO, AO and soft shadows of the 12 ceiling panels for every point, query grid, DETP
//    disc index), once; counters: points, darts, AO calls;
//  - Query: CPU blends at random positions on the points' own surfaces (jittered within
//    their spacing radius), items = queries;
//  - UpdateMovingMobile: the `point.cache` frame while the crate in the court moves 5 cm per
//    frame (the photon update runs untimed before it), at the default budget; counters: delta
//    segments, points queued and refreshed.
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointCacheSystem.h"

#include <benchmark/benchmark.h>
#include <glm/gtc/matrix_transform.hpp>

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
    if (!w.cache) {
        w.cache = std::make_unique<PointCacheSystem>(PointCacheSettings{});
        w.cache->build(w.registry);
    }
    const PointCache& cache = w.registry.ctx().get<PointCache>();
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

void BM_UpdateMovingMobile(benchmark::State& state) {
    Atrium& w = atrium();
    if (!w.cache) {
        w.cache = std::make_unique<PointCacheSystem>(PointCacheSettings{});
        w.cache->build(w.registry);
    }
    if (!w.photons) {
        w.photons = std::make_unique<PhotonUpdateSystem>(PhotonSettings{});
        w.photons->update(w.registry, FrameContext{w.frame, 0.0, 0.f, 0});
        w.cache->update(w.registry, FrameContext{w.frame++, 0.0, 0.f, 0});
        w.registry.clearChanges();
    }
    double segments = 0, queued = 0, refreshed = 0, candidates = 0, indirectMs = 0, queueMs = 0,
           refreshMs = 0;
    for (auto _ : state) {
        state.PauseTiming();
        const float x = 0.05f * float(w.frame % 40 < 20 ? w.frame % 20 : 20 - w.frame % 20);
        w.registry.patch<WorldTransform>(w.crate).matrix =
            glm::translate(glm::mat4(1.f), glm::vec3(x, 0.f, 0.f)) * w.rest;
        w.registry.ctx().get<RayScene>().syncMoved(w.registry);
        w.photons->update(w.registry, FrameContext{w.frame, 0.0, 0.f, 0});
        state.ResumeTiming();
        w.cache->update(w.registry, FrameContext{w.frame++, 0.0, 0.f, 0});
        state.PauseTiming();
        w.registry.clearChanges();
        const auto& s = w.cache->lastFrame();
        segments += double(s.deltaSegments);
        queued += double(s.queued);
        refreshed += double(s.refreshed);
        candidates += double(s.shadowCandidates);
        indirectMs += s.indirectMs;
        queueMs += s.queueMs;
        refreshMs += s.refreshMs;
        state.ResumeTiming();
    }
    const double n = double(state.iterations());
    state.counters["deltaSegments"] = segments / n;
    state.counters["queued"] = queued / n;
    state.counters["refreshed"] = refreshed / n;
    state.counters["shadowCandidates"] = candidates / n;
    state.counters["indirect_ms"] = indirectMs / n;
    state.counters["queue_ms"] = queueMs / n;
    state.counters["refresh_ms"] = refreshMs / n;
}
BENCHMARK(BM_UpdateMovingMobile)->Unit(benchmark::kMillisecond)->Iterations(40);

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
