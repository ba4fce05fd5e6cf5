#pragma once

#include "runtime/ecs/Entity.h"
#include "systems/photon_update/PhotonEmitter.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

class Registry;
class RayScene;
struct Aabb;

/// An area light: a static mesh whose Material emits (uniform radiance on its front side).
struct AreaLight {
    Entity entity;
    glm::vec3 radiance{0.f};                        ///< W/(m^2 sr), linear RGB
    std::vector<PhotonEmitter::Triangle> triangles; ///< world space, non-zero area
    std::vector<float> cdf;                         ///< cumulative area fraction, last entry 1
    float area = 0.f;                               ///< m^2
    glm::vec3 centre{0.f};                          ///< bounding sphere of the triangles
    float boundRadius = 0.f;
};

/// Every emissive StaticMesh, in registry order (the photon emitters' order). Emissive mobiles
/// are not area lights of the cache (its light samples are fixed in world space), nor are
/// lamps whose direct light the shader draws through a LightStandIn (hasLightStandIn).
std::vector<AreaLight> findAreaLights(const Registry& registry, const Aabb& sceneBox);

/// Irradiance at x (unit normal n) from one area light, with shadows, and the visible fraction.
struct LightSample {
    glm::vec3 irradiance{0.f}; ///< W/m^2
    float visibility = 1.f;    ///< unoccluded-irradiance-weighted visible fraction, [0, 1]
};

/** Soft shadow of `light` at x: `samples` points on the light, stratified over its area (a
 *  jittered sqrt x sqrt grid mapped through the area CDF when samples is a square), each with
 *  a shadow ray against the whole ray scene (mobiles at their current pose). Monte Carlo
 *  estimate of E = L integral_A cos(theta_x) cos(theta_y) / d^2 V dA:
 *  E ~ L A / m sum f_i V_i, f = cos cos / d^2. Random numbers from (seed, key, light index). */
LightSample shadeAreaLight(const RayScene& scene, const AreaLight& light, std::uint32_t lightIndex,
                           const glm::vec3& x, const glm::vec3& n, std::uint32_t samples,
                           std::uint64_t seed, std::uint32_t key);

/// shadeAreaLight that also records which samples reached the light: bit s % 32 of
/// reached[s / 32] is set where sample s's shadow ray got through (cleared where it was
/// blocked or the sample faced away). `reached` holds at least `samples` bits.
LightSample shadeAreaLight(const RayScene& scene, const AreaLight& light, std::uint32_t lightIndex,
                           const glm::vec3& x, const glm::vec3& n, std::uint32_t samples,
                           std::uint64_t seed, std::uint32_t key, std::span<std::uint32_t> reached);

/// shadeAreaLight again from the samples it recorded, with no ray cast: bit for bit the value
/// the recording call returned, for as long as nothing that could block those rays moved.
LightSample replayAreaLight(const AreaLight& light, std::uint32_t lightIndex, const glm::vec3& x,
                            const glm::vec3& n, std::uint32_t samples, std::uint64_t seed,
                            std::uint32_t key, std::span<const std::uint32_t> reached);

/** Ambient occlusion at x (unit normal n): the fraction of `rays` cosine-weighted directions
 *  that meet static geometry within `distance` metres. A pure function of its arguments
 *  (random numbers from (seed, key)), so the build and the shading fill agree exactly.     */
float ambientOcclusion(const RayScene& scene, const glm::vec3& x, const glm::vec3& n,
                       std::uint32_t rays, float distance, std::uint64_t seed, std::uint32_t key);

} // namespace qgi
