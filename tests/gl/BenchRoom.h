#pragma once
// The scene and frame loop the renderer benchmarks share: a 4 m room of five 20k-triangle walls
// (100k triangles) with per-vertex irradiance, one spot light and a camera, drawn at 1280x720
// in a headless window (run under `xvfb-run -a`, or with QGI_GL_CONTEXT=egl on a GPU machine
// without X).

#include "GlTestWindow.h"
#include "components/Camera.h"
#include "components/Material.h"
#include "components/Mesh.h"
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

#include <array>
#include <cmath>
#include <vector>

namespace qgi::bench {

inline constexpr int kWidth = 1280, kHeight = 720;

/// An n x n grid over the unit square in XY (2 n^2 triangles), facing +Z; `wavy` displaces it
/// along Z by up to 2 cm (normals stay +Z), flat otherwise.
inline Mesh gridMesh(int n, bool wavy) {
    Mesh mesh;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            const float u = float(i) / float(n), v = float(j) / float(n);
            const float z = wavy ? 0.02f * std::sin(40.f * u) * std::cos(40.f * v) : 0.f;
            mesh.positions.push_back({u, v, z});
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

/// One window for every case: the context outlives each case's registry and renderer. With
/// QGI_GL_CONTEXT=egl in the environment it is an EGL pbuffer (a GPU machine without X).
inline GlWindow& context() {
    static GlWindow window(test::testWindow(kWidth, kHeight, "qgi benchmark"));
    return window;
}

/// The room: gridMesh(100, wavy) scaled to 4 m as back, left, right, floor and ceiling walls
/// (each with a default Material and per-vertex irradiance 0.5 W/m^2), then a spot light 3 m up
/// pointing down and the active camera. Returns the wall entities in that order; the unit
/// square's +Z (the front of a wall) maps through the wall's WorldTransform.
inline std::array<Entity, 5> buildRoom(Registry& world, bool wavy) {
    const Mesh wall = gridMesh(100, wavy); // 20,000 triangles
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
    std::array<Entity, 5> walls{};
    for (std::size_t w = 0; w < walls.size(); ++w) {
        const Entity e = walls[w] = world.create();
        world.emplace<Mesh>(e, wall);
        world.emplace<WorldTransform>(e, WorldTransform{poses[w]});
        world.emplace<Material>(e);
        world.emplace<VertexIrradiance>(e).irradiance.assign(wall.positions.size(),
                                                             glm::vec3(0.5f));
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
    return walls;
}

/// Renders `world` once per benchmark iteration at kWidth x kHeight in `mode`, calling
/// `beforeFrame(frame)` first each time, and waits for the GPU at the end of each frame. Reports
/// the mean time of every "render/" pass as a counter "<pass>_ms".
template <typename BeforeFrame>
void renderFrames(benchmark::State& state, Registry& world, ShadingMode mode,
                  BeforeFrame&& beforeFrame) {
    RenderSettings settings;
    settings.width = kWidth;
    settings.height = kHeight;
    settings.mode = mode;
    RenderSystem renderer(settings);
    std::uint64_t frame = 0;
    FrameProfiler& profiler = world.ctx().emplace<FrameProfiler>(); // per-pass times
    for (auto _ : state) {
        profiler.beginFrame(frame);
        beforeFrame(frame);
        renderer.update(world, FrameContext{frame++, 0.0, 0.f, 0});
        world.clearChanges();
        glFinish(); // the frame is done when the GPU is
        profiler.endFrame();
    }
    for (const ProfileStats& pass : profiler.statistics())
        if (pass.name.starts_with("render/")) state.counters[pass.name + "_ms"] = pass.mean;
}

} // namespace qgi::bench
