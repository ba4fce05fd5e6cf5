// Fragment-shader cost of point-cache shading (shaders/common/pointcache.glsl) against plain
// per-vertex shading, at 1280x720 on the renderer's 100k-triangle room (run under
// `xvfb-run -a`). Both cases run in one process on the same scene: PerVertex draws the walls
// with their per-vertex irradiance; PointCache tags every wall PointCacheShaded and blends a
// cache of `points` points spread uniformly over the walls (spacing radius chosen so a query
// finds about 6 points, as on the atrium). Hybrid mode, one spot light with a shadow map.
#include "components/Camera.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/PointCacheShaded.h"
#include "components/SpotLight.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/render/GlWindow.h"
#include "systems/point_cache/PointCache.h"
#include "systems/render/RenderSystem.h"

#include <benchmark/benchmark.h>
#include <epoxy/gl.h>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include <random>

namespace qgi {
namespace {

constexpr int kWidth = 1280, kHeight = 720;

Mesh gridMesh(int n) {
    Mesh mesh;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            mesh.positions.push_back({float(i) / float(n), float(j) / float(n), 0.f});
            mesh.normals.push_back({0.f, 0.f, 1.f});
        }
    const auto at = [&](int i, int j) { return std::uint32_t(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            for (const std::uint32_t k : {at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j),
                                          at(i + 1, j + 1), at(i, j + 1)})
                mesh.indices.push_back(k);
    return mesh;
}

GlWindow& context() {
    static GlWindow window([] {
        WindowSettings settings;
        settings.width = kWidth;
        settings.height = kHeight;
        settings.headless = true;
        return settings;
    }());
    return window;
}

void renderRoom(benchmark::State& state, bool pointCache) {
    context();
    Registry world;
    const Mesh wall = gridMesh(100); // 20,000 triangles
    const glm::mat4 scale = glm::scale(glm::mat4(1.f), glm::vec3(4.f));
    const glm::mat4 poses[5] = {
        glm::translate(glm::mat4(1.f), {-2.f, 0.f, -2.f}) * scale,
        glm::rotate(glm::translate(glm::mat4(1.f), {-2.f, 0.f, 2.f}), glm::radians(90.f),
                    {0, 1, 0}) *
            scale,
        glm::rotate(glm::translate(glm::mat4(1.f), {2.f, 0.f, -2.f}), glm::radians(-90.f),
                    {0, 1, 0}) *
            scale,
        glm::rotate(glm::translate(glm::mat4(1.f), {-2.f, 0.f, 2.f}), glm::radians(-90.f),
                    {1, 0, 0}) *
            scale,
        glm::rotate(glm::translate(glm::mat4(1.f), {-2.f, 4.f, -2.f}), glm::radians(90.f),
                    {1, 0, 0}) *
            scale,
    };
    PointCache* cache = pointCache ? &world.ctx().emplace<PointCache>() : nullptr;
    const std::uint32_t perWall = std::uint32_t(state.range(0)) / 5;
    // Uniform points over a 16 m^2 wall at density d find d pi R^2 points in reach: R for 6.
    const float density = float(perWall) / 16.f;
    const float spacing = std::sqrt(6.f / (glm::pi<float>() * density)) / 2.f;
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (const glm::mat4& pose : poses) {
        const Entity e = world.create();
        world.emplace<Mesh>(e, wall);
        world.emplace<WorldTransform>(e, WorldTransform{pose});
        world.emplace<Material>(e);
        world.emplace<VertexIrradiance>(e).irradiance.assign(wall.positions.size(),
                                                             glm::vec3(0.5f));
        if (!cache) continue;
        world.emplace<PointCacheShaded>(e);
        // Points face the wall's front (+z of its frame); a side seen from the back finds
        // none in range after the same candidate loop and draws the per-vertex fallback.
        const glm::vec3 n = glm::normalize(glm::vec3(pose * glm::vec4(0.f, 0.f, 1.f, 0.f)));
        for (std::uint32_t i = 0; i < perWall; ++i) {
            cache->position.push_back(glm::vec3(pose * glm::vec4(u(rng), u(rng), 0.f, 1.f)));
            cache->normal.push_back(n);
            cache->radius.push_back(spacing);
            cache->dart.push_back(i);
            cache->ao.push_back(0.f);
            cache->direct.push_back(glm::vec3(u(rng)));
            cache->indirect.push_back(glm::vec3(0.2f));
        }
    }
    if (cache) cache->buildGrid();
    const Entity light = world.create();
    world.emplace<SpotLight>(light, SpotLight{glm::vec3(1.f), 5.f, 0.5f, 1.2f});
    world.emplace<WorldTransform>(
        light, WorldTransform{glm::rotate(glm::translate(glm::mat4(1.f), {0.f, 3.f, 0.f}), -1.5708f,
                                          glm::vec3(1, 0, 0))});
    const Entity camera = world.create();
    world.emplace<Camera>(camera).active = true;
    world.emplace<WorldTransform>(camera,
                                  WorldTransform{glm::translate(glm::mat4(1.f), {0.f, 2.f, 5.5f})});

    RenderSettings settings;
    settings.width = kWidth;
    settings.height = kHeight;
    settings.mode = ShadingMode::Hybrid;
    RenderSystem renderer(settings);
    std::uint64_t frame = 0;
    FrameProfiler& profiler = world.ctx().emplace<FrameProfiler>();
    for (auto _ : state) {
        profiler.beginFrame(frame);
        renderer.update(world, FrameContext{frame++, 0.0, 0.f, 0});
        world.clearChanges();
        glFinish();
        profiler.endFrame();
    }
    for (const ProfileStats& pass : profiler.statistics())
        if (pass.name.starts_with("render/")) state.counters[pass.name + "_ms"] = pass.mean;
    if (cache) state.counters["gridEntries"] = double(cache->grid.entryCount());
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
