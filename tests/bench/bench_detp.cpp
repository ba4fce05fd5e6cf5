// Cost of per-vertex irradiance on the cornell scene in photon mode (the luminaire's photons):
//  - Full/<photons>/<estimator>: a full estimate over the whole ray set (estimator 0 DETP,
//    1 impact count, 2 photon map);
//  - MovingMobile/<photons>: DETP's frame while the mobile box moves 1 cm per frame (the
//    photon update runs untimed before it), with the delta sizes it sees as counters;
//  - Incremental/<paths>: DETP's incremental update for a delta of that many re-traced paths
//    at 1M photons, to set against the full estimate at the same photon count: each path's
//    segments as they are and with the first one 1% shorter (a mobile moved into its way),
//    applied one way and back on alternate iterations;
//  - DiscIndex vs DiscBruteForce: the same (segment, disc) pairs found with Embree's
//    oriented-disc index and with the all-pairs loop.
#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/EmbreeDevice.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/detp/DiscCrossing.h"
#include "systems/detp/DiscIndex.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonUpdateSystem.h"

#include <benchmark/benchmark.h>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <numeric>
#include <random>
#include <vector>

namespace qgi {
namespace {

/// The cornell scene with its ray scene and a photon ray set, built once per photon count.
struct BenchWorld {
    Registry registry;
    std::unique_ptr<PhotonUpdateSystem> photons;
    Entity mobile;
    glm::mat4 rest{1.f};
    std::uint64_t frame = 0;

    explicit BenchWorld(std::uint32_t photonCount) {
        buildBuiltinScene(registry, "cornell", SceneOptions{});
        registry.ctx().emplace<RayScene>().build(registry);
        PhotonSettings settings;
        settings.photonCount = photonCount;
        settings.punctualLights = false; // photon mode: the luminaire alone
        photons = std::make_unique<PhotonUpdateSystem>(settings);
        photons->update(registry, FrameContext{frame++, 0.0, 0.f, 0});
        registry.clearChanges();
        mobile = registry.view<const MobileMesh>().entities().front();
        rest = registry.get<WorldTransform>(mobile).matrix;
    }

    /// Moves the mobile 1 cm along x (back and forth over 20 cm) and updates the photons.
    void step() {
        const float x = 0.01f * float(frame % 40 < 20 ? frame % 20 : 20 - frame % 20);
        registry.patch<WorldTransform>(mobile).matrix =
            glm::translate(glm::mat4(1.f), glm::vec3(x, 0.f, 0.f)) * rest;
        registry.ctx().get<RayScene>().syncMoved(registry);
        photons->update(registry, FrameContext{frame++, 0.0, 0.f, 0});
    }
};

BenchWorld& world(std::uint32_t photons) {
    static std::map<std::uint32_t, std::unique_ptr<BenchWorld>> worlds;
    std::unique_ptr<BenchWorld>& slot = worlds[photons];
    if (!slot) {
        setLogLevel(LogLevel::Warning);
        slot = std::make_unique<BenchWorld>(photons);
    }
    return *slot;
}

void Full(benchmark::State& state) {
    BenchWorld& w = world(std::uint32_t(state.range(0)));
    DetpSettings settings;
    settings.estimator = IrradianceEstimator(state.range(1));
    DetpIrradianceSystem system(settings);
    system.build(w.registry);
    PhotonDelta& delta = w.registry.ctx().get<PhotonDelta>();
    for (auto _ : state) {
        delta.full = true;
        ++delta.sequence; // a new delta each time: the system skips one it has applied
        system.update(w.registry, {});
    }
    if (system.lastFrame().verticesWritten == 0) state.SkipWithError("nothing was estimated");
    delta.full = false;
    const auto& store = w.registry.ctx().get<PhotonStore>();
    state.counters["segments"] = double(store.segments.size());
    state.counters["crossings"] = double(system.lastFrame().crossings);
    state.counters["vertices"] = double(system.lastFrame().verticesWritten);
}
BENCHMARK(Full)
    ->ArgsProduct({{100'000, 1'000'000}, {0, 1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void MovingMobile(benchmark::State& state) {
    BenchWorld& w = world(std::uint32_t(state.range(0)));
    DetpIrradianceSystem system(DetpSettings{});
    system.build(w.registry);
    w.registry.ctx().get<PhotonDelta>().full = true;
    system.update(w.registry, {});
    w.registry.clearChanges();
    double deltaSegments = 0, candidates = 0, crossings = 0;
    for (auto _ : state) {
        w.step();
        const auto start = std::chrono::steady_clock::now();
        system.update(w.registry, {});
        state.SetIterationTime(
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        w.registry.clearChanges();
        deltaSegments += double(system.lastFrame().deltaSegments);
        candidates += double(system.lastFrame().candidateSegments);
        crossings += double(system.lastFrame().crossings);
    }
    const double frames = double(state.iterations());
    state.counters["deltaSegments"] = deltaSegments / frames;
    state.counters["mobileCandidates"] = candidates / frames;
    state.counters["crossings"] = crossings / frames;
}
BENCHMARK(MovingMobile)
    ->Arg(100'000)
    ->Arg(1'000'000)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime();

void Incremental(benchmark::State& state) {
    BenchWorld& w = world(1'000'000);
    DetpIrradianceSystem system(DetpSettings{});
    system.build(w.registry);
    PhotonDelta& delta = w.registry.ctx().get<PhotonDelta>();
    delta.full = true;
    system.update(w.registry, {});

    // Two deltas over the same paths: cut the heads 1% short, and restore them.
    const auto& store = w.registry.ctx().get<PhotonStore>();
    PhotonDelta deltas[2];
    std::mt19937 rng(7);
    std::uniform_int_distribution<std::uint32_t> pick(0, std::uint32_t(store.pathCount() - 1));
    for (PhotonDelta& d : deltas) {
        d.oldFirst = {0};
        d.newFirst = {0};
    }
    for (std::int64_t i = 0; i < state.range(0); ++i) {
        const std::uint32_t p = pick(rng);
        for (PhotonDelta& d : deltas) {
            d.paths.push_back(p);
            for (std::uint32_t k = 0; k < store.paths[p].count; ++k) {
                d.oldSegments.appendFrom(store.segments, store.paths[p].first + k);
                d.newSegments.appendFrom(store.segments, store.paths[p].first + k);
            }
            d.oldFirst.push_back(std::uint32_t(d.oldSegments.size()));
            d.newFirst.push_back(std::uint32_t(d.newSegments.size()));
        }
        float& cut = deltas[0].newSegments.length[deltas[0].newFirst[std::size_t(i)]];
        cut = std::isinf(cut) ? 1.f : 0.99f * cut;
        deltas[1].oldSegments.length[deltas[1].oldFirst[std::size_t(i)]] = cut;
    }
    std::size_t iteration = 0;
    for (auto _ : state) {
        PhotonDelta& next = deltas[iteration++ % 2];
        std::swap(delta, next);
        system.update(w.registry, {});
        std::swap(delta, next);
    }
    delta = PhotonDelta{};
    state.counters["deltaSegments"] = double(system.lastFrame().deltaSegments);
    state.counters["crossings"] = double(system.lastFrame().crossings);
}
BENCHMARK(Incremental)
    ->Arg(100)
    ->Arg(1'000)
    ->Arg(10'000)
    ->Arg(100'000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// ---- disc index against brute force --------------------------------------------------------

constexpr float kRadius = 0.02f;

struct DiscWorld {
    std::vector<glm::vec3> centers, normals;
    PhotonSegments segments;
    std::vector<std::uint32_t> indices;

    explicit DiscWorld(std::size_t n) {
        std::mt19937 rng(5);
        std::uniform_real_distribution<float> unit(0.f, 1.f);
        std::normal_distribution<float> gauss;
        const auto direction = [&] {
            return glm::normalize(glm::vec3(gauss(rng), gauss(rng), gauss(rng)) + 1e-6f);
        };
        for (std::size_t i = 0; i < n; ++i) {
            centers.push_back({unit(rng), unit(rng), unit(rng)});
            normals.push_back(direction());
            segments.origin.push_back({unit(rng), unit(rng), unit(rng)});
            segments.direction.push_back(direction());
            segments.length.push_back(i % 2 ? unit(rng) : std::numeric_limits<float>::infinity());
            segments.power.push_back(glm::vec3(1.f));
            segments.hitEntity.push_back({});
            segments.hitPrimitive.push_back(0);
            segments.bounce.push_back(1);
        }
        indices.resize(n);
        std::iota(indices.begin(), indices.end(), 0u);
    }
};

void DiscIndexQuery(benchmark::State& state) {
    const DiscWorld w(std::size_t(state.range(0)));
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(w.centers, w.normals, kRadius);
    std::vector<DiscCrossing> out;
    for (auto _ : state) {
        index.collectCrossings(w.segments, w.indices, out);
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["pairs"] = double(out.size());
    state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(DiscIndexQuery)->Arg(4096)->Arg(16384)->Unit(benchmark::kMillisecond)->UseRealTime();

void DiscBruteForce(benchmark::State& state) {
    const DiscWorld w(std::size_t(state.range(0)));
    std::size_t pairs = 0;
    for (auto _ : state) {
        pairs = 0;
        for (std::size_t s = 0; s < w.segments.size(); ++s)
            for (std::size_t d = 0; d < w.centers.size(); ++d)
                pairs += crossesDisc(w.segments.origin[s], w.segments.direction[s],
                                     w.segments.length[s], w.centers[d], w.normals[d], kRadius);
        benchmark::DoNotOptimize(pairs);
    }
    state.counters["pairs"] = double(pairs);
    state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(DiscBruteForce)->Arg(4096)->Arg(16384)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
