#pragma once

#include "systems/point_cache/PointCacheSettings.h"
#include "systems/point_cache/PointGrid.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <vector>

namespace qgi {

/// What the cache gives a shaded position: the blend of the points in range.
struct PointCacheSample {
    std::uint32_t count = 0; ///< points that took part; 0: no point in range (fallback)
    glm::vec3 direct{0.f};   ///< W/m^2: area lights with soft shadows
    glm::vec3 indirect{0.f}; ///< W/m^2: photon light after one or more bounces (DETP)
    float ao = 0.f;          ///< ambient occlusion, 0 open .. 1 fully occluded
    glm::vec3 irradiance() const { return direct + indirect; }
};

/// Most shadow samples per light whose outcomes each point keeps (one bit each,
/// PointCache::reached), so that a refresh re-traces only the lights a moved mobile may
/// shadow; with more samples every light of a refreshed point is traced again.
inline constexpr std::uint32_t kMaxRecordedShadowSamples = 64;

/// 32-bit words PointCache::reached holds per (point, light) for `shadowSamples` samples: 0
/// past kMaxRecordedShadowSamples.
inline std::uint32_t recordedShadowWords(std::uint32_t shadowSamples) {
    return shadowSamples <= kMaxRecordedShadowSamples ? (shadowSamples + 31) / 32 : 0;
}

/** World resource: the precalculated point set and the shading stored in it (seed 003).
 *  Points sit on static surfaces only; each has a unit normal facing the side light reaches,
 *  a spacing radius r_p in [rMin, rMax] and a search radius R_p = searchScale r_p.
 *  Positions never change after the build; only the shading arrays are rewritten (by
 *  PointCacheSystem), so queries are read-only and lock-free.
 *
 *  Blend at x with normal n (seed 003 section 1.7): over the points p in range (PointGrid),
 *  w_p = (1 - d_p / R_p)^k, value = sum w_p v_p / sum w_p: a convex combination. With no
 *  point in range the sample has count 0 and zero values: the caller falls back (the renderer
 *  to its per-vertex irradiance).                                                          */
struct PointCache {
    PointCacheSettings settings; ///< resolved (scene defaults filled in)

    // ---- the point set (built once) ---------------------------------------------------------
    std::vector<glm::vec3> position; ///< metres, world space, on a static surface
    std::vector<glm::vec3> normal;   ///< unit, world space, the lit side
    std::vector<float> radius;       ///< spacing radius r_p, metres
    std::vector<std::uint32_t> dart; ///< the dart that placed it: keys its random numbers

    // ---- stored shading ------------------------------------------------------------------------
    std::vector<float> ao;           ///< ambient occlusion in [0, 1] (static geometry)
    std::vector<glm::vec3> direct;   ///< W/m^2, area lights, shadowed (mobiles included)
    std::vector<glm::vec3> indirect; ///< W/m^2, DETP of photon segments after >= 1 bounce
    std::uint32_t lightCount = 0;    ///< area lights (emissive meshes) in `visibility`
    /// Unoccluded-irradiance-weighted visible fraction of light l at point p, in [0, 1]:
    /// visibility[p * lightCount + l] (1 where the light is below the horizon).
    std::vector<float> visibility;
    /// 32-bit words per (point, light) in `reached`: (shadowSamples + 31) / 32, or 0 where
    /// shadowSamples is over kMaxRecordedShadowSamples and nothing is recorded.
    std::uint32_t sampleWords = 0;
    /// Which shadow samples of light l reached it from point p when last traced: bit s % 32
    /// of reached[(p * lightCount + l) * sampleWords + s / 32] (replayAreaLight).
    std::vector<std::uint32_t> reached;

    PointGrid grid;
    /// Bumped whenever a shading array changes (the renderer re-uploads on a new value).
    std::uint64_t shadingVersion = 0;
    /// Bumped whenever the point set itself is (re)built or loaded.
    std::uint64_t pointSetVersion = 0;

    std::size_t size() const { return position.size(); }
    float searchRadius(std::uint32_t p) const { return settings.searchScale * radius[p]; }
    /// Weight of a point at distance d with search radius R (0 outside).
    float weight(float d, float R) const;
    /// (Re)builds the query grid from the point set and the settings.
    void buildGrid();
    /// The blend at x, unit normal n. Never NaN; thread safe.
    PointCacheSample sample(const glm::vec3& x, const glm::vec3& n) const;
};

} // namespace qgi
