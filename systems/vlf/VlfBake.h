#pragma once

#include "systems/vlf/Vlf.h"
#include "systems/vlf/VlfScene.h"
#include "systems/vlf/VlfSettings.h"

#include <glm/vec3.hpp>

#include <vector>

namespace qgi::vlf {

/// Flux bookkeeping of one propagation iteration, W (RGB, double precision sums).
struct VlfIterationStats {
    glm::dvec3 sent{0.0};            ///< leaving senders along every line that has a receiver
    glm::dvec3 received{0.0};        ///< arriving at receivers (from senders and the environment)
    glm::dvec3 escaped{0.0};         ///< leaving senders along lines with nothing beyond
    glm::dvec3 fromEnvironment{0.0}; ///< arriving from the environment (first iteration only)
    /// Sum over texels of (received irradiance x texel area x coverage), before the filter:
    /// equals `received` when no deposit was lost.
    glm::dvec3 deposited{0.0};
    glm::dvec3 reflectedDiffuse{0.0}; ///< k_d x deposited: what the next iteration shoots
    std::size_t lostDeposits = 0;     ///< deposits with no covered texel nearby (dropped)
    double seconds = 0.0;
    double gatherSeconds = 0.0; ///< of which the specular (mirror and glossy) gather
};

struct VlfBakeStats {
    std::vector<VlfIterationStats> iterations;
    double directSeconds = 0.0; ///< the point/spot direct-light pass
    double seconds = 0.0;       ///< the whole bake, allocation included
    std::size_t lines = 0;      ///< lines traced over all iterations
    std::size_t crossings = 0;  ///< crossings found on them
    /// Lines with more crossings than the bake keeps (kMaxLineCrossings): their crossings
    /// beyond it are dropped, and their far end exchanges nothing.
    std::size_t truncatedLines = 0;
};

/// Most crossings of one line the bake keeps, in depth order.
inline constexpr std::size_t kMaxLineCrossings = 256;

/** The bake of seed 002 (chapter 4-5; digest section 2), on the CPU with oneTBB.
 *
 *  Visibility: every line of every subfield is traced once per iteration with Embree,
 *  collecting all its crossings in depth order (repeated intersect-and-advance); consecutive
 *  crossings (a, b) with a facing along the line and b facing against it exchange light both
 *  ways (the thesis's exchange lists, section 4.3.2, in O(crossings) per line). Back faces
 *  block. A line's first crossing facing against it receives the environment.
 *
 *  Order: a direct-light pass for point, spot and directional lights (shadow rays to texel
 *  centres and to glossy cells), then `iterations` passes. Each pass, for every subfield (in
 * parallel), for each jittered direction in its cell: senders emit emission (first pass) + k_d / pi
 * x unshot irradiance + unshot specular tile radiance; receivers deposit flux L * A_line * dOmega
 * into their irradiance map and, for specular faces, record the incident radiance in their tiles.
 *  Then every specular cell gathers its outgoing radiance: a mirror takes k_s times the
 *  incident light around the mirrored direction (12-tap), a glossy face sums the modified
 *  Phong lobe over the incident subfields. The received irradiance is filtered and becomes
 *  the next pass's unshot light; totals accumulate.
 *
 *  Deterministic: jitter is seeded per (seed, iteration, subfield), and sums are reduced in
 *  a fixed order. Throws qgi::Error on bad settings.                                        */
Vlf bakeVlf(const VlfScene& scene, const VlfSettings& settings, VlfBakeStats* stats = nullptr);

} // namespace qgi::vlf
