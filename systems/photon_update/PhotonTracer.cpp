#include "systems/photon_update/PhotonTracer.h"

#include "runtime/core/Error.h"
#include "runtime/raytrace/RayScene.h"
#include "systems/photon_update/PhotonSampling.h"

#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <limits>

namespace qgi {
namespace {

// Paths per block: enough live rays for full 8-wide packets over several bounces; a round of
// blocks is traced in parallel, then appended in order (deterministic layout). A round holds
// at least kBlocksPerThread blocks per worker, so that the blocks' uneven lengths even out
// before the round's end waits for the last of them.
constexpr std::size_t kMaxBlockPaths = 256;
constexpr std::size_t kMinBlockPaths = 32;
constexpr std::size_t kMinBlocksPerRound = 32;
constexpr std::size_t kBlocksPerThread = 16;

std::size_t blocksPerRound() {
    return std::max(kMinBlocksPerRound,
                    kBlocksPerThread * std::size_t(tbb::this_task_arena::max_concurrency()));
}

/// Continues photon `h` after `hit`: Russian roulette, then the reflected ray. False when the
/// path ends here.
bool reflect(const PhotonTracer::Surfaces& surfaces, const Hit& hit, PhotonHead& h) {
    if (h.bounce >= surfaces.maxBounces) return false;
    const std::uint32_t index = hit.entity.index;
    const glm::vec3 albedo =
        index < surfaces.albedo.size() ? surfaces.albedo[index] : glm::vec3(0.f);
    const float survival = std::max({albedo.x, albedo.y, albedo.z});
    const std::uint64_t key = photon::mixBits(surfaces.seed);
    if (!(photon::hashUniform(key, h.photon, h.bounce, 0) < survival)) return false;
    h.power *= albedo / survival;
    const glm::vec3 facing = glm::dot(hit.normal, h.direction) > 0.f ? -hit.normal : hit.normal;
    const glm::vec3 point = h.origin + hit.t * h.direction;
    h.direction =
        photon::sampleCosine(photon::Frame(facing), photon::hashUniform(key, h.photon, h.bounce, 1),
                             photon::hashUniform(key, h.photon, h.bounce, 2));
    h.origin = photon::offsetFromSurface(point, facing);
    ++h.bounce;
    return true;
}

} // namespace

void PhotonTracer::traceBlock(const RayScene& scene, const Surfaces& surfaces, std::size_t begin,
                              std::size_t end, const HeadFn& head, Block& out) {
    Scratch& s = mScratch.local();
    const std::size_t n = end - begin;
    const std::size_t slotsPerPath = std::size_t(surfaces.maxBounces) + 1;
    s.state.resize(n);
    s.active.resize(n);
    s.rays.resize(n);
    s.hits.resize(n);
    out.counts.assign(n, 0);
    if (s.slots.size() < n * slotsPerPath) s.slots.resize(n * slotsPerPath);
    // A photon that leaves its light with no power (the light is dark) is not traced: its path
    // is empty. Later in a path power may drop to zero (a red photon on a green wall); such
    // a path is traced on as it always was, so that a re-traced suffix matches a fresh shot.
    std::size_t live = 0;
    for (std::size_t i = 0; i < n; ++i) {
        s.state[i] = head(begin + i);
        const PhotonHead& h = s.state[i];
        if (h.bounce > 0 || carriesPower(h.power)) s.active[live++] = std::uint32_t(i);
    }

    PhotonSegments& slots = s.slots;
    while (live > 0) {
        for (std::size_t j = 0; j < live; ++j) {
            const PhotonHead& h = s.state[s.active[j]];
            s.rays[j] = Ray{h.origin, 0.f, h.direction, std::numeric_limits<float>::infinity()};
        }
        scene.intersect(std::span<const Ray>(s.rays.data(), live),
                        std::span<std::optional<Hit>>(s.hits.data(), live));
        std::size_t next = 0;
        for (std::size_t j = 0; j < live; ++j) {
            const std::uint32_t i = s.active[j];
            PhotonHead& h = s.state[i];
            // Bounce-major slots: a wavefront's writes land close together.
            const std::size_t slot = std::size_t(out.counts[i]++) * n + i;
            slots.origin[slot] = h.origin;
            slots.direction[slot] = h.direction;
            slots.power[slot] = h.power;
            slots.bounce[slot] = h.bounce;
            const std::optional<Hit>& hit = s.hits[j];
            if (!hit) {
                slots.length[slot] = std::numeric_limits<float>::infinity();
                slots.hitEntity[slot] = kNullEntity;
                slots.hitPrimitive[slot] = 0;
                continue;
            }
            slots.length[slot] = hit->t;
            slots.hitEntity[slot] = hit->entity;
            slots.hitPrimitive[slot] = hit->primitive;
            if (reflect(surfaces, *hit, h)) s.active[next++] = i;
        }
        live = next;
    }

    // Pack path by path while the slots are in cache.
    std::size_t total = 0;
    for (const std::uint32_t c : out.counts)
        total += c;
    PhotonSegments& packed = out.segments;
    packed.resize(total);
    for (std::size_t i = 0, to = 0; i < n; ++i)
        for (std::size_t k = 0; k < out.counts[i]; ++k, ++to) {
            const std::size_t slot = k * n + i;
            packed.origin[to] = slots.origin[slot];
            packed.direction[to] = slots.direction[slot];
            packed.length[to] = slots.length[slot];
            packed.power[to] = slots.power[slot];
            packed.hitEntity[to] = slots.hitEntity[slot];
            packed.hitPrimitive[to] = slots.hitPrimitive[slot];
            packed.bounce[to] = slots.bounce[slot];
        }
}

void PhotonTracer::trace(const RayScene& scene, const Surfaces& surfaces, std::size_t count,
                         const HeadFn& head, PhotonSegments& out,
                         std::vector<std::uint32_t>& ends) {
    // Small jobs (a frame's re-traced paths) still split into a few blocks per thread.
    const std::size_t roundBlocks = blocksPerRound();
    const std::size_t blockPaths = std::clamp(count / roundBlocks, kMinBlockPaths, kMaxBlockPaths);
    QGI_ASSERT(!ends.empty() && ends.back() == out.size(), "ends must end with out.size()");
    if (mBlocks.size() < roundBlocks) mBlocks.resize(roundBlocks);
    ends.reserve(ends.size() + count);
    const std::size_t outStart = out.size();
    for (std::size_t round = 0; round < count; round += blockPaths * roundBlocks) {
        const std::size_t roundEnd = std::min(count, round + blockPaths * roundBlocks);
        const std::size_t blocks = (roundEnd - round + blockPaths - 1) / blockPaths;
        tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t b) {
            const std::size_t begin = round + b * blockPaths;
            traceBlock(scene, surfaces, begin, std::min(roundEnd, begin + blockPaths), head,
                       mBlocks[b]);
        });
        // Where each block's segments go (a serial sum over the blocks only), then each block's
        // path ends and copy, in parallel.
        std::size_t roundOut = out.size();
        for (std::size_t b = 0; b < blocks; ++b) {
            mBlocks[b].start = roundOut;
            roundOut += mBlocks[b].segments.size();
        }
        if (round == 0 && roundEnd < count) {
            // Grow the output once, to the first round's segments per path times the paths
            // and a sixteenth more, instead of doubling it (and copying it) along the way.
            const double perPath = double(roundOut - outStart) / double(roundEnd);
            out.reserve(outStart + std::size_t(perPath * double(count) * (1.0 + 1.0 / 16.0)));
        }
        const std::size_t firstEnd = ends.size();
        ends.resize(firstEnd + (roundEnd - round));
        out.resize(roundOut);
        tbb::parallel_for(std::size_t(0), blocks, [&](std::size_t b) {
            const Block& block = mBlocks[b];
            std::uint32_t end = std::uint32_t(block.start);
            std::uint32_t* blockEnds = ends.data() + firstEnd + b * blockPaths;
            for (std::size_t i = 0; i < block.counts.size(); ++i)
                blockEnds[i] = end += block.counts[i];
            out.copyFrom(block.start, block.segments, 0, block.segments.size());
        });
    }
}

} // namespace qgi
