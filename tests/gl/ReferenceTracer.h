#pragma once
// An independent CPU renderer for the GL image tests. Per pixel centre it finds the nearest
// triangle along the camera ray (Moller-Trumbore in double precision on every triangle a
// bounding volume hierarchy cannot rule out) and shades direct light analytically with a hard
// shadow ray. It shares no code with the renderer: only the physics
// (radiance = albedo / pi * E + emission) and the documented light conventions.
// referenceRange gives, per pixel, the range the reference takes when its inputs move by what
// another computation of the scene may legitimately change (rasterization, shadow maps,
// another platform's rounding): the bound a comparison with the reference is held to.

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
    bool castsShadow = true; ///< false: lights every surface that faces it (no shadow ray)
};

/// A pinhole camera at `position` looking along its local -Z with local Y up.
struct RefCamera {
    glm::dvec3 position{0.0};
    double yfov = 0.9; ///< radians
    int width = 0, height = 0;
    glm::dmat3 orientation{1.0}; ///< camera to world rotation
};

struct RefImage {
    ImageF radiance; ///< W/(m^2 sr), rows top to bottom
};

RefImage traceReference(const std::vector<RefTriangle>& triangles,
                        const std::vector<RefLight>& lights, const RefCamera& camera);

/// For referenceRange: which inputs of a pixel of the reference another computation of the
/// same scene (a rasterizer with shadow maps, or the reference on another platform) may
/// legitimately see differently, and by how much.
struct RefPerturbation {
    /// Camera rays are traced through the pixel centre and through the four points offset from
    /// it by +-rayOffset pixels in x and y: the coverage a rasterizer computes from vertices
    /// snapped to its sub-pixel grid.
    double rayOffset = 0.0;
    /// Added to rayOffset per pixel: the offset, in pixels, that moves the point the centre
    /// ray hits by at least this many metres across the line of sight (none where it hits
    /// nothing).
    double pointOffset = 0.0;
    /// false: an offset ray counts only where it sees another surface than the centre ray (or
    /// nothing where that sees one), as a rasterizer interpolates at the pixel centre whatever
    /// its coverage; true: every offset ray counts, so the range also holds the reference's
    /// smooth change over the offset.
    bool shadeEveryOffsetRay = false;
    /// Per light (in the order of the lights), the world size of one shadow-map texel: per
    /// metre of distance for point and spot lights, in metres for directional lights; 0 where
    /// the light has no shadow map. Where positive, the light's visibility counts as ambiguous
    /// at a surface point when a shadow ray from any of 9 points (the corners, edge midpoints
    /// and centre of a square of half-width kLookupRadiusTexels texels, perpendicular to the
    /// light, centred kNormalOffsetTexels texels off the surface along the shading normal)
    /// sees another visibility than the shadow ray from the point itself. Those shadow rays
    /// pass the face the point lies on, not the rest of its surface.
    std::vector<double> shadowTexel;

    /// The renderer's shadow lookup (shaders/common/lighting.glsl): it is offset along the
    /// normal by 1.5 texels, and its 2x2 taps half a texel apart, each a 2x2 bilinear PCF
    /// fetch, read the depth texels whose centres lie within 1.5 texels of it along either map
    /// axis, so within 1.5 sqrt(2) texels of it whatever the map's orientation. A straight
    /// shadow edge that crosses the disc of that radius separates the corners of the square
    /// around it.
    static constexpr double kNormalOffsetTexels = 1.5;
    static constexpr double kLookupRadiusTexels = 2.1213203435596424; // 1.5 sqrt(2)
};

/// Per pixel and channel, the least and the greatest radiance of the reference over the
/// perturbations: the camera rays of RefPerturbation, each shaded with its ambiguous lights
/// left out (lo) and added (hi). A light is ambiguous where RefPerturbation::shadowTexel says
/// so, and where only the shading normal faces it (a smooth mesh's terminator: the reference
/// hides it, a renderer that shades with the smooth normal leaves it to its shadow map).
/// Where nothing is ambiguous, lo and hi are the reference itself.
struct RefRange {
    ImageF lo, hi;
};

RefRange referenceRange(const std::vector<RefTriangle>& triangles,
                        const std::vector<RefLight>& lights, const RefCamera& camera,
                        const RefPerturbation& perturbation);

/// A rendered image against the reference's range. A pixel passes where every channel lies in
/// [lo, hi] widened by `tolerance` times the nearer end, or times `floor` where that end is
/// darker; its range is narrow where hi - lo is within the same tolerance of hi in every
/// channel. A value that is not finite fails.
struct RangeComparison {
    std::size_t failed = 0;  ///< pixels that do not pass
    std::size_t excused = 0; ///< pixels whose range is not narrow
    /// Largest |actual - reference| / max(reference, floor) where the range is narrow.
    double worstNarrow = 0.0;
    /// Largest relative distance outside [lo, hi] (as the pass test measures it) where not.
    double worstExcused = 0.0;
    std::vector<bool> failures; ///< per pixel
};

RangeComparison compareWithRange(const ImageF& actual, const ImageF& reference,
                                 const RefRange& range, double tolerance, double floor);

} // namespace qgi::test
