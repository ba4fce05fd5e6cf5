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

/// Most neighbours a photon map query may gather: each query keeps that many candidates per
/// thread (Jensen's estimates use tens to hundreds; a billion asked for gigabytes).
inline constexpr std::uint32_t kMaxPhotonMapNeighbours = 65536;

struct DetpSettings {
    IrradianceEstimator estimator = IrradianceEstimator::Detp;
    /// Hybrid mode: the renderer draws the direct light of punctual lights (point, spot,
    /// directional) and of emissive surfaces with a LightStandIn, so the segments that leave
    /// one of those (bounce 0) are not counted and their photons carry only the light of later
    /// bounces. Other emissive surfaces' photons count in full: the renderer does not draw area
    /// lights. Photon mode (false) counts every segment.
    bool hybrid = false;
    /// DETP disc radius r, metres. 0: the scene default, defaultDiscRadius().
    float discRadius = 0.f;
    /// The photon count the default radius is chosen for (PhotonSettings::photonCount; the
    /// frame schedule fills it in). 0: the mesh-based rule alone.
    std::uint32_t photonCount = 0;
    /// Photon map: k, the number of nearest hit points per estimate.
    std::uint32_t photonMapNeighbours = 50; ///< 1 to kMaxPhotonMapNeighbours
    /// Photon map: the search stops growing at this radius, metres; where fewer than k hit points
    /// lie inside it, the estimate divides what it found by the area of this disc.
    /// 0: kPhotonMapRadiusPerDisc disc radii.
    float photonMapMaxRadius = 0.f;
    /// Drift bound of the incremental updates (see DetpIrradianceSystem): a vertex (triangle,
    /// for impact count) whose double-precision sum has taken this many additions since its
    /// last full estimate schedules a full re-estimate for the next frame.
    std::uint32_t maxIncrementalUpdates = 1u << 30;
    /// A moved mobile keeps a copy of the stored segments near it (NearSegments) over a box
    /// this share of its size wider on every side than its discs' reach, or more when it moves
    /// fast (neighbourhoodBox), so that the moves that follow
    /// read the copy instead of querying the path grid and walking the store; kept while that
    /// costs less than the walk (kNearCopiesPerWalkedPath). 0: no copy is kept, every move
    /// walks the store. At most 1.
    float nearSegmentMargin = 0.125f;
};

/// A mobile keeps a copy of the segments near it while it holds at most this many segments per
/// path its last walk read: each costs at most half as much a frame to keep up (apply, select)
/// as a candidate path costs to walk (ARCHITECTURE.md, "Copies of the segments near a mobile").
inline constexpr double kNearCopiesPerWalkedPath = 2.0;

/// Default search cap of the photon map, in disc radii: wide enough that k = 50 hit points are
/// found wherever a DETP disc would count about 3 or more segments.
inline constexpr float kPhotonMapRadiusPerDisc = 4.f;

/// Expected photon landings per disc the default radius aims for when photons are scarce:
/// with about two counted segments per landing that is a relative noise near 1/sqrt(128), 9%.
inline constexpr float kDefaultDiscLandings = 64.f;
/// A radius chosen by hand that catches fewer landings than this (with about two counted
/// segments per landing, a relative noise over a third) is warned about.
inline constexpr double kFewDiscLandings = 4.0;
/// A default radius wider than this share of the scene's diagonal is warned about.
inline constexpr float kMaxDefaultRadiusShare = 0.1f;

/// The default DETP disc radius, the larger of two rules:
///  - half the scene's mesh refinement bound (SceneInfo::maxEdgeLength), so a disc covers about
///    a vertex's own share of the surface. That is the seed's reference setting (r = 0.01 over
///    0.02 m triangles) and the size at which it found disc indexing fastest ("about the
///    triangle edge length"). A scene loaded without refinement falls back to 1% of its bounds
///    diagonal (the seed's reference, 0.01 of a unit scene).
///  - with `photons` > 0 and the receivers' total surface area `area` (m^2), the radius at which
///    photons spread evenly over every surface would land kDefaultDiscLandings times per disc:
///    sqrt(64 area / (pi photons)). Large scenes lit by few photons get wider discs (less
///    noise, more smoothing); the cornell box at 500k photons or more keeps r = 0.01.
/// The cost of an update grows with the discs a segment crosses (r^2): on the cornell box,
/// doubling r crosses 3.9x the discs at 2.4x the time, for half the noise. Throws qgi::Error
/// when the scene has neither an edge bound nor bounds.
float defaultDiscRadius(const SceneInfo& info, double area = 0.0, std::uint32_t photons = 0);

/// Throws qgi::Error naming the first field of `settings` that is out of range.
void validate(const DetpSettings& settings);

} // namespace qgi
