// Fragment-shader cost of point-cache shading (shaders/common/pointcache.glsl) against plain
// per-vertex shading, at 1280x720 on the renderer's 100k-triangle room (run under
// `xvfb-run -a`). Both cases run in one process on the same scene: PerVertex draws the walls
// with their per-vertex irradiance; PointCache tags every wall PointCacheShaded and blends a
// cache of `points` points spread uniformly over the walls (spacing radius chosen so a query
// finds about 6 points, as on the atrium). Hybrid mode, one spot light with a shadow map.
#include "BenchRoom.h"

#include "components/PointCacheShaded.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "systems/point_cache/PointCache.h"
#include "systems/render/RenderSystem.h"

#include <benchmark/benchmark.h>
#include <glm/gtc/constants.hpp>

#include <cmath>
#include <random>

namespace qgi {
namespace {

void renderRoom(benchmark::State& state, bool pointCache) {
    bench::context();
    Registry world;
    const auto walls = bench::buildRoom(world, false);
    if (pointCache) {
        PointCache& cache = world.ctx().emplace<PointCache>();
        const std::uint32_t perWall = std::uint32_t(state.range(0)) / 5;
        // Uniform points over a 16 m^2 wall at density d find d pi R^2 points in reach: R for 6.
        const float density = float(perWall) / 16.f;
        const float spacing = std::sqrt(6.f / (glm::pi<float>() * density)) / 2.f;
        std::mt19937 rng(1);
        std::uniform_real_distribution<float> u(0.f, 1.f);
        for (const Entity e : walls) {
            world.emplace<PointCacheShaded>(e);
            const glm::mat4 pose = world.get<WorldTransform>(e).matrix;
            // Points face the wall's front (+z of its frame); a side seen from the back finds
            // none in range after the same candidate loop and draws the per-vertex fallback.
            const glm::vec3 n = glm::normalize(glm::vec3(pose * glm::vec4(0.f, 0.f, 1.f, 0.f)));
            for (std::uint32_t i = 0; i < perWall; ++i) {
                cache.position.push_back(glm::vec3(pose * glm::vec4(u(rng), u(rng), 0.f, 1.f)));
                cache.normal.push_back(n);
                cache.radius.push_back(spacing);
                cache.dart.push_back(i);
                cache.ao.push_back(0.f);
                cache.direct.push_back(glm::vec3(u(rng)));
                cache.indirect.push_back(glm::vec3(0.2f));
            }
        }
        cache.buildGrid();
    }
    bench::renderFrames(state, world, ShadingMode::Hybrid, [](std::uint64_t) {});
    if (pointCache)
        state.counters["gridEntries"] = double(world.ctx().get<PointCache>().grid.entryCount());
}

void BM_PerVertex(benchmark::State& state) {
    renderRoom(state, false);
}
void BM_PointCache(benchmark::State& state) {
    renderRoom(state, true);
}
BENCHMARK(BM_PerVertex)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PointCache)->Arg(10'000)->Arg(100'000)->Unit(benchmark::kMillisecond)->UseRealTime();

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
