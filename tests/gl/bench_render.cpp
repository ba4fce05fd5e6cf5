// Frame time of the renderer on a 100k-triangle scene at 1280x720 (run under `xvfb-run -a`).
// Three cases: photon mode (no shadows), hybrid with a static scene (shadow maps kept), and
// hybrid with a 20k-triangle mobile moving every frame (the cube faces that see it refreshed).

#include "BenchRoom.h"

#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "systems/render/RenderSystem.h"

#include <benchmark/benchmark.h>

namespace qgi {
namespace {

/// The benchmark room with wavy walls; its last wall (the ceiling) is a MobileMesh, the wall
/// that moves in the "moving" case.
void renderFrames(benchmark::State& state, ShadingMode mode, bool moving) {
    bench::context();
    Registry world;
    const Entity mobile = bench::buildRoom(world, true).back();
    world.emplace<MobileMesh>(mobile);
    bench::renderFrames(state, world, mode, [&](std::uint64_t frame) {
        if (moving)
            world.patch<WorldTransform>(mobile).matrix[3].y = 4.f + 0.01f * float(frame % 10);
    });
}

void BM_PhotonMode(benchmark::State& state) {
    renderFrames(state, ShadingMode::Photon, false);
}
void BM_HybridStatic(benchmark::State& state) {
    renderFrames(state, ShadingMode::Hybrid, false);
}
void BM_HybridMoving(benchmark::State& state) {
    renderFrames(state, ShadingMode::Hybrid, true);
}

BENCHMARK(BM_PhotonMode)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HybridStatic)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HybridMoving)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
