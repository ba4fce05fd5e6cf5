#include "ReferenceTracer.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

namespace qgi::test {
namespace {

constexpr std::uint32_t kBackground = 0xffffffffu;

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

} // namespace

RefImage traceReference(const std::vector<RefTriangle>& triangles,
                        const std::vector<RefLight>& lights, const RefCamera& camera) {
    RefImage image;
    image.radiance = ImageF{camera.width, camera.height,
                            std::vector<float>(std::size_t(camera.width) * camera.height * 4, 0.f)};
    image.key.assign(std::size_t(camera.width) * camera.height, kBackground);
    const double tanHalf = std::tan(0.5 * camera.yfov);
    const double aspect = double(camera.width) / double(camera.height);
    const Bvh bvh(triangles);

    for (int y = 0; y < camera.height; ++y)
        for (int x = 0; x < camera.width; ++x) {
            float* out = image.radiance.pixel(x, y);
            out[3] = 1.f;
            const double ndcX = 2.0 * (x + 0.5) / camera.width - 1.0;
            const double ndcY = 1.0 - 2.0 * (y + 0.5) / camera.height;
            const glm::dvec3 dir =
                camera.orientation *
                glm::normalize(glm::dvec3(ndcX * tanHalf * aspect, ndcY * tanHalf, -1.0));

            RayHit nearest;
            const RefTriangle* hit = nearestHit(bvh, camera.position, dir, nearest);
            if (!hit) continue;

            const glm::dvec3 p = camera.position + nearest.t * dir;
            const double side = glm::dot(hit->normal, dir) > 0.0 ? -1.0 : 1.0;
            const glm::dvec3 facing = side * hit->normal;
            glm::dvec3 n = facing;
            if (const auto& vn = hit->vertexNormals)
                n = side * glm::normalize((1.0 - nearest.u - nearest.v) * (*vn)[0] +
                                          nearest.u * (*vn)[1] + nearest.v * (*vn)[2]);
            glm::dvec3 irradiance(0.0);
            std::uint32_t visible = 0;
            for (std::size_t i = 0; i < lights.size(); ++i) {
                const RefLight& light = lights[i];
                glm::dvec3 toLight, e;
                double distance = std::numeric_limits<double>::infinity();
                if (light.type == RefLightType::Directional) {
                    toLight = -light.direction;
                    e = light.radiance;
                } else {
                    const glm::dvec3 d = light.position - p;
                    distance = glm::length(d);
                    toLight = d / distance;
                    e = light.radiance / (distance * distance);
                    if (light.type == RefLightType::Spot) {
                        // glTF KHR_lights_punctual: linear in cos between the cones, squared.
                        const double cosInner = std::cos(light.innerCone);
                        const double cosOuter = std::cos(light.outerCone);
                        const double t =
                            std::clamp((glm::dot(light.direction, -toLight) - cosOuter) /
                                           (cosInner - cosOuter),
                                       0.0, 1.0);
                        e *= t * t;
                    }
                }
                // A smooth normal may still face a light that the triangle's own plane, and so
                // its convex surface, hides.
                const double cosTheta = glm::dot(n, toLight);
                if (cosTheta <= 0.0 || glm::dot(facing, toLight) <= 0.0 ||
                    occluded(bvh, hit->surface, p, toLight, distance))
                    continue;
                visible |= 1u << i;
                irradiance += e * cosTheta;
            }
            const glm::dvec3 radiance = hit->albedo / std::numbers::pi * irradiance + hit->emission;
            out[0] = float(radiance.x);
            out[1] = float(radiance.y);
            out[2] = float(radiance.z);
            image.key[std::size_t(y) * camera.width + x] =
                std::uint32_t(hit->surface) << 8 | visible;
        }
    return image;
}

std::vector<bool> discontinuities(const RefImage& image) {
    const int w = image.radiance.width, h = image.radiance.height;
    std::vector<bool> mask(image.key.size(), false);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::uint32_t key = image.key[std::size_t(y) * w + x];
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int nx = std::clamp(x + dx, 0, w - 1), ny = std::clamp(y + dy, 0, h - 1);
                    if (image.key[std::size_t(ny) * w + nx] != key)
                        mask[std::size_t(y) * w + x] = true;
                }
        }
    return mask;
}

} // namespace qgi::test
