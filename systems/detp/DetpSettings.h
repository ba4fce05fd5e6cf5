#pragma once

#include <cstdint>
#include <string_view>

namespace qgi {

struct SceneInfo;

/// How per-vertex irradiance is estimated from the photon ray set (seed 000 sections 2.4-2.7).
enum class IrradianceEstimator {
    Detp,        ///< density estimation on the tangent plane: the default
    ImpactCount, ///< hit power per triangle / triangle area, averaged at the vertices
    PhotonMap,   ///< Jensen's k-nearest radiance estimate over the hit points
};

/// "detp" | "impact" | "photonmap" (the demo's --estimator). Throws qgi::Error naming the
/// accepted values for anything else.
IrradianceEstimator parseIrradianceEstimator(std::string_view name);
std::string_view irradianceEstimatorName(IrradianceEstimator estimator);

struct DetpSettings {
    IrradianceEstimator estimator = IrradianceEstimator::Detp;
    /// Hybrid mode: the renderer draws the direct light of punctual lights (point, spot,
    /// directional), so the segments that leave one (bounce 0) are not counted and their photons
    /// carry only the light of later bounces. Emissive surfaces' photons count in full: the
    /// renderer does not draw area lights. Photon mode (false) counts every segment.
    bool hybrid = false;
    /// DETP disc radius r, metres. 0: the scene default, defaultDiscRadius(SceneInfo).
    float discRadius = 0.f;
    /// Photon map: k, the number of nearest hit points per estimate.
    std::uint32_t photonMapNeighbours = 50;
    /// Photon map: the search stops growing at this radius, metres; where fewer than k hit points
    /// lie inside it, the estimate divides what it found by the area of this disc.
    /// 0: kPhotonMapRadiusPerDisc disc radii.
    float photonMapMaxRadius = 0.f;
    /// Drift bound of the incremental updates (see DetpIrradianceSystem): a vertex (triangle,
    /// for impact count) whose double-precision sum has taken this many additions since its
    /// last full estimate schedules a full re-estimate for the next frame.
    std::uint32_t maxIncrementalUpdates = 1u << 24;
};

/// Default search cap of the photon map, in disc radii: wide enough that k = 50 hit points are
/// found wherever a DETP disc would count about 3 or more segments.
inline constexpr float kPhotonMapRadiusPerDisc = 4.f;

/// The default DETP disc radius: half the scene's mesh refinement bound
/// (SceneInfo::maxEdgeLength), so a disc covers about a vertex's own share of the surface.
/// That is the seed's reference setting (r = 0.01 over 0.02 m triangles) and the size at which
/// it found disc indexing fastest ("about the triangle edge length"). The cost of an update
/// grows with the discs a segment crosses, about 4 r^2 / maxEdgeLength^2 of them here: on the
/// cornell box, r = maxEdgeLength crosses 7.8 per segment at 2.4x the cost of r = maxEdgeLength / 2
/// (2 per segment), for half the noise. A scene loaded without refinement falls back to 1% of
/// its bounds diagonal (the seed's reference, 0.01 of a unit scene). Throws qgi::Error when the
/// scene has neither (empty bounds).
float defaultDiscRadius(const SceneInfo& info);

/// Throws qgi::Error naming the first field of `settings` that is out of range.
void validate(const DetpSettings& settings);

} // namespace qgi
