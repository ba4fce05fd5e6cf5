#include "systems/sh_probes/ShProbeSettings.h"

#include "runtime/core/Error.h"
#include "runtime/core/Finite.h"
#include "runtime/scene/SceneInfo.h"

#include <algorithm>
#include <cmath>

namespace qgi {

void validate(const ShProbeSettings& s) {
    if (!std::isfinite(s.spacing) || s.spacing < 0.f || (s.spacing > 0.f && s.spacing < 1e-4f))
        fail("ShProbeSettings.spacing = ", s.spacing,
             ": must be 0 (scene default) or a finite number of metres >= 1e-4");
    if (s.cellsAlongLongestAxis < 1 || s.cellsAlongLongestAxis > 4096)
        fail("ShProbeSettings.cellsAlongLongestAxis = ", s.cellsAlongLongestAxis,
             ": must be in [1, 4096]");
    if (s.maxProbes < 8 || s.maxProbes > (1u << 26))
        fail("ShProbeSettings.maxProbes = ", s.maxProbes, ": must be in [8, 2^26]");
    if (s.raysPerProbe < 16 || s.raysPerProbe > 65536)
        fail("ShProbeSettings.raysPerProbe = ", s.raysPerProbe, ": must be in [16, 65536]");
    if (!(s.backFaceShare > 0.f && s.backFaceShare <= 1.f))
        fail("ShProbeSettings.backFaceShare = ", s.backFaceShare, ": must be in (0, 1]");
    if (s.updateBudget > (1u << 24))
        fail("ShProbeSettings.updateBudget = ", s.updateBudget, ": must be at most 2^24");
    if (s.sweepPerFrame > (1u << 24))
        fail("ShProbeSettings.sweepPerFrame = ", s.sweepPerFrame, ": must be at most 2^24");
    if (!std::isfinite(s.influenceDistance) || s.influenceDistance < 0.f)
        fail("ShProbeSettings.influenceDistance = ", s.influenceDistance,
             ": must be a finite number of metres >= 0 (0: twice the spacing)");
    if (!(s.mobileSolidAngleShare > 0.f && s.mobileSolidAngleShare <= 1.f))
        fail("ShProbeSettings.mobileSolidAngleShare = ", s.mobileSolidAngleShare,
             ": must be in (0, 1]");
    if (s.minDeltaEndPoints < 1 || s.minDeltaEndPoints > 65535)
        fail("ShProbeSettings.minDeltaEndPoints = ", s.minDeltaEndPoints,
             ": must be in [1, 65535]");
    if (s.visibilitySubdivisions < 1 || s.visibilitySubdivisions > 16)
        fail("ShProbeSettings.visibilitySubdivisions = ", s.visibilitySubdivisions,
             ": must be in [1, 16]");
}

float resolveProbeSpacing(const ShProbeSettings& settings, const Aabb& bounds) {
    if (settings.spacing > 0.f) return settings.spacing;
    if (bounds.empty() || !isFinite(bounds.min) || !isFinite(bounds.max))
        fail("SH probes: the scene bounds are empty or not finite, so there is no default probe "
             "spacing (set ShProbeSettings.spacing)");
    const glm::vec3 extent = bounds.extent();
    const float longest = std::max({extent.x, extent.y, extent.z});
    if (!(longest > 0.f))
        fail("SH probes: the scene bounds have no extent, so there is no default probe spacing "
             "(set ShProbeSettings.spacing)");
    return longest / float(settings.cellsAlongLongestAxis);
}

} // namespace qgi
