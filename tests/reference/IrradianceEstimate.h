#pragma once

#include <glm/vec3.hpp>

namespace qgi::reference {

/// A Monte Carlo estimate of irradiance, W/m^2, linear RGB.
struct IrradianceEstimate {
    glm::dvec3 mean{0.0};
    /// Per channel: sample standard deviation / sqrt(samples). The mean is normally distributed
    /// around the true value with this spread (central limit theorem).
    glm::dvec3 standardError{0.0};
};

} // namespace qgi::reference
