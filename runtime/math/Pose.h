#pragma once
// Which world matrices may place a mesh or a light: the one rule the ray scene, the renderer
// and the lighting systems share, so a pose one refuses the others refuse too.

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/mat4x4.hpp>
#include <glm/matrix.hpp>
#include <glm/vec3.hpp>

#include <cmath>

namespace qgi {

/// Metres: how far from the world origin a pose may put a mesh's origin, and how far a unit
/// of the mesh may reach (each axis's scale). Ten times the largest scene the importer
/// accepts; Embree asserts on ray origins past about 1.8e18 m, and float lighting is
/// meaningless long before. A mobile parked farther away is left where it was, with a warning.
inline constexpr float kMaxPoseReach = 1e7f;

/// Finite, invertible, and within kMaxPoseReach.
inline bool isUsablePose(const glm::mat4& m) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            if (!std::isfinite(m[c][r]) || std::abs(m[c][r]) > kMaxPoseReach) return false;
    const float det = glm::determinant(glm::mat3(m));
    return std::isfinite(det) && det != 0.f;
}

/// Where a point or spot light may shine from: finite and within kMaxPoseReach of the origin
/// on every axis, as a mesh's pose. Rays towards a light much farther (Embree asserts past
/// about 1.8e18 m) are meaningless; every system leaves such a light dark.
inline bool isUsableLightPosition(const glm::vec3& p) {
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(p[a]) || std::abs(p[a]) > kMaxPoseReach) return false;
    return true;
}

/// W/sr (W/m^2 for a sun, W/(m^2 sr) for an emissive surface): the brightest a light may be.
/// Past it float lighting overflows (a point light's radiance over the square of a distance of
/// a micrometre, summed over a probe's rays), so every system leaves such a light dark: the
/// importer takes at most 1e9 from a file, a game's code may set more.
inline constexpr float kMaxLightRadiance = 1e20f;

/// A light's colour times intensity every system can light with: finite, not negative, and
/// at most kMaxLightRadiance.
inline bool isUsableLightRadiance(const glm::vec3& radiance) {
    for (int c = 0; c < 3; ++c)
        if (!(radiance[c] >= 0.f && radiance[c] <= kMaxLightRadiance)) return false;
    return true;
}

/// Where a spot or directional light shines: its local -Z axis in world space (glTF's
/// convention), unit length, or zero where the pose collapses that axis (a scale of 0 along
/// it) or it is not finite. Every system leaves a light with no axis dark. The length is
/// taken in double, so a huge scale (1e20) still gives the axis.
inline glm::vec3 lightForward(const glm::mat4& world) {
    const glm::dvec3 z(world[2]);
    const double length = std::sqrt(glm::dot(z, z));
    return length > 0.0 && std::isfinite(length) ? glm::vec3(-z / length) : glm::vec3(0.f);
}

} // namespace qgi
