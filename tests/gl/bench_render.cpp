// Frame time of the renderer on a 100k-triangle scene at 1280x720 (run under `xvfb-run -a`).
// Three cases: photon mode (no shadows), hybrid with a static scene (shadow maps kept), and
// hybrid with a 20k-triangle mobile moving every frame (the cube faces that see it refreshed).

#include "components/Camera.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/render/GlWindow.h"
#include "systems/render/RenderSystem.h"

#include <benchmark/benchmark.h>
#include <epoxy/gl.h>
#include <glm/gtc/matrix_transform.hpp>

namespace qgi {
namespace {

constexpr int kWidth = 1280, kHeight = 720;

/// A wavy n x n grid over the unit square in XY (2 n^2 triangles), facing +Z.
Mesh gridMesh(int n) {
    Mesh mesh;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            const float u = float(i) / float(n), v = float(j) / float(n);
            mesh.positions.push_back({u, v, 0.02f * std::sin(40.f * u) * std::cos(40.f * v)});
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

/// A 4 m room of five 20k-triangle walls (100k triangles), a point light, a camera, per-vertex
/// irradiance on every wall. Returns the wall that moves in the "moving" case (a MobileMesh).
Entity buildRoom(Registry& world) {
    const Mesh wall = gridMesh(100); // 20,000 triangles
    const glm::mat4 scale = glm::scale(glm::mat4(1.f), glm::vec3(4.f));
    const glm::mat4 poses[5] = {
        glm::translate(glm::mat4(1.f), {-2.f, 0.f, -2.f}) * scale, // back
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
    Entity last{};
    for (const glm::mat4& pose : poses) {
        last = world.create();
        world.emplace<Mesh>(last, wall);
        world.emplace<WorldTransform>(last, WorldTransform{pose});
        world.emplace<Material>(last);
        VertexIrradiance& e = world.emplace<VertexIrradiance>(last);
        e.irradiance.assign(wall.positions.size(), glm::vec3(0.5f));
    }
    const Entity light = world.create();
    world.emplace<SpotLight>(light, SpotLight{glm::vec3(1.f), 5.f, 0.5f, 1.2f});
    world.emplace<WorldTransform>(
        light, WorldTransform{glm::rotate(glm::translate(glm::mat4(1.f), {0.f, 3.f, 0.f}), -1.5708f,
                                          glm::vec3(1, 0, 0))});
    const Entity camera = world.create();
    world.emplace<Camera>(camera).active = true;
    world.emplace<WorldTransform>(camera,
                                  WorldTransform{glm::translate(glm::mat4(1.f), {0.f, 2.f, 5.5f})});
    world.emplace<MobileMesh>(last);
    return last;
}

/// One window for every case: the context outlives each case's registry and renderer.
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

void renderFrames(benchmark::State& state, ShadingMode mode, bool moving) {
    context();
    Registry world;
    const Entity mobile = buildRoom(world);
    RenderSettings settings;
    settings.width = kWidth;
    settings.height = kHeight;
    settings.mode = mode;
    RenderSystem renderer(settings);
    std::uint64_t frame = 0;
    FrameProfiler& profiler = world.ctx().emplace<FrameProfiler>(); // per-pass times
    for (auto _ : state) {
        profiler.beginFrame(frame);
        if (moving) {
            world.patch<WorldTransform>(mobile).matrix[3].y = 4.f + 0.01f * float(frame % 10);
        }
        renderer.update(world, FrameContext{frame++, 0.0, 0.f, 0});
        world.clearChanges();
        glFinish(); // the frame is done when the GPU is
        profiler.endFrame();
    }
    for (const ProfileStats& pass : profiler.statistics())
        if (pass.name.starts_with("render/")) state.counters[pass.name + "_ms"] = pass.mean;
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
