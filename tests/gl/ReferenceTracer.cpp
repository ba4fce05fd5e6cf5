#include "ReferenceTracer.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

namespace qgi::test {
namespace {

struct RayHit {
    double t = std::numeric_limits<double>::infinity(); ///< distance along the ray
    double u = 0.0, v = 0.0;                            ///< barycentrics of p1 and p2
};

/// Where the ray meets the triangle; t is infinity for a miss.
RayHit intersect(const glm::dvec3& origin, const glm::dvec3& dir, const RefTriangle& tri) {
    const glm::dvec3 e1 = tri.p1 - tri.p0, e2 = tri.p2 - tri.p0;
    const glm::dvec3 p = glm::cross(dir, e2);
    const double det = glm::dot(e1, p);
    if (std::abs(det) < 1e-14) return {};
    const glm::dvec3 s = origin - tri.p0;
    const double u = glm::dot(s, p) / det;
    if (u < 0.0 || u > 1.0) return {};
    const glm::dvec3 q = glm::cross(s, e1);
    const double v = glm::dot(dir, q) / det;
    if (v < 0.0 || u + v > 1.0) return {};
    const double t = glm::dot(e2, q) / det;
    return t > 0.0 ? RayHit{t, u, v} : RayHit{};
}

/// A bounding volume hierarchy over the triangles (median splits), so that scenes of tens of
/// thousands of triangles trace in well under a second. It only skips triangles whose boxes a
/// ray cannot reach: every candidate is still tested with intersect().
class Bvh {
public:
    explicit Bvh(const std::vector<RefTriangle>& triangles) : mTriangles(triangles) {
        mOrder.resize(triangles.size());
        for (std::uint32_t i = 0; i < mOrder.size(); ++i)
            mOrder[i] = i;
        mNodes.emplace_back();
        if (!triangles.empty()) split(0, 0, std::uint32_t(triangles.size()));
    }

    /// Calls `visit(triangle)` for the triangles of every leaf whose box the ray
    /// origin + t dir meets at some 0 <= t <= tMax. visit returns the ray's new extent: tMax to
    /// go on, less after a nearer hit, or a negative value to stop.
    template <typename Visit>
    void traverse(const glm::dvec3& origin, const glm::dvec3& dir, double tMax,
                  Visit&& visit) const {
        const glm::dvec3 inverse = 1.0 / dir;
        std::array<std::uint32_t, 64> stack; // median splits: depth <= log2(triangles) + 1
        std::size_t top = 0;
        stack[top++] = 0;
        while (top > 0) {
            const Node& node = mNodes[stack[--top]];
            if (!meets(node, origin, inverse, tMax)) continue;
            if (node.count == 0) {
                stack[top++] = node.first;
                stack[top++] = node.first + 1;
                continue;
            }
            for (std::uint32_t i = node.first; i < node.first + node.count; ++i)
                if ((tMax = visit(mTriangles[mOrder[i]])) < 0.0) return;
        }
    }

private:
    struct Node {
        glm::dvec3 lo{std::numeric_limits<double>::infinity()};
        glm::dvec3 hi{-std::numeric_limits<double>::infinity()};
        std::uint32_t first = 0; ///< leaf: first of mOrder; inner: left child (right follows)
        std::uint32_t count = 0; ///< triangles of a leaf; 0 for an inner node
    };
    static constexpr std::uint32_t kLeafSize = 4;

    static glm::dvec3 centroid(const RefTriangle& tri) { return (tri.p0 + tri.p1 + tri.p2) / 3.0; }

    void split(std::size_t node, std::uint32_t begin, std::uint32_t end) {
        glm::dvec3 lo = mNodes[node].lo, hi = mNodes[node].hi;
        glm::dvec3 centreLo = lo, centreHi = hi;
        for (std::uint32_t i = begin; i < end; ++i) {
            const RefTriangle& tri = mTriangles[mOrder[i]];
            for (const glm::dvec3& p : {tri.p0, tri.p1, tri.p2}) {
                lo = glm::min(lo, p);
                hi = glm::max(hi, p);
            }
            centreLo = glm::min(centreLo, centroid(tri));
            centreHi = glm::max(centreHi, centroid(tri));
        }
        // Padded, so that flat boxes (a wall) stay boxes under rounding of the slab test.
        mNodes[node].lo = lo - 1e-9;
        mNodes[node].hi = hi + 1e-9;
        if (end - begin <= kLeafSize) {
            mNodes[node].first = begin;
            mNodes[node].count = end - begin;
            return;
        }
        const glm::dvec3 extent = centreHi - centreLo;
        int axis = extent.y > extent.x ? 1 : 0;
        if (extent.z > extent[axis]) axis = 2;
        const std::uint32_t middle = begin + (end - begin) / 2;
        std::nth_element(mOrder.begin() + begin, mOrder.begin() + middle, mOrder.begin() + end,
                         [&](std::uint32_t a, std::uint32_t b) {
                             return centroid(mTriangles[a])[axis] < centroid(mTriangles[b])[axis];
                         });
        const auto left = std::uint32_t(mNodes.size());
        mNodes.resize(mNodes.size() + 2);
        mNodes[node].first = left;
        split(left, begin, middle);
        split(left + 1, middle, end);
    }

    /// Slab test. A direction component of 0 gives infinite slab distances, or NaN for an
    /// origin exactly on that slab's plane, which std::min/max then leave out (conservative).
    static bool meets(const Node& node, const glm::dvec3& origin, const glm::dvec3& inverse,
                      double tMax) {
        double tNear = 0.0, tFar = tMax;
        for (int axis = 0; axis < 3; ++axis) {
            const double t0 = (node.lo[axis] - origin[axis]) * inverse[axis];
            const double t1 = (node.hi[axis] - origin[axis]) * inverse[axis];
            tNear = std::max(tNear, std::min(t0, t1));
            tFar = std::min(tFar, std::max(t0, t1));
        }
        return tNear <= tFar;
    }

    const std::vector<RefTriangle>& mTriangles;
    std::vector<std::uint32_t> mOrder; ///< triangle indices, each leaf's a contiguous range
    std::vector<Node> mNodes;          ///< the root first
};

/// The nearest triangle the ray hits, or null; `hit` comes in as a miss and leaves with that
/// hit. Of triangles hit at exactly the same distance (a ray through a corner of a box), the
/// first in the list wins, whatever the traversal order.
const RefTriangle* nearestHit(const Bvh& bvh, const glm::dvec3& origin, const glm::dvec3& dir,
                              RayHit& hit) {
    const RefTriangle* nearest = nullptr;
    bvh.traverse(origin, dir, hit.t, [&](const RefTriangle& tri) {
        if (const RayHit h = intersect(origin, dir, tri);
            h.t < hit.t || (h.t == hit.t && nearest && &tri < nearest)) {
            hit = h;
            nearest = &tri;
        }
        return hit.t;
    });
    return nearest;
}

bool occluded(const Bvh& bvh, int surface, const glm::dvec3& from, const glm::dvec3& dir,
              double distance) {
    bool blocked = false;
    bvh.traverse(from, dir, distance, [&](const RefTriangle& tri) {
        blocked = tri.surface != surface && intersect(from, dir, tri).t < distance;
        return blocked ? -1.0 : distance;
    });
    return blocked;
}

/// Whether a triangle lies in the plane of `hit` and on its surface (a face of it): its
/// corners within 1e-6 m of that plane, taken from hit's corners (float vertices put the
/// corners of a rotated planar quad up to ~1e-7 m off a common plane, and `normal` comes from
/// a float normal).
bool inPlaneOf(const RefTriangle& tri, const RefTriangle& hit) {
    if (tri.surface != hit.surface) return false;
    const glm::dvec3 n = glm::normalize(glm::cross(hit.p1 - hit.p0, hit.p2 - hit.p0));
    for (const glm::dvec3& p : {tri.p0, tri.p1, tri.p2})
        if (std::abs(glm::dot(n, p - hit.p0)) > 1e-6) return false;
    return true;
}

/// occluded() from a point near the face `hit` rather than on it: only the triangles in that
/// face's plane are left out, so other faces of the same convex surface can occlude.
bool occludedNear(const Bvh& bvh, const RefTriangle& hit, const glm::dvec3& from,
                  const glm::dvec3& dir, double distance) {
    bool blocked = false;
    bvh.traverse(from, dir, distance, [&](const RefTriangle& tri) {
        blocked = !inPlaneOf(tri, hit) && intersect(from, dir, tri).t < distance;
        return blocked ? -1.0 : distance;
    });
    return blocked;
}

/// Unit direction of the camera ray through image position (px, py), in pixels from the top
/// left corner (pixel centres at x + 0.5, y + 0.5).
glm::dvec3 cameraRay(const RefCamera& camera, double px, double py) {
    const double tanHalf = std::tan(0.5 * camera.yfov);
    const double aspect = double(camera.width) / double(camera.height);
    const double ndcX = 2.0 * px / camera.width - 1.0;
    const double ndcY = 1.0 - 2.0 * py / camera.height;
    return camera.orientation *
           glm::normalize(glm::dvec3(ndcX * tanHalf * aspect, ndcY * tanHalf, -1.0));
}

/// The nearest surface along a camera ray, with its normals turned towards the camera.
struct Surfel {
    const RefTriangle* triangle = nullptr; ///< null: the ray hits nothing
    glm::dvec3 position{0.0};
    glm::dvec3 facing{0.0}; ///< the triangle's normal, on the camera's side
    glm::dvec3 normal{0.0}; ///< the shading normal, on the camera's side
};

Surfel surfelAlong(const Bvh& bvh, const glm::dvec3& origin, const glm::dvec3& dir) {
    RayHit nearest;
    Surfel s;
    s.triangle = nearestHit(bvh, origin, dir, nearest);
    if (!s.triangle) return s;
    const RefTriangle& hit = *s.triangle;
    s.position = origin + nearest.t * dir;
    const double side = glm::dot(hit.normal, dir) > 0.0 ? -1.0 : 1.0;
    s.facing = side * hit.normal;
    s.normal = s.facing;
    if (const auto& vn = hit.vertexNormals)
        s.normal = side * glm::normalize((1.0 - nearest.u - nearest.v) * (*vn)[0] +
                                         nearest.u * (*vn)[1] + nearest.v * (*vn)[2]);
    return s;
}

/// How a surfel faces a light: away (the shading normal turns from it), towards it, or only
/// its shading normal does while its face turns away (the terminator of a smooth mesh).
enum class Facing { Away, Towards, ShadingNormalOnly };

/// Light `light` at the surfel before shadowing: the direction and distance to it, and (unless
/// it faces away) the irradiance term E cos(theta) with the shading normal.
Facing lightTerm(const RefLight& light, const Surfel& s, glm::dvec3& toLight, double& distance,
                 glm::dvec3& term) {
    glm::dvec3 e;
    distance = std::numeric_limits<double>::infinity();
    if (light.type == RefLightType::Directional) {
        toLight = -light.direction;
        e = light.radiance;
    } else {
        const glm::dvec3 d = light.position - s.position;
        distance = glm::length(d);
        toLight = d / distance;
        e = light.radiance / (distance * distance);
        if (light.type == RefLightType::Spot) {
            // glTF KHR_lights_punctual: linear in cos between the cones, squared.
            const double cosInner = std::cos(light.innerCone);
            const double cosOuter = std::cos(light.outerCone);
            const double t = std::clamp(
                (glm::dot(light.direction, -toLight) - cosOuter) / (cosInner - cosOuter), 0.0, 1.0);
            e *= t * t;
        }
    }
    const double cosTheta = glm::dot(s.normal, toLight);
    if (cosTheta <= 0.0) return Facing::Away;
    term = e * cosTheta;
    // A smooth normal may still face a light that the triangle's own plane, and so its convex
    // surface, hides.
    return glm::dot(s.facing, toLight) > 0.0 ? Facing::Towards : Facing::ShadingNormalOnly;
}

/// Whether the shadow-map lookup of `light` at the surfel may see another visibility than the
/// shadow ray from it (see RefPerturbation::shadowTexel): shadow rays from the corners, edge
/// midpoints and centre of the lookup square, each against the visibility `clear`.
bool shadowAmbiguous(const Bvh& bvh, const RefLight& light, double texel, const Surfel& s,
                     const glm::dvec3& toLight, double distance, bool clear) {
    const double size = light.type == RefLightType::Directional ? texel : texel * distance;
    const glm::dvec3 centre = s.position + RefPerturbation::kNormalOffsetTexels * size * s.normal;
    const glm::dvec3 a = glm::normalize(
        glm::cross(toLight, std::abs(toLight.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0)));
    const glm::dvec3 b = glm::cross(toLight, a);
    const double half = RefPerturbation::kLookupRadiusTexels * size;
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j) {
            const glm::dvec3 q = centre + double(i) * half * a + double(j) * half * b;
            glm::dvec3 dir = toLight;
            double reach = distance;
            if (light.type != RefLightType::Directional) {
                const glm::dvec3 d = light.position - q;
                reach = glm::length(d);
                dir = d / reach;
            }
            if (occludedNear(bvh, *s.triangle, q, dir, reach) == clear) return true;
        }
    return false;
}

} // namespace

RefImage traceReference(const std::vector<RefTriangle>& triangles,
                        const std::vector<RefLight>& lights, const RefCamera& camera) {
    RefImage image;
    image.radiance = ImageF{camera.width, camera.height,
                            std::vector<float>(std::size_t(camera.width) * camera.height * 4, 0.f)};
    const Bvh bvh(triangles);

    for (int y = 0; y < camera.height; ++y)
        for (int x = 0; x < camera.width; ++x) {
            float* out = image.radiance.pixel(x, y);
            out[3] = 1.f;
            const Surfel s = surfelAlong(bvh, camera.position, cameraRay(camera, x + 0.5, y + 0.5));
            if (!s.triangle) continue;
            glm::dvec3 irradiance(0.0);
            for (std::size_t i = 0; i < lights.size(); ++i) {
                glm::dvec3 toLight, term;
                double distance;
                if (lightTerm(lights[i], s, toLight, distance, term) != Facing::Towards ||
                    (lights[i].castsShadow &&
                     occluded(bvh, s.triangle->surface, s.position, toLight, distance)))
                    continue;
                irradiance += term;
            }
            const glm::dvec3 radiance =
                s.triangle->albedo / std::numbers::pi * irradiance + s.triangle->emission;
            out[0] = float(radiance.x);
            out[1] = float(radiance.y);
            out[2] = float(radiance.z);
        }
    return image;
}

RefRange referenceRange(const std::vector<RefTriangle>& triangles,
                        const std::vector<RefLight>& lights, const RefCamera& camera,
                        const RefPerturbation& perturbation) {
    const std::size_t pixels = std::size_t(camera.width) * camera.height;
    RefRange range{ImageF{camera.width, camera.height, std::vector<float>(pixels * 4, 0.f)},
                   ImageF{camera.width, camera.height, std::vector<float>(pixels * 4, 0.f)}};
    const Bvh bvh(triangles);
    // Angle between neighbouring pixel centres on the optical axis; at angle a off the axis it
    // is this times cos^2(a).
    const double pixelAngle = 2.0 * std::tan(0.5 * camera.yfov) / camera.height;
    const glm::dvec3 forward = camera.orientation * glm::dvec3(0.0, 0.0, -1.0);
    for (int y = 0; y < camera.height; ++y)
        for (int x = 0; x < camera.width; ++x) {
            glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(0.0);
            int centreSurface = -1;
            double offset = perturbation.rayOffset;
            for (int k = 0; k < 5; ++k) {
                // k = 0: the pixel centre; 1..4: the corners of the offset square.
                const double dx = k == 0 ? 0.0 : (k & 1 ? offset : -offset);
                const double dy = k == 0 ? 0.0 : (k & 2 ? offset : -offset);
                if (k > 0 && offset <= 0.0) break;
                const glm::dvec3 dir = cameraRay(camera, x + 0.5 + dx, y + 0.5 + dy);
                const Surfel s = surfelAlong(bvh, camera.position, dir);
                const int surface = s.triangle ? s.triangle->surface : -1;
                if (k == 0) {
                    centreSurface = surface;
                    if (s.triangle && perturbation.pointOffset > 0.0) {
                        const double cosine = glm::dot(dir, forward);
                        offset +=
                            perturbation.pointOffset / (glm::length(s.position - camera.position) *
                                                        pixelAngle * cosine * cosine);
                    }
                } else if (surface == centreSurface && !perturbation.shadeEveryOffsetRay) {
                    continue;
                }
                if (!s.triangle) {
                    lo = glm::dvec3(0.0);
                    continue;
                }
                glm::dvec3 sure(0.0), unsure(0.0);
                for (std::size_t i = 0; i < lights.size(); ++i) {
                    glm::dvec3 toLight, term;
                    double distance;
                    const Facing facing = lightTerm(lights[i], s, toLight, distance, term);
                    if (facing == Facing::Away) continue;
                    // At a smooth mesh's terminator the reference hides the light; a renderer
                    // that shades with the smooth normal leaves it to its shadow map.
                    if (facing == Facing::ShadingNormalOnly) {
                        unsure += term;
                        continue;
                    }
                    const bool clear =
                        !lights[i].castsShadow ||
                        !occluded(bvh, s.triangle->surface, s.position, toLight, distance);
                    const double texel =
                        i < perturbation.shadowTexel.size() ? perturbation.shadowTexel[i] : 0.0;
                    if (texel > 0.0 &&
                        shadowAmbiguous(bvh, lights[i], texel, s, toLight, distance, clear))
                        unsure += term;
                    else if (clear)
                        sure += term;
                }
                const glm::dvec3 albedo = s.triangle->albedo / std::numbers::pi;
                lo = glm::min(lo, albedo * sure + s.triangle->emission);
                hi = glm::max(hi, albedo * (sure + unsure) + s.triangle->emission);
            }
            float* l = range.lo.pixel(x, y);
            float* h = range.hi.pixel(x, y);
            for (int c = 0; c < 3; ++c) {
                l[c] = float(lo[c]);
                h[c] = float(hi[c]);
            }
            l[3] = h[3] = 1.f;
        }
    return range;
}

RangeComparison compareWithRange(const ImageF& actual, const ImageF& reference,
                                 const RefRange& range, double tolerance, double floor) {
    RangeComparison c;
    const std::size_t pixels = reference.rgba.size() / 4;
    c.failures.assign(pixels, false);
    for (std::size_t p = 0; p < pixels; ++p) {
        bool narrow = true;
        double outside = 0.0, error = 0.0;
        for (std::size_t ch = 0; ch < 3; ++ch) {
            const std::size_t i = 4 * p + ch;
            const double r = reference.rgba[i], a = actual.rgba[i];
            const double lo = range.lo.rgba[i], hi = range.hi.rgba[i];
            narrow &= hi - lo <= tolerance * std::max(hi, floor);
            // Written so that a NaN or an infinity is the largest error (std::max drops NaN).
            const double beyond = std::isfinite(a) ? std::max({(lo - a) / std::max(lo, floor),
                                                               (a - hi) / std::max(hi, floor), 0.0})
                                                   : std::numeric_limits<double>::infinity();
            outside = std::max(outside, beyond);
            error = std::max(error, std::isfinite(a) ? std::abs(a - r) / std::max(r, floor)
                                                     : std::numeric_limits<double>::infinity());
        }
        c.failures[p] = !(outside <= tolerance);
        c.failed += c.failures[p];
        if (narrow) {
            c.worstNarrow = std::max(c.worstNarrow, error);
        } else {
            ++c.excused;
            c.worstExcused = std::max(c.worstExcused, outside);
        }
    }
    return c;
}

} // namespace qgi::test
