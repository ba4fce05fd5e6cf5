#pragma once

#include "runtime/ecs/Entity.h"
#include "tests/reference/IrradianceEstimate.h"

#include <glm/vec3.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace qgi {
class Registry;
class RayScene;
} // namespace qgi

namespace qgi::reference {

/// A mesh vertex in world space, with the irradiance the system under test gave it.
struct VertexSample {
    glm::vec3 position{0.f}, normal{0.f};
    glm::vec3 irradiance{0.f}; ///< VertexIrradiance, W/m^2 (zero when the entity has none)
    Entity mesh;               ///< the entity whose vertex it is
};

/// Whether a vertex's disc neighbourhood is an open plane: no surface within 2r along its
/// tangent plane (8 directions) or above it. Vertices in corners, under blocks or behind the
/// luminaire see geometry a plain tangent disc does not account for (seed 000's "reachable
/// area" problem), so accuracy checks leave them out.
bool openNeighbourhood(const RayScene& scene, const glm::vec3& x, const glm::vec3& n, float r);

/// `count` static vertices with open neighbourhoods at radius r, spread evenly over the list of
/// all such vertices in entity order (fewer when the scene has fewer).
std::vector<VertexSample> openStaticVertices(const Registry& registry, const RayScene& scene,
                                             float r, std::size_t count);
/// The same over the vertices of mobile meshes, where they stand now, and only where their
/// surface goes on for 2r all around (not near a block's rim, which static rooms close off).
std::vector<VertexSample> openMobileVertices(const Registry& registry, const RayScene& scene,
                                             float r, std::size_t count);

/// The Monte Carlo reference at each sample's position and normal, `paths` paths each, without
/// sky light (photons are not emitted by the sky, so photon transport has none either).
/// includeDirect = false leaves out the light that reaches the point without a reflection:
/// what photons carry in hybrid mode.
std::vector<IrradianceEstimate> photonReferenceAt(const Registry& registry, const RayScene& scene,
                                                  std::span<const VertexSample> samples,
                                                  std::uint32_t paths, bool includeDirect = true);

/// The p-quantile (0..1) of `values` by the nearest-rank rule; 0 for an empty list.
double percentile(std::vector<double> values, double p);

/// Estimates against reference values (summed RGB, W/m^2) over points: the median and 90th
/// percentile of |estimate - reference| / reference, and the summed estimate over the summed
/// reference minus 1. Points whose reference is not positive, or whose estimate is NaN (none
/// available), are left out.
struct ErrorSummary {
    double median = 0, p90 = 0, sum = 0;
    std::size_t points = 0;
};
ErrorSummary summariseErrors(const std::vector<double>& estimates,
                             const std::vector<double>& references);

} // namespace qgi::reference
