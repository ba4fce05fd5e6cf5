// ECS view iteration against a plain structure-of-arrays loop doing the same work, in the same
// run, so the ratio is meaningful on a noisy machine. Target: the view within 2x of the arrays.
#include "runtime/ecs/Registry.h"

#include <benchmark/benchmark.h>
#include <glm/vec3.hpp>

#include <vector>

namespace qgi {
namespace {

struct Position {
    glm::vec3 value{0.f};
};
struct Velocity {
    glm::vec3 value{1.f, 0.5f, 0.25f};
};

constexpr float kDt = 1.f / 60.f;

void BM_PlainArrays(benchmark::State& state) {
    const auto n = std::size_t(state.range(0));
    std::vector<glm::vec3> positions(n, glm::vec3(0.f));
    std::vector<glm::vec3> velocities(n, glm::vec3(1.f, 0.5f, 0.25f));
    for (auto _ : state) {
        for (std::size_t i = 0; i < n; ++i) positions[i] += velocities[i] * kDt;
        benchmark::DoNotOptimize(positions.data());
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(n));
}

void BM_RegistryView(benchmark::State& state) {
    const auto n = std::size_t(state.range(0));
    Registry registry;
    for (std::size_t i = 0; i < n; ++i) {
        const Entity e = registry.create();
        registry.emplace<Position>(e);
        registry.emplace<Velocity>(e);
    }
    auto view = registry.view<Position, const Velocity>();
    for (auto _ : state) {
        view.each([](Position& p, const Velocity& v) { p.value += v.value * kDt; });
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(n));
}

// Half the entities lack a Velocity: the view probes and skips them.
void BM_RegistryViewSparse(benchmark::State& state) {
    const auto n = std::size_t(state.range(0));
    Registry registry;
    for (std::size_t i = 0; i < n; ++i) {
        const Entity e = registry.create();
        registry.emplace<Position>(e);
        if (i % 2 == 0) registry.emplace<Velocity>(e);
    }
    auto view = registry.view<Position, const Velocity>();
    for (auto _ : state) {
        view.each([](Position& p, const Velocity& v) { p.value += v.value * kDt; });
        benchmark::ClobberMemory();
    }
    state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(n / 2));
}

BENCHMARK(BM_PlainArrays)->Arg(1 << 20)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RegistryView)->Arg(1 << 20)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RegistryViewSparse)->Arg(1 << 20)->Unit(benchmark::kMillisecond);

} // namespace
} // namespace qgi

BENCHMARK_MAIN();
