#pragma once

#include <cstdint>
#include <string>

namespace qgi {

struct Aabb;

/// Scene defaults of the spacing radii (see PointCacheSettings::rMin, rMax).
inline constexpr float kRMaxPerDiagonal = 250.f;
/// Smallest rMax, as a share of the scene's farthest coordinate from the origin, that the
/// bake's grid can key (2^20 cells either side; just above 2^-20).
inline constexpr float kMinRadiusPerReach = 1e-6f;
inline constexpr float kRMaxPerRMin = 4.f;

/** Settings of the point cache (seed 003). The paper leaves every number open (digest section
 *  6); each choice is documented here with its reason. Lengths are metres; 0 in a length field
 *  means "the scene default" (resolvePointCacheSettings), scaled to the scene's bounds so the
 *  same settings serve a 1 m test box and the 36 m atrium.
 *  `validate(PointCacheSettings)` rejects absurd values with a qgi::Error naming the field. */
struct PointCacheSettings {
    // ---- construction (seed 003 section 1.1-1.3) -------------------------------------------
    /// Seeds every random choice of the build and of the shading fill.
    std::uint64_t seed = 1;
    /// Light particles shot to create dart sources, shared among the lights in proportion to
    /// their power (the photon emitters' rule).
    std::uint32_t particleCount = 16384;
    /// Diffuse (cosine-weighted) bounces per particle. Every hit of a particle on static
    /// geometry (up to particleBounces + 1 of them) becomes a hemispherical dart source facing
    /// the side the particle came from; the light's own emission point is not a source.
    /// Three bounces reach the light pools under galleries and the backs of arcades.
    std::uint32_t particleBounces = 3;
    /// Stopping rule: the build ends after this many consecutive darts that add no point (a
    /// saturated set: the chance that a dart finds room is then about 1 / stopAfterRejections),
    /// or at maxDarts darts, or at maxPoints points, whichever comes first.
    std::uint32_t stopAfterRejections = 20'000;
    std::uint64_t maxDarts = 20'000'000;
    std::uint32_t maxPoints = 200'000;
    /// Spacing radii r_min <= r(AO) <= r_max. 0: rMax = diagonal / kRMaxPerDiagonal (0.15 m on
    /// the atrium, about 100k points), rMin = rMax / kRMaxPerRMin.
    float rMin = 0.f;
    float rMax = 0.f;
    /// Ambient occlusion of a dart: the fraction of aoRays cosine-weighted rays from the hit
    /// that meet static geometry within aoDistance (mobiles are ignored: the set is static).
    /// 0: aoDistance = 2 rMax, so occlusion reacts to geometry within the reach of the coarsest
    /// spacing. 16 rays give AO in steps of 1/16 (radius steps of (rMax - rMin) / 16).
    std::uint32_t aoRays = 16;
    float aoDistance = 0.f;
    /// Trivial accept (no point within rMax) and trivial reject (a point within rMin) skip the
    /// AO of darts whose fate does not depend on it. Off only to test that they change nothing.
    bool trivialTests = true;

    // ---- query (seed 003 sections 1.6-1.7) --------------------------------------------------
    /// Search radius of point p: R_p = searchScale * r_p (per point, so the blend follows the
    /// adaptive density). 2: a dart-thrown set leaves no hole wider than about r_p, so every
    /// surface position lies within reach of a few points.
    float searchScale = 2.f;
    /// Weight of point p at distance d: (1 - d / R_p)^falloffExponent (1: the paper's linear
    /// C_p = R - d_p, normalised by R_p; 2 or 3: the quadratic / cubic falloff it mentions).
    std::uint32_t falloffExponent = 1;
    /// A point counts only where it faces the same way as the shaded surface (n_p . n >= this)
    /// and the shaded position lies within planeTolerance * R_p of its tangent plane: no light
    /// leaks through thin walls, across back-to-back surfaces or from a panel to the ceiling
    /// above it. 0.5 = 60 degrees; 0.5 R_p keeps neighbours on a 0.25 m column.
    float minNormalCosine = 0.5f;
    float planeTolerance = 0.5f;
    /// Edge of the query grid's cubic cells. 0: the mean search radius of the points.
    float gridCellSize = 0.f;

    // ---- stored shading (seed 003 section 1.4) ----------------------------------------------
    /// Shadow rays per point and area light (emissive mesh), stratified over the light's area
    /// (a sqrt x sqrt jittered grid when it is a square number).
    std::uint32_t shadowSamples = 16;
    /// DETP disc radius of the points' indirect irradiance. 0: 3 rMax (indirect light is low
    /// frequency; a disc three times wider counts nine times the photon segments, a third of
    /// the noise, where the vertices' default disc resolves a mesh edge).
    float detpRadius = 0.f;

    // ---- per-frame update -------------------------------------------------------------------
    /// Points whose soft shadows are re-traced per frame after a mobile moved, nearest to the
    /// mobile first; the rest wait for later frames.
    std::uint32_t updateBudget = 500;

    // ---- disk cache -------------------------------------------------------------------------
    /// Cache file; empty: build every time. A file whose key (scene + settings) or checksum
    /// does not match is reported, rebuilt and rewritten.
    std::string cacheFile;
};

/// Throws qgi::Error naming the first field that is out of range.
void validate(const PointCacheSettings& settings);

/// Copy with every 0-means-default length replaced by its scene value (bounds: the static
/// world). Throws qgi::Error when a default is needed and the bounds are empty, or when the
/// resolved radii are not ordered (rMin > rMax).
PointCacheSettings resolvePointCacheSettings(const PointCacheSettings& settings,
                                             const Aabb& bounds);

/// AO -> spacing radius: r(a) = rMax - a (rMax - rMin), a in [0, 1] clamped (1: fully
/// occluded, densest). Non-increasing, r(0) = rMax, r(1) = rMin.
float spacingRadius(float ao, float rMin, float rMax);

} // namespace qgi
