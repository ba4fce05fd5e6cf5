#pragma once

#include <cstdint>

namespace qgi::reference {

/// How the brute-force Monte Carlo irradiance reference samples (IrradianceReference.h).
struct ReferenceSettings {
    /// Independent paths per point; at least 2, so the sample variance exists.
    std::uint32_t samplesPerPoint = 4096;
    /// Most diffuse reflections a path may make before it reaches the point. Russian roulette
    /// ends paths earlier without bias; the cap drops only longer paths: in a closed scene of
    /// uniform albedo rho, the fraction rho^(maxBounces + 1) of the light (1e-10 for rho = 0.7).
    std::uint32_t maxBounces = 64;
    std::uint64_t seed = 1;
    /// false: only light that reflected at least once on its way to the point, the part that
    /// photons carry in hybrid mode (the renderer draws the direct part).
    bool includeDirect = true;
    /// false: rays that leave the scene bring nothing, as in photon transport, which emits no
    /// photons from the sky. true: they bring SceneInfo::environment.
    bool includeEnvironment = true;
};

} // namespace qgi::reference
