// Embree throughput of the RayScene for incoherent rays (photon paths): random origins inside the
// scene bounds, uniform random directions, fixed seed. Single-ray and 8-wide batched queries on
// 1 and 2 threads (oneTBB arenas, argument = threads) on every built-in scene, the cost of moving
// one mobile (syncMoved), the full build, and the price of the robust mode (Intersect8Fast:
// robust off, leaky at edges), and loading each scene (SceneLoad: mesh processing included).
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneInfo.h"

#include <benchmark/benchmark.h>
#include <glm/gtc/matrix_transform.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace qgi {
namespace {

constexpr std::size_t kRayCount = std::size_t(1) << 16;
constexpr std::size_t kGrain = 1024; // rays per task: enough to hide the scheduling cost
constexpr std::uint32_t kSeed = 1234;

/// A built-in scene with its ray scene and a fixed set of random rays, built once per process.
struct BenchWorld {
    Registry registry;
    RayScene scene;
    std::vector<Ray> rays;

    BenchWorld(const std::string& name, const RaySceneSettings& settings) : scene(settings) {
        buildBuiltinScene(registry, name, SceneOptions{});
        scene.build(registry);
        const Aabb bounds = registry.ctx().get<SceneInfo>().bounds;
        std::mt19937 rng(kSeed);
        std::uniform_real_distribution<float> unit(0.f, 1.f);
        std::normal_distribution<float> gauss;
        rays.resize(kRayCount);
        for (Ray& ray : rays) {
            ray.origin = bounds.min + glm::vec3(unit(rng), unit(rng), unit(rng)) * bounds.extent();
            do
                ray.direction = {gauss(rng), gauss(rng), gauss(rng)};
            while (glm::length(ray.direction) < 1e-6f);
            ray.direction = glm::normalize(ray.direction);
        }
    }
};

BenchWorld& world(const std::string& name, bool robust = true) {
    static std::map<std::pair<std::string, bool>, std::unique_ptr<BenchWorld>> worlds;
    std::unique_ptr<BenchWorld>& slot = worlds[{name, robust}];
    if (!slot) {
        RaySceneSettings settings;
        settings.robust = robust;
        slot = std::make_unique<BenchWorld>(name, settings);
    }
    return *slot;
}

/// Runs `trace(first, last)` over all rays on state.range(0) threads; reports rays/s.
template <typename Trace> void runRays(benchmark::State& state, const BenchWorld& w, Trace trace) {
    tbb::task_arena arena(int(state.range(0)));
    for (auto _ : state) {
        arena.execute([&] {
            tbb::parallel_for(
                tbb::blocked_range<std::size_t>(0, w.rays.size(), kGrain),
                [&](const tbb::blocked_range<std::size_t>& r) { trace(r.begin(), r.end()); });
        });
        benchmark::ClobberMemory();
    }
    state.counters["rays/s"] =
        benchmark::Counter(double(state.iterations() * w.rays.size()), benchmark::Counter::kIsRate);
    state.SetLabel(std::to_string(w.scene.staticTriangleCount()) + " static triangles, " +
                   std::to_string(w.scene.mobileCount()) + " mobiles");
}

void BM_Intersect1(benchmark::State& state, const std::string& name) {
    const BenchWorld& w = world(name);
    std::vector<std::optional<Hit>> hits(w.rays.size());
    runRays(state, w, [&](std::size_t first, std::size_t last) {
        for (std::size_t i = first; i < last; ++i)
            hits[i] = w.scene.intersect(w.rays[i]);
    });
}

void BM_Intersect8(benchmark::State& state, const std::string& name, bool robust) {
    const BenchWorld& w = world(name, robust);
    std::vector<std::optional<Hit>> hits(w.rays.size());
    runRays(state, w, [&](std::size_t first, std::size_t last) {
        w.scene.intersect(std::span(w.rays).subspan(first, last - first),
                          std::span(hits).subspan(first, last - first));
    });
}

void BM_Occluded1(benchmark::State& state, const std::string& name) {
    const BenchWorld& w = world(name);
    std::vector<std::uint8_t> blocked(w.rays.size());
    runRays(state, w, [&](std::size_t first, std::size_t last) {
        for (std::size_t i = first; i < last; ++i)
            blocked[i] = w.scene.occluded(w.rays[i]);
    });
}

void BM_Occluded8(benchmark::State& state, const std::string& name) {
    const BenchWorld& w = world(name);
    std::vector<std::uint8_t> blocked(w.rays.size());
    runRays(state, w, [&](std::size_t first, std::size_t last) {
        w.scene.occluded(std::span(w.rays).subspan(first, last - first),
                         std::span(blocked).subspan(first, last - first));
    });
}

/// One mobile moves per frame: the transform system's patch, then syncMoved (instance
/// transform, instance commit, top-level commit).
void BM_MobileMove(benchmark::State& state, const std::string& name) {
    BenchWorld& w = world(name);
    const auto mobiles = w.registry.view<const MobileMesh>().entities();
    if (mobiles.empty()) {
        state.SkipWithError("the scene has no mobile");
        return;
    }
    const Entity mobile = mobiles.front();
    const glm::mat4 rest = w.registry.get<WorldTransform>(mobile).matrix;
    const glm::mat4 moved = glm::translate(rest, glm::vec3(0.01f, 0.f, 0.f));
    bool away = false;
    for (auto _ : state) {
        away = !away;
        w.registry.clearChanges();
        w.registry.patch<WorldTransform>(mobile).matrix = away ? moved : rest;
        benchmark::DoNotOptimize(w.scene.syncMoved(w.registry));
    }
    w.registry.patch<WorldTransform>(mobile).matrix = rest;
    w.scene.syncMoved(w.registry);
}

void BM_Build(benchmark::State& state, const std::string& name) {
    BenchWorld& w = world(name);
    for (auto _ : state)
        w.scene.build(w.registry);
    state.SetLabel(std::to_string(w.scene.staticTriangleCount()) + " static triangles");
}

/// Builds the built-in scene into a fresh registry: geometry generation and mesh processing
/// (welding, the refinement count, refinement, normals), the ray scene not included.
void BM_SceneLoad(benchmark::State& state, const std::string& name) {
    std::size_t triangles = 0;
    for (auto _ : state) {
        auto registry = std::make_unique<Registry>();
        buildBuiltinScene(*registry, name, SceneOptions{});
        state.PauseTiming(); // counting and tearing down are not the load
        triangles = 0;
        registry->view<const Mesh>().each(
            [&](Entity, const Mesh& mesh) { triangles += mesh.indices.size() / 3; });
        registry.reset();
        state.ResumeTiming();
    }
    state.SetLabel(std::to_string(triangles) + " triangles");
}

/// Runs a throughput benchmark on 1 .. `most` threads (its argument).
void onThreads(benchmark::internal::Benchmark* b, int most) {
    b->DenseRange(1, most)->ArgName("threads")->UseRealTime()->Unit(benchmark::kMillisecond);
}

} // namespace
} // namespace qgi

int main(int argc, char** argv) {
    using namespace qgi;
    using benchmark::RegisterBenchmark;
    setLogLevel(LogLevel::Warning); // BM_Build would log every rebuild
    for (const std::string& scene : builtinSceneNames()) {
        const auto id = [&](const char* what) { return std::string(what) + "/" + scene; };
        onThreads(RegisterBenchmark(id("Intersect1").c_str(), BM_Intersect1, scene), 2);
        onThreads(RegisterBenchmark(id("Intersect8").c_str(), BM_Intersect8, scene, true), 2);
        onThreads(RegisterBenchmark(id("Occluded1").c_str(), BM_Occluded1, scene), 2);
        onThreads(RegisterBenchmark(id("Occluded8").c_str(), BM_Occluded8, scene), 2);
        onThreads(RegisterBenchmark(id("Intersect8Fast").c_str(), BM_Intersect8, scene, false), 1);
        RegisterBenchmark(id("MobileMove").c_str(), BM_MobileMove, scene)
            ->Unit(benchmark::kMicrosecond);
        RegisterBenchmark(id("Build").c_str(), BM_Build, scene)->Unit(benchmark::kMillisecond);
        RegisterBenchmark(id("SceneLoad").c_str(), BM_SceneLoad, scene)
            ->Unit(benchmark::kMillisecond);
    }
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
