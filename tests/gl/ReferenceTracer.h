#pragma once
// An independent CPU renderer for the GL image tests. Per pixel centre it finds the nearest
// triangle along the camera ray (Moller-Trumbore in double precision on every triangle a
// bounding volume hierarchy cannot rule out) and shades direct light analytically with a hard
// shadow ray. It shares no code with the renderer: only the physics
// (radiance = albedo / pi * E + emission) and the documented light conventions.

#include "runtime/io/ImageF.h"

#include <glm/mat3x3.hpp>
#include <glm/vec3.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

namespace qgi::test {

struct RefTriangle {
    glm::dvec3 p0, p1, p2; ///< world, metres
    glm::dvec3 normal;     ///< unit, world; the side facing the camera is shaded
    glm::dvec3 albedo;
    /// Convex surface the triangle belongs to (a planar face, a box, a capsule): it never
    /// shadows itself; a light behind the triangle's own plane is hidden by it.
    int surface = 0;
    glm::dvec3 emission{0.0}; ///< W/(m^2 sr), added to the reflected radiance
    /// Unit shading normals at p0, p1, p2, interpolated across the triangle (a smooth mesh);
    /// none: shaded with `normal`.
    std::optional<std::array<glm::dvec3, 3>> vertexNormals = std::nullopt;
};

enum class RefLightType { Point, Spot, Directional };

struct RefLight {
    RefLightType type = RefLightType::Point;
    glm::dvec3 position{0.0};
    glm::dvec3 direction{0.0, 0.0, -1.0}; ///< spot axis / direction the light travels
    glm::dvec3 radiance{1.0};             ///< W/sr, or W/m^2 for directional
    double innerCone = 0.0, outerCone = 0.0;
};

/// A pinhole camera at `position` looking along its local -Z with local Y up.
struct RefCamera {
    glm::dvec3 position{0.0};
    double yfov = 0.9; ///< radians
    int width = 0, height = 0;
    glm::dmat3 orientation{1.0}; ///< camera to world rotation
};

struct RefImage {
    ImageF radiance;                ///< W/(m^2 sr), rows top to bottom
    std::vector<std::uint32_t> key; ///< per pixel: surface and which lights are unoccluded
};

RefImage traceReference(const std::vector<RefTriangle>& triangles,
                        const std::vector<RefLight>& lights, const RefCamera& camera);

/// Pixels whose 3x3 neighbourhood sees another surface or another set of unoccluded lights:
/// where rasterization against ray casting and shadow maps against shadow rays may disagree.
std::vector<bool> discontinuities(const RefImage& image);

} // namespace qgi::test
