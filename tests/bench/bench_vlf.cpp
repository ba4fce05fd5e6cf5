// Cost of the Virtual Light Field (seed 002):
//  - Bake/<scene>/<level>/<lines>: the whole bake (3 iterations, one jittered direction per
//    subfield and iteration) on a built-in scene (0 cornell, 1 cornell-glossy, 2 atrium),
//    with its memory as counters (MB: render tables and the bake's peak) and element counts;
//  - Iteration/<boxes>: one propagation iteration at 513 directions, 64 x 64 lines, against
//    the face count (a room holding boxes x boxes small blocks: 6 + 6 boxes^2 faces, the
//    blocks' tops lit by the emitting ceiling);
//  - DiffuseError/<level>/<jitter>: RMS relative error of a floor's irradiance under a
//    rectangular emitter against the closed-form form factor, as directions grow;
//  - Lookup: one CPU 12-tap lookup on the glossy floor and the mirror of cornell-glossy.
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/vlf/VlfBake.h"
#include "systems/vlf/VlfScene.h"

#include <benchmark/benchmark.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <memory>
#include <random>

namespace qgi {
namespace {

const char* const kScenes[] = {"cornell", "cornell-glossy", "atrium"};

std::unique_ptr<vlf::VlfScene> builtin(int index) {
    Registry registry;
    buildBuiltinScene(registry, kScenes[index], SceneOptions{});
    return vlf::VlfScene::fromRegistry(registry);
}

void Bake(benchmark::State& state) {
    setLogLevel(LogLevel::Warning);
    const auto scene = builtin(int(state.range(0)));
    VlfSettings s;
    s.directionLevel = int(state.range(1));
    s.linesPerSide = int(state.range(2));
    s.tileSize = 8;
    s.iterations = 3;
    vlf::VlfBakeStats stats;
    vlf::VlfMemory mem;
    for (auto _ : state) {
        const vlf::Vlf v = vlf::bakeVlf(*scene, s, &stats);
        mem = v.memory();
        benchmark::DoNotOptimize(v.irradiance().data());
    }
    state.SetLabel(kScenes[state.range(0)]);
    state.counters["faces"] = double(scene->faces().size());
    state.counters["directions"] = double(mem.directions);
    state.counters["tileCells"] = double(mem.tileCells);
    state.counters["texels"] = double(mem.diffuseTexels);
    state.counters["renderMB"] = double(mem.renderBytes) / 1e6;
    state.counters["bakeMB"] = double(mem.bakeBytes) / 1e6;
    state.counters["directS"] = stats.directSeconds;
    double iterations = 0.0, gather = 0.0;
    for (const auto& it : stats.iterations) {
        iterations += it.seconds;
        gather += it.gatherSeconds;
    }
    state.counters["gatherS"] = gather / double(stats.iterations.size());
    state.counters["iterationS"] = iterations / double(stats.iterations.size());
    state.counters["linesPerS"] = double(stats.lines) / iterations;
}
BENCHMARK(Bake)
    ->Args({0, 4, 64})
    ->Args({0, 5, 64})
    ->Args({1, 3, 64})
    ->Args({1, 4, 64})
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();
BENCHMARK(Bake)
    ->Name("BakeAtrium")
    ->Args({2, 4, 64})
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime();

std::unique_ptr<vlf::VlfScene> boxes(int k) {
    std::vector<vlf::VlfScene::Triangle> tris;
    std::vector<std::uint32_t> groups;
    std::vector<vlf::VlfScene::Material> materials{
        {glm::vec3(0.6f), glm::vec3(0.f), glm::vec3(0.f), 0.f},
        {glm::vec3(0.f), glm::vec3(10.f), glm::vec3(0.f), 0.f}};
    const auto quad = [&](glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d, std::uint32_t g) {
        tris.push_back({a, b, c, 0});
        tris.push_back({a, c, d, 0});
        groups.insert(groups.end(), {g, g});
    };
    const auto box = [&](glm::vec3 lo, glm::vec3 hi, bool inward, std::uint32_t group,
                         std::uint32_t topGroup) {
        for (int axis = 0; axis < 3; ++axis)
            for (int side = 0; side < 2; ++side) {
                const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
                glm::vec3 p[4];
                for (int q = 0; q < 4; ++q) {
                    p[q][axis] = side ? hi[axis] : lo[axis];
                    p[q][a1] = (q == 1 || q == 2) ? hi[a1] : lo[a1];
                    p[q][a2] = q >= 2 ? hi[a2] : lo[a2];
                }
                glm::vec3 want(0.f);
                want[axis] = (side ? 1.f : -1.f) * (inward ? -1.f : 1.f);
                const std::uint32_t g = axis == 1 && side == 1 ? topGroup : group;
                if (glm::dot(glm::cross(p[1] - p[0], p[2] - p[0]), want) > 0.f)
                    quad(p[0], p[1], p[2], p[3], g);
                else
                    quad(p[0], p[3], p[2], p[1], g);
            }
    };
    box({-1.f, 0.f, -1.f}, {1.f, 2.f, 1.f}, true, 0, 1); // the ceiling emits
    const float step = 1.6f / float(k);
    for (int i = 0; i < k; ++i)
        for (int j = 0; j < k; ++j) {
            const glm::vec3 lo(-0.8f + step * (float(i) + 0.2f), 0.f,
                               -0.8f + step * (float(j) + 0.2f));
            // Each block its own mesh, so coplanar faces of different blocks stay apart.
            const std::uint32_t g = std::uint32_t(materials.size());
            materials.push_back(materials[0]);
            box(lo, lo + glm::vec3(0.6f * step, 0.3f, 0.6f * step), false, g, g);
        }
    return std::make_unique<vlf::VlfScene>(tris, groups, materials,
                                           std::vector<vlf::PunctualLight>{}, glm::vec3(0.f));
}

void Iteration(benchmark::State& state) {
    setLogLevel(LogLevel::Warning);
    const auto scene = boxes(int(state.range(0)));
    VlfSettings s;
    s.directionLevel = 4;
    s.linesPerSide = 64;
    s.tileSize = 8;
    s.iterations = 1;
    vlf::VlfBakeStats stats;
    for (auto _ : state) {
        const vlf::Vlf v = vlf::bakeVlf(*scene, s, &stats);
        state.SetIterationTime(stats.iterations[0].seconds);
        benchmark::DoNotOptimize(v.irradiance().data());
    }
    state.counters["faces"] = double(scene->faces().size());
    state.counters["crossingsPerLine"] = double(stats.crossings) / double(stats.lines);
}
BENCHMARK(Iteration)
    ->DenseRange(1, 13, 3)
    ->Unit(benchmark::kSecond)
    ->Iterations(2)
    ->UseManualTime();

/// Floor [-1,1]^2 (albedo 0.5) under a 0.6 x 0.4 emitter (radiance 2) at height 0.5, one
/// iteration: the floor's irradiance against the closed form E = pi L F (digest section 6,
/// item 9), as RMS relative error over the texels under and around the emitter.
void DiffuseError(benchmark::State& state) {
    setLogLevel(LogLevel::Warning);
    const float a = 0.6f, b = 0.4f, c = 0.5f, L = 2.f;
    std::vector<vlf::VlfScene::Triangle> tris;
    const auto quad = [&](glm::vec3 p0, glm::vec3 p1, glm::vec3 p2, glm::vec3 p3) {
        tris.push_back({p0, p1, p2, 0});
        tris.push_back({p0, p2, p3, 0});
    };
    quad({-1.f, 0.f, -1.f}, {-1.f, 0.f, 1.f}, {1.f, 0.f, 1.f}, {1.f, 0.f, -1.f});
    quad({-a / 2, c, -b / 2}, {a / 2, c, -b / 2}, {a / 2, c, b / 2}, {-a / 2, c, b / 2});
    const vlf::VlfScene scene(tris, {0, 0, 1, 1},
                              {{glm::vec3(0.5f), glm::vec3(0.f), glm::vec3(0.f), 0.f},
                               {glm::vec3(0.f), glm::vec3(L), glm::vec3(0.f), 0.f}},
                              {}, glm::vec3(0.f));
    const auto corner = [&](double u, double v) {
        const double X = std::abs(u) / c, Y = std::abs(v) / c;
        const double sx = std::sqrt(1 + X * X), sy = std::sqrt(1 + Y * Y);
        return (u < 0 ? -1 : 1) * (v < 0 ? -1 : 1) *
               (X / sx * std::atan(Y / sx) + Y / sy * std::atan(X / sy)) / (2 * M_PI);
    };
    const auto exact = [&](double x, double z) {
        const double x0 = -a / 2 - x, x1 = a / 2 - x, z0 = -b / 2 - z, z1 = b / 2 - z;
        return M_PI * L * (corner(x1, z1) - corner(x0, z1) - corner(x1, z0) + corner(x0, z0));
    };
    VlfSettings s;
    s.directionLevel = int(state.range(0));
    s.linesPerSide = 128;
    s.tileSize = 8;
    s.iterations = 1;
    s.jitterSamples = int(state.range(1));
    s.filterSigma = 0.f;
    s.texelCells = 2.f;
    double rms = 0.0;
    for (auto _ : state) {
        const vlf::Vlf v = vlf::bakeVlf(scene, s);
        const vlf::FaceMap& m = v.faceMaps()[0];
        double err2 = 0.0;
        int n = 0;
        for (std::uint32_t ty = 0; ty < m.height; ++ty)
            for (std::uint32_t tx = 0; tx < m.width; ++tx) {
                const glm::vec3 x = v.texelCenter(0, tx, ty);
                if (std::abs(x.x) > 0.6f || std::abs(x.z) > 0.6f) continue;
                double truth = 0.0; // texel mean, 8 x 8 midpoint rule
                for (int i = 0; i < 8; ++i)
                    for (int j = 0; j < 8; ++j)
                        truth += exact(x.x + m.texelU * ((i + 0.5) / 8 - 0.5),
                                       x.z + m.texelV * ((j + 0.5) / 8 - 0.5)) /
                                 64;
                const double e =
                    (v.irradiance()[m.firstTexel + ty * m.width + tx].x - truth) / truth;
                err2 += e * e;
                ++n;
            }
        rms = std::sqrt(err2 / n);
    }
    state.counters["rmsRelError"] = rms;
}
BENCHMARK(DiffuseError)
    ->ArgsProduct({{2, 3, 4, 5}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();

void Lookup(benchmark::State& state) {
    setLogLevel(LogLevel::Warning);
    const auto scene = builtin(1);
    VlfSettings s;
    s.directionLevel = 4;
    s.linesPerSide = 64;
    s.iterations = 3;
    static const vlf::Vlf v = vlf::bakeVlf(*scene, s);
    std::vector<std::uint32_t> faces;
    for (std::uint32_t f = 0; f < v.faces().size(); ++f)
        if (v.specularIndex(f) >= 0) faces.push_back(f);
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    struct Query {
        std::uint32_t face;
        glm::vec3 x, view;
    };
    std::vector<Query> queries;
    for (int k = 0; k < 4096; ++k) {
        const std::uint32_t f = faces[std::size_t(k) % faces.size()];
        const vlf::Face& face = v.faces()[f];
        const glm::vec3 x =
            face.origin + u(rng) * face.extentU * face.axisU + u(rng) * face.extentV * face.axisV;
        const glm::vec3 view =
            glm::normalize(face.normal + glm::vec3(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f));
        queries.push_back({f, x, view});
    }
    std::size_t k = 0;
    for (auto _ : state) {
        const Query& q = queries[k++ & 4095];
        benchmark::DoNotOptimize(v.specularRadiance(q.face, q.x, q.view));
    }
}
BENCHMARK(Lookup);

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
