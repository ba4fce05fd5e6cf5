#include "systems/point_cache/PointCacheSettings.h"

#include "runtime/core/Error.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/geometric.hpp>
#include <glm/gtx/component_wise.hpp>

#include <algorithm>
#include <cmath>

namespace qgi {
namespace {

void checkLength(const char* field, float value) {
    if (!std::isfinite(value) || value < 0.f)
        fail("PointCacheSettings.", field, " = ", value,
             ": must be a finite number of metres >= 0 (0: scene default)");
}

} // namespace

void validate(const PointCacheSettings& s) {
    if (s.particleCount == 0 || s.particleCount > 100'000'000u)
        fail("PointCacheSettings.particleCount = ", s.particleCount, ": must be in [1, 1e8]");
    if (s.particleBounces > 64)
        fail("PointCacheSettings.particleBounces = ", s.particleBounces, ": must be at most 64");
    if (s.stopAfterRejections == 0)
        fail("PointCacheSettings.stopAfterRejections = 0: must be at least 1");
    if (s.maxDarts == 0 || s.maxDarts > 4'000'000'000ull)
        fail("PointCacheSettings.maxDarts = ", s.maxDarts, ": must be in [1, 4e9]");
    if (s.maxPoints == 0 || s.maxPoints > 50'000'000u)
        fail("PointCacheSettings.maxPoints = ", s.maxPoints, ": must be in [1, 5e7]");
    checkLength("rMin", s.rMin);
    checkLength("rMax", s.rMax);
    if (s.rMin > 0.f && s.rMax > 0.f && s.rMin > s.rMax)
        fail("PointCacheSettings.rMin = ", s.rMin, " exceeds rMax = ", s.rMax);
    if (s.aoRays == 0 || s.aoRays > 4096)
        fail("PointCacheSettings.aoRays = ", s.aoRays, ": must be in [1, 4096]");
    checkLength("aoDistance", s.aoDistance);
    if (!std::isfinite(s.searchScale) || s.searchScale < 1.f || s.searchScale > 16.f)
        fail("PointCacheSettings.searchScale = ", s.searchScale,
             ": must be in [1, 16] (below 1 the blend leaves holes between points)");
    if (s.falloffExponent < 1 || s.falloffExponent > 3)
        fail("PointCacheSettings.falloffExponent = ", s.falloffExponent, ": must be 1, 2 or 3");
    if (!(s.minNormalCosine >= -1.f && s.minNormalCosine <= 1.f))
        fail("PointCacheSettings.minNormalCosine = ", s.minNormalCosine, ": must be in [-1, 1]");
    if (!(s.planeTolerance > 0.f && s.planeTolerance <= 1.f))
        fail("PointCacheSettings.planeTolerance = ", s.planeTolerance, ": must be in (0, 1]");
    checkLength("gridCellSize", s.gridCellSize);
    if (s.shadowSamples == 0 || s.shadowSamples > 16384)
        fail("PointCacheSettings.shadowSamples = ", s.shadowSamples, ": must be in [1, 16384]");
    checkLength("detpRadius", s.detpRadius);
    if (s.updateBudget == 0)
        fail("PointCacheSettings.updateBudget = 0: must be at least 1 point per frame");
}

PointCacheSettings resolvePointCacheSettings(const PointCacheSettings& settings,
                                             const Aabb& bounds) {
    validate(settings);
    PointCacheSettings s = settings;
    const bool needsScene = s.rMax == 0.f || s.rMin == 0.f;
    if (needsScene) {
        const float diagonal = bounds.empty() ? 0.f : glm::length(bounds.extent());
        if (!(diagonal > 0.f) || !std::isfinite(diagonal))
            fail("point cache: the static world is empty, so there is no default spacing "
                 "radius (set PointCacheSettings.rMin and rMax)");
        if (s.rMax == 0.f) s.rMax = std::max(s.rMin, diagonal / kRMaxPerDiagonal);
        if (s.rMin == 0.f) s.rMin = s.rMax / kRMaxPerRMin;
    }
    if (s.rMin > s.rMax) fail("PointCacheSettings: rMin = ", s.rMin, " exceeds rMax = ", s.rMax);
    // The bake's grid of rMax cells keys 2^20 cells either side of the origin along each axis.
    const float reach =
        bounds.empty() ? 0.f : glm::compMax(glm::max(glm::abs(bounds.min), glm::abs(bounds.max)));
    if (std::isfinite(reach) && s.rMax < kMinRadiusPerReach * reach)
        fail("PointCacheSettings.rMax = ", s.rMax, " m is below a millionth of the scene's ", reach,
             " m reach from the origin: the bake cannot index so fine a spacing");
    if (s.aoDistance == 0.f) s.aoDistance = 2.f * s.rMax;
    if (s.detpRadius == 0.f) s.detpRadius = 3.f * s.rMax;
    return s;
}

float spacingRadius(float ao, float rMin, float rMax) {
    const float a = std::clamp(std::isfinite(ao) ? ao : 1.f, 0.f, 1.f);
    // Each rounding step is monotone, so the map is; a = 1 is pinned to rMin exactly.
    return a >= 1.f ? rMin : std::clamp(rMax - a * (rMax - rMin), rMin, rMax);
}

} // namespace qgi
