#include "systems/photon_update/PhotonSettings.h"

#include "runtime/core/Error.h"

#include <glm/vector_relational.hpp>

#include <cmath>

namespace qgi {
namespace {

// Segment indices are 32-bit (PhotonPath::first). The store holds up to (1 + region room +
// compactionFraction) times the live segments plus one frame of re-traced paths (under 2.5
// times, PhotonStoreSpace), so the worst case (every photon reaching maxBounces, the store
// grown to kMaxPhotonGrowth times photonCount) must fit four times over.
constexpr std::uint64_t kMaxStoredSegments = std::uint64_t(1) << 30;
constexpr std::uint32_t kMaxBounces = 255; // PhotonSegments::bounce is 8 bits
constexpr std::uint32_t kMaxGridResolution = 128;
/// Metres a side: the largest scene the glTF importer accepts (kSceneMaxSize).
constexpr float kMaxDirectionalExtent = 1e6f;

void checkFraction(float value, const char* field, float max) {
    if (!(value > 0.f && value <= max)) // NaN fails too
        fail("PhotonSettings.", field, " = ", value, " is not in (0, ", max, "]");
}

} // namespace

std::uint64_t maxPhotonCount(std::uint32_t maxBounces) {
    return kMaxStoredSegments / (kMaxPhotonGrowth * (std::uint64_t(maxBounces) + 1));
}

void validatePhotonSettings(const PhotonSettings& s) {
    if (s.maxBounces > kMaxBounces)
        fail("PhotonSettings.maxBounces = ", s.maxBounces, " is not in [0, ", kMaxBounces, "]");
    const std::uint64_t maxPhotons = maxPhotonCount(s.maxBounces);
    if (s.photonCount == 0 || s.photonCount > maxPhotons)
        fail("PhotonSettings.photonCount = ", s.photonCount, " is not in [1, ", maxPhotons,
             "] (the limit for maxBounces = ", s.maxBounces, ")");
    if (s.reshootBudget == 0) fail("PhotonSettings.reshootBudget = 0: moved lights never refresh");
    if (s.gridResolution == 0 || s.gridResolution > kMaxGridResolution)
        fail("PhotonSettings.gridResolution = ", s.gridResolution, " is not in [1, ",
             kMaxGridResolution, "]");
    if (s.gridRefreshBudget == 0)
        fail("PhotonSettings.gridRefreshBudget = 0: the path index would never catch up");
    checkFraction(s.compactionFraction, "compactionFraction", 1.f);
    if (!(s.nearPathMargin >= 0.f && s.nearPathMargin <= 1.f))
        fail("PhotonSettings.nearPathMargin = ", s.nearPathMargin,
             ": must be a share of a mobile's size from 0 (no near paths kept) to 1");
    const Aabb& box = s.directionalBounds;
    if (directionalBoundsSet(s)) { // set: a range on every axis
        for (int axis = 0; axis < 3; ++axis)
            if (!std::isfinite(box.min[axis]) || !std::isfinite(box.max[axis]) ||
                !(box.max[axis] - box.min[axis] >= 0.f) ||
                !(box.max[axis] - box.min[axis] <= kMaxDirectionalExtent))
                fail("PhotonSettings.directionalBounds: axis ", axis, " spans [", box.min[axis],
                     ", ", box.max[axis], "], not a finite range of at most ",
                     kMaxDirectionalExtent, " m");
        const glm::bvec3 flat = glm::equal(box.min, box.max);
        if (int(flat.x) + int(flat.y) + int(flat.z) >= 2)
            fail("PhotonSettings.directionalBounds: a line or a point, which no light covers");
    }
    if (!s.punctualLights && !s.emissiveSurfaces)
        fail("PhotonSettings: punctualLights and emissiveSurfaces are both off: nothing emits");
}

} // namespace qgi
