// Cost of the SH probe system on the atrium scene (hybrid mode unless named otherwise):
//  - ProbeUpdate/<hybrid>: re-projecting 64 probes spread over the volume, per probe
//    (items/s = probes/s), on every core (the system's parallel loop);
//  - FullRefresh: projecting the whole atrium volume once;
//  - MovingMobile/<budget>: the system's frame while the cart moves along the east gallery
//    (the photon update and DETP run untimed before it, 100k photons): stale marking from the
//    photon delta and the moved bounds, a refresh of at most <budget> probes, the 7 avatars;
//  - UnchangedScene/<sweep>: the system's frame on a still scene with sweepPerFrame <sweep>
//    (the sweep rests once it has gone round after the last change: the avatars only);
//  - StaleResidual: the irradiance error the stale-marking rules leave in the probes they do
//    not mark while the cart moves (an unlimited budget refreshes every marked probe);
//  - AvatarLookups/<count>: ProbeVolume::interpolate for <count> avatars spread over the
//    walkable floor, on the calling thread only (one core);
//  - LightAvatars/<count>: the same plus reading WorldTransform and writing ShLighting
//    through the registry (ShProbeSystem::lightAvatars, warm visibility lattices).
#include "components/Avatar.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/SphericalHarmonics.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "systems/sh_probes/ProbeVolume.h"
#include "systems/sh_probes/ShProbeSystem.h"

#include <benchmark/benchmark.h>
#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <map>
#include <memory>
#include <random>
#include <vector>

namespace qgi {
namespace {

/// The atrium with photons, per-vertex irradiance and a probe volume, built once per mode.
struct BenchWorld {
    Registry registry;
    std::unique_ptr<PhotonUpdateSystem> photons;
    std::unique_ptr<DetpIrradianceSystem> detp;
    std::unique_ptr<ShProbeSystem> probes;
    Entity cart;
    glm::mat4 rest{1.f};
    std::uint64_t frame = 0;

    explicit BenchWorld(bool hybrid) {
        setLogLevel(LogLevel::Warning);
        buildBuiltinScene(registry, "atrium", SceneOptions{});
        registry.ctx().emplace<RayScene>().build(registry);
        PhotonSettings photonSettings;
        photonSettings.photonCount = 100'000;
        photons = std::make_unique<PhotonUpdateSystem>(photonSettings);
        DetpSettings detpSettings;
        detpSettings.hybrid = hybrid;
        detp = std::make_unique<DetpIrradianceSystem>(detpSettings);
        detp->build(registry);
        ShProbeSettings probeSettings;
        probeSettings.hybrid = hybrid;
        probes = std::make_unique<ShProbeSystem>(probeSettings);
        probes->build(registry);
        step(false);
        registry.view<const MobileMesh, const Name>().each(
            [&](Entity e, const MobileMesh&, const Name& n) {
                if (n.value == "cart") cart = e;
            });
        rest = registry.get<WorldTransform>(cart).matrix;
    }

    /// One frame of photons, DETP and (when `cart` moves) a 10 cm step of the cart.
    void step(bool moveCart) {
        if (moveCart) {
            const float z = 0.1f * float(frame % 160 < 80 ? frame % 80 : 80 - frame % 80);
            registry.patch<WorldTransform>(cart).matrix =
                glm::translate(glm::mat4(1.f), glm::vec3(0.f, 0.f, z)) * rest;
            registry.ctx().get<RayScene>().syncMoved(registry);
        }
        photons->update(registry, FrameContext{frame, 0.0, 0.f, 0});
        detp->update(registry, FrameContext{frame, 0.0, 0.f, 0});
        if (!moveCart) probes->update(registry, FrameContext{frame, 0.0, 0.f, 0});
        ++frame;
    }
};

BenchWorld& world(bool hybrid) {
    static std::map<bool, std::unique_ptr<BenchWorld>> worlds;
    auto& slot = worlds[hybrid];
    if (!slot) slot = std::make_unique<BenchWorld>(hybrid);
    return *slot;
}

/// A probe system of the benchmark's own on the shared atrium, with other settings: built and
/// through its first (full) projection; when it goes, the world's own system takes the probe
/// volume back.
struct OwnProbes {
    BenchWorld& w;
    ShProbeSystem probes;
    OwnProbes(BenchWorld& world, const ShProbeSettings& settings) : w(world), probes(settings) {
        probes.build(w.registry);
        probes.update(w.registry, FrameContext{});
        w.registry.clearChanges();
    }
    OwnProbes(const OwnProbes&) = delete;
    OwnProbes& operator=(const OwnProbes&) = delete;
    ~OwnProbes() {
        w.probes->build(w.registry);
        w.probes->projectAll(w.registry);
    }
};

void ProbeUpdate(benchmark::State& state) {
    BenchWorld& w = world(state.range(0) != 0);
    const std::size_t count = w.registry.ctx().get<ProbeVolume>().probeCount();
    std::vector<std::uint32_t> batch;
    for (std::size_t i = 0; i < 64; ++i)
        batch.push_back(std::uint32_t(i * count / 64));
    for (auto _ : state)
        w.probes->projectProbes(w.registry, batch);
    state.SetItemsProcessed(std::int64_t(state.iterations()) * 64);
    state.counters["rays_per_probe"] = double(w.probes->settings().raysPerProbe);
}
BENCHMARK(ProbeUpdate)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void FullRefresh(benchmark::State& state) {
    BenchWorld& w = world(true);
    for (auto _ : state)
        w.probes->projectAll(w.registry);
    state.counters["probes"] = double(w.registry.ctx().get<ProbeVolume>().probeCount());
}
BENCHMARK(FullRefresh)->Unit(benchmark::kMillisecond)->UseRealTime();

void MovingMobile(benchmark::State& state) {
    BenchWorld& w = world(true);
    ShProbeSettings settings = w.probes->settings();
    settings.updateBudget = std::uint32_t(state.range(0));
    OwnProbes own(w, settings);
    ShProbeSystem& probes = own.probes;
    double marked = 0, refreshed = 0, swept = 0, stale = 0;
    for (auto _ : state) {
        state.PauseTiming();
        w.step(true);
        state.ResumeTiming();
        probes.update(w.registry, FrameContext{w.frame, 0.0, 0.f, 0});
        state.PauseTiming();
        w.registry.clearChanges();
        marked += double(probes.lastFrame().markedStale);
        refreshed += double(probes.lastFrame().refreshed);
        swept += double(probes.lastFrame().swept);
        stale += double(probes.lastFrame().staleAfter);
        state.ResumeTiming();
    }
    const double n = double(state.iterations());
    state.counters["marked_per_frame"] = marked / n;
    state.counters["refreshed_per_frame"] = refreshed / n;
    state.counters["swept_per_frame"] = swept / n;
    state.counters["stale_left"] = stale / n;
}
BENCHMARK(MovingMobile)
    ->Arg(8)
    ->Arg(32)
    ->Arg(128)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(60);

void UnchangedScene(benchmark::State& state) {
    BenchWorld& w = world(true);
    ShProbeSettings settings = w.probes->settings();
    settings.sweepPerFrame = std::uint32_t(state.range(0));
    OwnProbes own(w, settings);
    ShProbeSystem& probes = own.probes;
    double refreshed = 0;
    for (auto _ : state) {
        probes.update(w.registry, FrameContext{++w.frame, 0.0, 0.f, 0});
        refreshed += double(probes.lastFrame().refreshed);
    }
    state.counters["refreshed_per_frame"] = refreshed / double(state.iterations());
}
BENCHMARK(UnchangedScene)
    ->Arg(0)
    ->Arg(4)
    ->Arg(16)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime()
    ->Iterations(400);

std::vector<glm::vec3> avatarPositions(std::size_t count) {
    // Avatar centres over the ground floor and the upper gallery, 0.875 m above each.
    std::mt19937 random(7);
    std::uniform_real_distribution<float> across(-11.5f, 11.5f);
    std::vector<glm::vec3> out;
    for (std::size_t i = 0; i < count; ++i)
        out.push_back({across(random), i % 4 == 3 ? 5.175f : 0.875f, across(random)});
    return out;
}

/// What the marking rules leave behind, the sweep off: the cart moves 10 cm a frame for 40 frames
/// with an unlimited budget, so every probe marked stale is refreshed at once; then each probe is
/// projected afresh with the same rays. A probe still differing was never marked: the
/// mobile was only in view of it (under mobileSolidAngleShare of its sphere), or the
/// per-vertex irradiance it sees changed by fewer delta end points than minDeltaEndPoints.
/// Counters: the relative irradiance difference (over the six axis normals, against the
/// probe's largest fresh irradiance) at its median, 99th percentile and maximum over the
/// enabled probes, and the share of probes that differ at all.
void StaleResidual(benchmark::State& state) {
    BenchWorld& w = world(true);
    ShProbeSettings settings = w.probes->settings();
    settings.updateBudget = 1u << 24; // more than the volume holds
    settings.sweepPerFrame = 0;       // the rules alone
    OwnProbes own(w, settings);
    ShProbeSystem& probes = own.probes;
    const ProbeVolume& volume = w.registry.ctx().get<ProbeVolume>();
    std::vector<double> residual;
    std::size_t differing = 0;
    for (auto _ : state) {
        for (int f = 0; f < 40; ++f) {
            w.step(true);
            probes.update(w.registry, FrameContext{w.frame, 0.0, 0.f, 0});
            w.registry.clearChanges();
        }
        std::vector<sh::ShRgb> kept(volume.probeCount());
        for (std::uint32_t p = 0; p < kept.size(); ++p)
            kept[p] = volume.coefficients(p);
        probes.projectAll(w.registry);
        const glm::vec3 axes[6] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                   {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
        for (std::uint32_t p = 0; p < kept.size(); ++p) {
            if (!volume.enabled(p)) continue;
            double largest = 0.0, worst = 0.0;
            for (const glm::vec3& n : axes) {
                const glm::vec3 fresh = sh::irradiance(volume.coefficients(p), n);
                const glm::vec3 stale = sh::irradiance(kept[p], n);
                largest = std::max({largest, double(fresh.x), double(fresh.y), double(fresh.z)});
                worst = std::max(worst, double(glm::length(fresh - stale)));
            }
            if (worst > 0.0) ++differing;
            residual.push_back(largest > 0.0 ? worst / largest : 0.0);
        }
    }
    std::sort(residual.begin(), residual.end());
    const auto at = [&](double q) {
        return residual.empty() ? 0.0 : residual[std::size_t(q * double(residual.size() - 1))];
    };
    state.counters["probes"] = double(residual.size());
    state.counters["differing_share"] =
        double(differing) / double(std::max<std::size_t>(1, residual.size()));
    state.counters["relative_p50"] = at(0.5);
    state.counters["relative_p99"] = at(0.99);
    state.counters["relative_max"] = at(1.0);
}
BENCHMARK(StaleResidual)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

void AvatarLookups(benchmark::State& state) {
    BenchWorld& w = world(true);
    const auto positions = avatarPositions(std::size_t(state.range(0)));
    // Warm the visibility lattices of the cells the avatars stand in.
    std::vector<Entity> avatars;
    for (const glm::vec3& p : positions) {
        const Entity e = w.registry.create();
        w.registry.emplace<WorldTransform>(e, glm::translate(glm::mat4(1.f), p));
        w.registry.emplace<Avatar>(e);
        avatars.push_back(e);
    }
    w.probes->lightAvatars(w.registry);
    const ProbeVolume& volume = w.registry.ctx().get<ProbeVolume>();
    sh::ShRgb sum{};
    for (auto _ : state) {
        for (const glm::vec3& p : positions) {
            sh::ShRgb L;
            if (volume.interpolate(p, L)) sum[0] += L[0];
        }
        benchmark::DoNotOptimize(sum);
    }
    state.SetItemsProcessed(std::int64_t(state.iterations()) * state.range(0));
    for (const Entity e : avatars)
        w.registry.destroy(e);
}
BENCHMARK(AvatarLookups)->Arg(10'000)->Unit(benchmark::kMicrosecond);

void LightAvatars(benchmark::State& state) {
    BenchWorld& w = world(true);
    std::vector<Entity> avatars;
    for (const glm::vec3& p : avatarPositions(std::size_t(state.range(0)))) {
        const Entity e = w.registry.create();
        w.registry.emplace<WorldTransform>(e, glm::translate(glm::mat4(1.f), p));
        w.registry.emplace<Avatar>(e);
        avatars.push_back(e);
    }
    w.probes->lightAvatars(w.registry); // warm: lattices and ShLighting components exist
    for (auto _ : state)
        w.probes->lightAvatars(w.registry);
    state.SetItemsProcessed(std::int64_t(state.iterations()) * state.range(0));
    for (const Entity e : avatars)
        w.registry.destroy(e);
}
BENCHMARK(LightAvatars)->Arg(10'000)->Unit(benchmark::kMicrosecond);

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
