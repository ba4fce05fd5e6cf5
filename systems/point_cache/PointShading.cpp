#include "systems/point_cache/PointShading.h"

#include "components/StaticMesh.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonSampling.h"
#include "systems/photon_update/PhotonSettings.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>

namespace qgi {
namespace {

// Distinct streams of the seed for the two uses.
constexpr std::uint64_t kShadowStream = 0x51a70d5ull;
constexpr std::uint64_t kAoStream = 0xa0a0a0ull;

} // namespace

std::vector<AreaLight> findAreaLights(const Registry& registry, const Aabb& sceneBox) {
    PhotonSettings only;
    only.punctualLights = false;
    only.emissiveSurfaces = true;
    std::vector<PhotonEmitter> emitters;
    findEmitterSources(registry, only, emitters);
    std::vector<AreaLight> lights;
    for (PhotonEmitter& e : emitters) {
        if (!registry.has<StaticMesh>(e.entity)) continue;
        prepareEmitter(registry, sceneBox, e);
        if (!(e.power.x + e.power.y + e.power.z > 0.f)) continue;
        // A lamp with a LightStandIn: the shader draws its direct light through the stand-in
        // on every surface, the cache's included, so the cache must not hold it too.
        if (e.directDrawn) continue;
        AreaLight light;
        light.entity = e.entity;
        light.radiance = e.radiant;
        light.triangles = std::move(e.triangles);
        light.cdf = std::move(e.triangleCdf);
        Aabb box;
        double area = 0.0;
        for (const auto& t : light.triangles) {
            area += 0.5 * double(glm::length(glm::cross(t.edge1, t.edge2)));
            box.extend(t.corner);
            box.extend(t.corner + t.edge1);
            box.extend(t.corner + t.edge2);
        }
        light.area = float(area);
        light.centre = box.center();
        light.boundRadius = 0.5f * glm::length(box.extent());
        lights.push_back(std::move(light));
    }
    return lights;
}

namespace {

/// How integrateAreaLight learns whether a sample's shadow ray gets through.
enum class Rays {
    Trace,  ///< cast it against `scene`
    Record, ///< cast it, and set the sample's bit of `reached` where it gets through
    Replay, ///< read the sample's bit of `reached`; no ray
};

/// Samples whose shadow rays are traced together: 8-wide packets, from one point towards one
/// light, are coherent, and a packet costs little more than one ray.
constexpr std::uint32_t kSampleChunk = 32;

/// The estimate of shadeAreaLight. One function body for all three ways, so that a replay
/// computes every sample's weight with the very instructions the recording did (two
/// instantiations could contract multiply-adds differently) and gives its value bit for bit.
/// Samples go in chunks: each chunk's weights and rays first, then its rays traced as packets
/// (or its bits read), then its sums in sample order.
LightSample integrateAreaLight(const AreaLight& light, std::uint32_t lightIndex, const glm::vec3& x,
                               const glm::vec3& n, std::uint32_t samples, std::uint64_t seed,
                               std::uint32_t key, Rays rays, const RayScene* scene,
                               std::uint32_t* reached) {
    const std::uint64_t seedKey = photon::mixBits(seed ^ kShadowStream);
    const auto u = [&](std::uint32_t dimension) {
        return photon::hashUniform(seedKey, key, lightIndex, dimension);
    };
    const std::uint32_t side = std::uint32_t(std::sqrt(double(samples)));
    const bool stratified = side * side == samples;
    const glm::vec3 origin = photon::offsetFromSurface(x, n);
    double total = 0.0, visible = 0.0;
    std::array<double, kSampleChunk> weight;
    std::array<std::uint32_t, kSampleChunk> sampleOf;
    std::array<Ray, kSampleChunk> ray;
    std::array<std::uint8_t, kSampleChunk> blocked;
    for (std::uint32_t first = 0; first < samples; first += kSampleChunk) {
        const std::uint32_t last = std::min(samples, first + kSampleChunk);
        std::uint32_t count = 0; // samples of the chunk that face both ways
        for (std::uint32_t s = first; s < last; ++s) {
            float u1 = u(2 * s), u2 = u(2 * s + 1);
            if (stratified) {
                u1 = std::min((float(s % side) + u1) / float(side), photon::kOneMinusEpsilon);
                u2 = std::min((float(s / side) + u2) / float(side), photon::kOneMinusEpsilon);
            }
            // u1 picks the triangle by area and, rescaled inside its CDF interval, the point on
            // it: the strata stay strata of the whole light.
            const auto it = std::upper_bound(light.cdf.begin(), light.cdf.end(), u1);
            const std::size_t t =
                std::min(std::size_t(it - light.cdf.begin()), light.cdf.size() - 1);
            const float low = t > 0 ? light.cdf[t - 1] : 0.f;
            const float width = light.cdf[t] - low;
            const float v1 =
                width > 0.f ? std::clamp((u1 - low) / width, 0.f, photon::kOneMinusEpsilon) : 0.f;
            const auto& tri = light.triangles[t];
            const glm::vec2 st = photon::sampleTriangle(v1, u2);
            const glm::vec3 y = tri.corner + st.x * tri.edge1 + st.y * tri.edge2;
            const glm::vec3 w = y - x;
            const float d2 = glm::dot(w, w);
            if (!(d2 > 0.f)) continue;
            const float d = std::sqrt(d2);
            const float cosX = glm::dot(n, w) / d, cosY = -glm::dot(tri.normal, w) / d;
            if (!(cosX > 0.f && cosY > 0.f)) continue;
            weight[count] = double(cosX) * double(cosY) / double(d2);
            sampleOf[count] = s;
            Ray& r = ray[count];
            r.origin = origin;
            r.direction = photon::offsetFromSurface(y, tri.normal) - origin;
            r.tnear = 0.f;
            r.tfar = 1.f - 1e-4f;
            ++count;
        }
        if (rays == Rays::Replay) {
            for (std::uint32_t i = 0; i < count; ++i) {
                const std::uint32_t s = sampleOf[i];
                blocked[i] = ((reached[s / 32] >> (s % 32)) & 1u) != 0 ? 0 : 1;
            }
        } else {
            scene->occluded(std::span<const Ray>(ray.data(), count),
                            std::span<std::uint8_t>(blocked.data(), count));
        }
        for (std::uint32_t i = 0; i < count; ++i) {
            total += weight[i];
            if (blocked[i]) continue;
            visible += weight[i];
            if (rays == Rays::Record) reached[sampleOf[i] / 32] |= 1u << (sampleOf[i] % 32);
        }
    }
    LightSample out;
    out.irradiance = light.radiance * float(double(light.area) * visible / double(samples));
    out.visibility = total > 0.0 ? float(visible / total) : 1.f;
    return out;
}

} // namespace

LightSample shadeAreaLight(const RayScene& scene, const AreaLight& light, std::uint32_t lightIndex,
                           const glm::vec3& x, const glm::vec3& n, std::uint32_t samples,
                           std::uint64_t seed, std::uint32_t key) {
    return integrateAreaLight(light, lightIndex, x, n, samples, seed, key, Rays::Trace, &scene,
                              nullptr);
}

LightSample shadeAreaLight(const RayScene& scene, const AreaLight& light, std::uint32_t lightIndex,
                           const glm::vec3& x, const glm::vec3& n, std::uint32_t samples,
                           std::uint64_t seed, std::uint32_t key,
                           std::span<std::uint32_t> reached) {
    QGI_ASSERT(reached.size() * 32 >= samples);
    std::fill(reached.begin(), reached.end(), 0u);
    return integrateAreaLight(light, lightIndex, x, n, samples, seed, key, Rays::Record, &scene,
                              reached.data());
}

LightSample replayAreaLight(const AreaLight& light, std::uint32_t lightIndex, const glm::vec3& x,
                            const glm::vec3& n, std::uint32_t samples, std::uint64_t seed,
                            std::uint32_t key, std::span<const std::uint32_t> reached) {
    QGI_ASSERT(reached.size() * 32 >= samples);
    // Replay only reads the bits.
    return integrateAreaLight(light, lightIndex, x, n, samples, seed, key, Rays::Replay, nullptr,
                              const_cast<std::uint32_t*>(reached.data()));
}

float ambientOcclusion(const RayScene& scene, const glm::vec3& x, const glm::vec3& n,
                       std::uint32_t rays, float distance, std::uint64_t seed, std::uint32_t key) {
    const std::uint64_t seedKey = photon::mixBits(seed ^ kAoStream);
    const photon::Frame frame(n);
    const glm::vec3 origin = photon::offsetFromSurface(x, n);
    const bool anyMobile = scene.mobileCount() > 0;
    std::uint32_t occluded = 0;
    for (std::uint32_t r = 0; r < rays; ++r) {
        Ray ray;
        ray.origin = origin;
        ray.direction = photon::sampleCosine(frame, photon::hashUniform(seedKey, key, 0, 2 * r),
                                             photon::hashUniform(seedKey, key, 0, 2 * r + 1));
        ray.tfar = distance;
        const bool hit =
            anyMobile
                ? scene.occludedFiltered(
                      ray, [&](const Hit& candidate) { return !scene.isMobile(candidate.entity); })
                : scene.occluded(ray);
        occluded += hit ? 1u : 0u;
    }
    return float(occluded) / float(rays);
}

} // namespace qgi
