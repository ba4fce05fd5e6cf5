#include "ReferenceTracer.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace qgi::test {
namespace {

constexpr std::uint32_t kBackground = 0xffffffffu;

/// Distance along the ray to the triangle, or infinity.
double intersect(const glm::dvec3& origin, const glm::dvec3& dir, const RefTriangle& tri) {
    const glm::dvec3 e1 = tri.p1 - tri.p0, e2 = tri.p2 - tri.p0;
    const glm::dvec3 p = glm::cross(dir, e2);
    const double det = glm::dot(e1, p);
    if (std::abs(det) < 1e-14) return std::numeric_limits<double>::infinity();
    const glm::dvec3 s = origin - tri.p0;
    const double u = glm::dot(s, p) / det;
    if (u < 0.0 || u > 1.0) return std::numeric_limits<double>::infinity();
    const glm::dvec3 q = glm::cross(s, e1);
    const double v = glm::dot(dir, q) / det;
    if (v < 0.0 || u + v > 1.0) return std::numeric_limits<double>::infinity();
    const double t = glm::dot(e2, q) / det;
    return t > 0.0 ? t : std::numeric_limits<double>::infinity();
}

bool occluded(const std::vector<RefTriangle>& triangles, int surface, const glm::dvec3& from,
              const glm::dvec3& dir, double distance) {
    for (const RefTriangle& tri : triangles)
        if (tri.surface != surface && intersect(from, dir, tri) < distance) return true;
    return false;
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

    for (int y = 0; y < camera.height; ++y)
        for (int x = 0; x < camera.width; ++x) {
            float* out = image.radiance.pixel(x, y);
            out[3] = 1.f;
            const double ndcX = 2.0 * (x + 0.5) / camera.width - 1.0;
            const double ndcY = 1.0 - 2.0 * (y + 0.5) / camera.height;
            const glm::dvec3 dir =
                glm::normalize(glm::dvec3(ndcX * tanHalf * aspect, ndcY * tanHalf, -1.0));

            double nearest = std::numeric_limits<double>::infinity();
            const RefTriangle* hit = nullptr;
            for (const RefTriangle& tri : triangles)
                if (const double t = intersect(camera.position, dir, tri); t < nearest) {
                    nearest = t;
                    hit = &tri;
                }
            if (!hit) continue;

            const glm::dvec3 p = camera.position + nearest * dir;
            const glm::dvec3 n = glm::dot(hit->normal, dir) > 0.0 ? -hit->normal : hit->normal;
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
                const double cosTheta = glm::dot(n, toLight);
                if (cosTheta <= 0.0 || occluded(triangles, hit->surface, p, toLight, distance))
                    continue;
                visible |= 1u << i;
                irradiance += e * cosTheta;
            }
            const glm::dvec3 radiance = hit->albedo / std::numbers::pi * irradiance;
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
