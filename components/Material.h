#pragma once

#include <glm/vec3.hpp>

#include <cstdint>

namespace qgi {

/// Surface description (glTF metallic-roughness, read as the design's radiometric conventions).
struct Material {
    glm::vec3 baseColor{0.8f};     ///< diffuse albedo, linear RGB in [0, 1]
    glm::vec3 emission{0.f};       ///< emitted radiance, W/(m^2 sr), linear RGB
    float metallic = 0.f;          ///< 0 dielectric .. 1 metal (glossy / mirror surfaces)
    float roughness = 1.f;         ///< perceptual roughness; 0 is a mirror
    std::int32_t baseColorTexture = -1; ///< index into the TextureLibrary resource, -1: none
    /// Modified Phong specular reflectance k_s, linear RGB (the VLF's glossy and mirror part);
    /// zero for a purely diffuse surface. baseColor + specular must not exceed 1 per channel
    /// (the VLF refuses such a material).
    glm::vec3 specular{0.f};
    /// Modified Phong exponent n_s of the specular lobe; 0 means an ideal mirror.
    float phongExponent = 0.f;
};

} // namespace qgi
