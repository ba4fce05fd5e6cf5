#pragma once

#include <glm/vec3.hpp>

#include <array>

namespace qgi {

/// Order-2 spherical harmonics of incident radiance at an avatar, W/(m^2 sr), linear RGB, in
/// the real basis of Ramamoorthi and Hanrahan over world (x, y, z), order
/// L00, L1-1, L10, L11, L2-2, L2-1, L20, L21, L22. All zero: unlit.
struct ShLighting {
    std::array<glm::vec3, 9> coefficients{};
};

} // namespace qgi
