#pragma once

#include <glm/vec3.hpp>

#include <cstdint>

namespace qgi {

/// Where a photon's path (or the re-traced rest of it) starts: the first segment's ray and
/// power, and the photon's index, which keys every random choice after it.
struct PhotonHead {
    glm::vec3 origin{0.f};    ///< metres, world space
    glm::vec3 direction{0.f}; ///< unit, world space
    glm::vec3 power{0.f};     ///< W, linear RGB
    std::uint32_t photon = 0;
    std::uint8_t bounce = 0; ///< reflections before this segment
};

/// Whether `power` (W, linear RGB) is any light at all: a light that is on, a photon worth
/// tracing from it.
inline bool carriesPower(const glm::vec3& power) {
    return power.x > 0.f || power.y > 0.f || power.z > 0.f;
}

} // namespace qgi
