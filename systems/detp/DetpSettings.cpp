#include "systems/detp/DetpSettings.h"

#include "runtime/core/Error.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include <algorithm>
#include <cmath>

namespace qgi {

IrradianceEstimator parseIrradianceEstimator(std::string_view name) {
    if (name == "detp") return IrradianceEstimator::Detp;
    if (name == "impact") return IrradianceEstimator::ImpactCount;
    if (name == "photonmap") return IrradianceEstimator::PhotonMap;
    fail("unknown irradiance estimator '", name, "' (expected detp, impact or photonmap)");
}

std::string_view irradianceEstimatorName(IrradianceEstimator estimator) {
    switch (estimator) {
    case IrradianceEstimator::Detp:
        return "detp";
    case IrradianceEstimator::ImpactCount:
        return "impact";
    case IrradianceEstimator::PhotonMap:
        return "photonmap";
    }
    return "?";
}

float defaultDiscRadius(const SceneInfo& info, double area, std::uint32_t photons) {
    float radius = 0.f;
    if (info.maxEdgeLength > 0.f && std::isfinite(info.maxEdgeLength)) {
        radius = 0.5f * info.maxEdgeLength;
    } else {
        const float diagonal = info.bounds.empty() ? 0.f : glm::length(info.bounds.extent());
        if (!(diagonal > 0.f) || !std::isfinite(diagonal))
            fail("SceneInfo of '", info.name,
                 "': no maxEdgeLength and empty bounds, so there is no default DETP disc radius "
                 "(set DetpSettings.discRadius)");
        radius = 0.01f * diagonal;
    }
    if (photons > 0 && area > 0.0 && std::isfinite(area))
        radius = std::max(radius, float(std::sqrt(double(kDefaultDiscLandings) * area /
                                                  (glm::pi<double>() * double(photons)))));
    return radius;
}

void validate(const DetpSettings& settings) {
    if (!std::isfinite(settings.discRadius) || settings.discRadius < 0.f)
        fail("DetpSettings.discRadius = ", settings.discRadius,
             ": must be a finite number of metres >= 0 (0: scene default)");
    if (settings.estimator != IrradianceEstimator::Detp &&
        settings.estimator != IrradianceEstimator::ImpactCount &&
        settings.estimator != IrradianceEstimator::PhotonMap)
        fail("DetpSettings.estimator = ", int(settings.estimator),
             " is none of detp, impact or photonmap");
    if (settings.photonMapNeighbours == 0 || settings.photonMapNeighbours > kMaxPhotonMapNeighbours)
        fail("DetpSettings.photonMapNeighbours = ", settings.photonMapNeighbours,
             ": the photon map takes 1 to ", kMaxPhotonMapNeighbours, " neighbours");
    if (!std::isfinite(settings.photonMapMaxRadius) || settings.photonMapMaxRadius < 0.f)
        fail("DetpSettings.photonMapMaxRadius = ", settings.photonMapMaxRadius,
             ": must be a finite number of metres >= 0 (0: default)");
    if (settings.maxIncrementalUpdates == 0)
        fail("DetpSettings.maxIncrementalUpdates = 0: must be at least 1");
    if (!(settings.nearSegmentMargin >= 0.f && settings.nearSegmentMargin <= 1.f))
        fail("DetpSettings.nearSegmentMargin = ", settings.nearSegmentMargin,
             ": must be a share of a mobile's size from 0 (no copy) to 1");
}

} // namespace qgi
