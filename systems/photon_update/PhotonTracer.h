#pragma once

#include "runtime/raytrace/Hit.h"
#include "runtime/raytrace/Ray.h"
#include "systems/photon_update/PhotonHead.h"
#include "systems/photon_update/PhotonStore.h"

#include <glm/vec3.hpp>
#include <oneapi/tbb/enumerable_thread_specific.h>

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

namespace qgi {

class RayScene;

/** Traces photon paths through the RayScene (seed 000 section 3.1, seed 004 section 2).
 *
 *  Paths are traced in blocks, the blocks in parallel (oneTBB); within a block every live
 *  path's next ray goes into one batch that RayScene traces as 8-wide packets. At a hit the
 *  segment is stored and Russian roulette decides on the surface's albedo rho (RGB): the
 *  photon survives with p = max(rho) and its power is scaled by rho / p per channel, so the
 *  expected power per channel is rho times the incoming one (unbiased) while the strongest
 *  channel keeps its power (photons of near-equal power). A survivor leaves in a
 *  cosine-weighted direction about the geometric normal turned to the side it came from.
 *  A ray that hits nothing is stored with length +inf and ends the path; so does the hit after
 *  the last allowed bounce. A photon that leaves its light with no power (a light switched
 *  off) is not traced at all: its path has no segments.
 *
 *  The decisions at bounce b of photon i use photon::hashUniform of (seed, i, b, 0..2) only,
 *  so re-tracing a path from any stored segment through unchanged geometry reproduces the
 *  rest of it bit for bit.                                                                  */
class PhotonTracer {
public:
    struct Surfaces {
        std::uint64_t seed = 0;
        std::uint32_t maxBounces = 0;
        /// Diffuse albedo in [0, 1] of every mesh the ray scene holds, by Entity::index.
        std::span<const glm::vec3> albedo;
    };
    /// Head of path i, i in [0, count); called concurrently from the tracing threads.
    using HeadFn = std::function<PhotonHead(std::size_t)>;

    /// Traces `count` paths: appends path i's segments to `out`, and where they end in `out`
    /// to `ends`, which must end with out.size() on entry ({0} for an empty `out`): then path
    /// i's segments are [ends[k + i], ends[k + i + 1]) with k = the entry's ends.size() - 1.
    void trace(const RayScene& scene, const Surfaces& surfaces, std::size_t count,
               const HeadFn& head, PhotonSegments& out, std::vector<std::uint32_t>& ends);

private:
    /// One thread's working set for tracing a block. The slots stay with the thread, so they
    /// are in cache from one block to the next: a traced block's path i has its k-th segment
    /// in slots[k * n + i] (bounce-major, so that a wavefront's writes land together).
    struct Scratch {
        std::vector<PhotonHead> state;
        std::vector<std::uint32_t> active;
        std::vector<Ray> rays;
        std::vector<std::optional<Hit>> hits;
        PhotonSegments slots;
    };
    /// A traced block of paths, packed while the slots are still in cache: path i's segments
    /// are contiguous, after those of paths 0 .. i-1; counts[i] of them.
    struct Block {
        PhotonSegments segments;
        std::vector<std::uint32_t> counts;
        std::size_t start = 0; ///< where its segments go in the output
    };

    void traceBlock(const RayScene& scene, const Surfaces& surfaces, std::size_t begin,
                    std::size_t end, const HeadFn& head, Block& out);

    tbb::enumerable_thread_specific<Scratch> mScratch;
    std::vector<Block> mBlocks; // one round of blocks, kept to reuse their memory
};

} // namespace qgi
