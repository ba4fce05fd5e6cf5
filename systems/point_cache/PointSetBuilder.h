#pragma once

#include "systems/point_cache/PointCacheSettings.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <vector>

namespace qgi {

class Registry;
class RayScene;
struct Aabb;
struct PointCache;

/// Why the dart throwing ended.
enum class PointSetStop : std::uint8_t { Rejections, DartBudget, PointBudget, NoSources };

/// What a build did (the stopping rule's inputs and the AO optimisation's effect).
struct PointSetStats {
    std::uint32_t particles = 0;      ///< light particles shot
    std::uint32_t sources = 0;        ///< hemispherical dart sources they left
    std::uint64_t darts = 0;          ///< darts thrown
    std::uint64_t misses = 0;         ///< darts that left the scene or hit a mobile
    std::uint64_t trivialAccepts = 0; ///< no point within rMax: accepted without AO
    std::uint64_t trivialRejects = 0; ///< a point within rMin: rejected without AO
    std::uint64_t aoCalls = 0;        ///< darts whose fate needed their AO
    std::uint32_t points = 0;
    PointSetStop stop = PointSetStop::Rejections;
};

/// A hemispherical dart source: a particle's hit on a static surface.
struct DartSource {
    glm::vec3 position{0.f}; ///< on the surface
    glm::vec3 normal{0.f};   ///< unit, the side the particle arrived from
};

/** Stage A1 (seed 003 section 1.1): light particles, shared among every light (punctual,
 *  directional and emissive surfaces, the photon emitters) in proportion to power, emitted
 *  with the photon emitters' sampling and bounced diffusely (cosine-weighted) particleBounces
 *  times; each hit on static geometry is a source. A particle that hits a mobile bounces on
 *  but leaves no source there. Deterministic: sources come in particle order.              */
std::vector<DartSource> makeDartSources(const Registry& registry, const RayScene& scene,
                                        const PointCacheSettings& resolved, const Aabb& bounds,
                                        std::uint32_t* particlesShot = nullptr);

/** Stage A2 (seed 003 section 1.2): dart d leaves source d mod S in a cosine-weighted
 *  direction; where it first lands on a static surface (mobiles and misses add nothing), with
 *  e the distance to the nearest point already accepted:
 *    e >= rMax: accept (trivial, no AO);  e < rMin: reject (trivial, no AO);
 *    else a = AO(hit), accept iff e >= spacingRadius(a).
 *  The point's normal faces the side the dart came from. A spatial hash of rMax cells finds e.
 *  Stopping rule: stopAfterRejections consecutive darts without a point, maxDarts, maxPoints.
 *  Darts are traced in parallel batches and AO is computed ahead in parallel for darts that
 *  will likely need it, but every decision is made in dart order against the points accepted
 *  so far, and AO is a pure function of (hit, dart index): the set is identical on any thread
 *  count and with or without the trivial tests (only stats.aoCalls changes).
 *  Fills cache.position, normal, dart, and (computed for every point after the throwing, in
 *  parallel) ao and radius = spacingRadius(ao). Logs progress.                              */
PointSetStats buildPointSet(const Registry& registry, const RayScene& scene,
                            const PointCacheSettings& resolved, const Aabb& bounds,
                            PointCache& cache);

/// World bounds of every StaticMesh (the point set's world), metres.
Aabb staticBounds(const Registry& registry);

} // namespace qgi
