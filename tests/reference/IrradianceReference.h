#pragma once

#include "tests/reference/IrradianceEstimate.h"
#include "tests/reference/ReferenceSettings.h"

#include <glm/vec3.hpp>

#include <span>
#include <vector>

namespace qgi {
class Registry;
class RayScene;
} // namespace qgi

namespace qgi::reference {

/** Brute-force Monte Carlo irradiance, the independent reference the lighting systems are
 *  checked against. It shares no code with the photon tracer or DETP: only RayScene (Embree is
 *  the ground truth for geometry) and the scene's components.
 *
 *  Physics, as the engine defines it (README.md, "Scene conventions"):
 *   - every StaticMesh and MobileMesh surface is Lambertian on both sides with albedo
 *     Material::baseColor (textures are not sampled), and emits Material::emission, W/(m^2 sr),
 *     from its front side only (Hit::normal's side: counter-clockwise corners);
 *   - PointLight: E = I cos / d^2; SpotLight: the same times the renderer's cone falloff
 *     (shaders/common/lighting.glsl: t = clamp linear in cos between the cones, squared);
 *     DirectionalLight: E = irradiance cos; all shine along the entity's local -Z and are
 *     shadowed;
 *   - rays that leave the scene see SceneInfo::environment (when includeEnvironment);
 *   - avatars are not in the ray scene and neither block nor reflect light.
 *
 *  Estimator of the irradiance E(x) over the hemisphere of n. A path starts at x; at each
 *  vertex z (x first, then surface hits, whose normal is the geometric one turned to face the
 *  arriving ray) it adds the throughput beta times
 *   - the punctual lights' direct irradiance at z, one shadow ray each (at x it is computed
 *     once per point: it has no variance);
 *   - one emitter sample (a triangle picked in proportion to its power, a uniform point on it),
 *     weighted by the power heuristic against cosine sampling;
 *  then continues in a cosine-weighted direction (pdf cos / pi, so E = pi * mean(L_i)). An
 *  emitter's front face hit by that ray adds beta * pi * L_e times the complementary power
 *  heuristic weight, so no emitted light is counted twice; an escaping ray adds
 *  beta * pi * L_env. A reflection multiplies beta by the albedo; from the third reflection on,
 *  Russian roulette ends the path with probability 1 - max(beta) and divides beta by max(beta)
 *  otherwise, which keeps the estimate unbiased.
 *
 *  Rays leave a surface from a point moved off it along the normal by
 *  kOffset = 1e-5 m * (1 + max |coordinate|): hundreds of float ulps at any scale, so a ray
 *  never re-hits its own triangle, and far below the smallest gap in the built-in scenes
 *  (0.5 mm between the Cornell luminaire and the ceiling).
 *
 *  The constructor snapshots materials, lights and emissive triangles (at their current
 *  WorldTransform, which must be the pose the RayScene holds) and throws qgi::Error naming the
 *  entity and field on input it cannot use. Results depend only on the seed, the point's index
 *  and the sample count, not on thread timing.                                             */
class IrradianceReference {
public:
    IrradianceReference(const Registry& registry, const RayScene& scene,
                        const ReferenceSettings& settings);

    /// Irradiance at world point x over the hemisphere around n (any length but zero). Uses the
    /// random streams of point index 0. Throws qgi::Error on a non-finite x or a zero n.
    IrradianceEstimate estimate(const glm::vec3& x, const glm::vec3& n) const;
    /// Point i with normal n[i]; parallel over points and blocks of samples (oneTBB).
    std::vector<IrradianceEstimate> estimate(std::span<const glm::vec3> x,
                                             std::span<const glm::vec3> n) const;

private:
    class Random;
    struct Surface {
        glm::vec3 albedo{0.f};
        glm::vec3 emission{0.f}; ///< W/(m^2 sr), front side
        /// Density per m^2 with which sampleEmitters picks a point on this surface: the same on
        /// all its triangles, since they are picked in proportion to power (area * radiance).
        float emitterDensity = 0.f;
        bool inScene = false;
    };
    struct EmitterTriangle {
        glm::vec3 corner{0.f}, edge1{0.f}, edge2{0.f}; ///< world space, metres
        glm::vec3 normal{0.f};                         ///< unit, front side
        glm::vec3 emission{0.f};                       ///< W/(m^2 sr)
        float density = 0.f;                           ///< the surface's emitterDensity
    };
    enum class LightKind { Point, Spot, Directional };
    struct PunctualLight {
        LightKind kind = LightKind::Point;
        glm::vec3 position{0.f};  ///< metres (point, spot)
        glm::vec3 direction{0.f}; ///< unit, where the light travels (spot axis, directional)
        glm::vec3 radiance{0.f};  ///< W/sr (point, spot) or W/m^2 (directional)
        float coneScale = 0.f, coneOffset = 0.f; ///< spot: falloff t = cos * scale + offset
    };

    void addSurfaces(const Registry& registry);
    void addLights(const Registry& registry);
    /// Direct irradiance of the punctual lights at z on the side of unit normal n, shadowed.
    glm::vec3 punctualIrradiance(const glm::vec3& z, const glm::vec3& n) const;
    /// One MIS-weighted sample of the emitters' direct irradiance at z.
    glm::vec3 sampleEmitters(const glm::vec3& z, const glm::vec3& n, Random& random) const;
    /// One path's estimate of E(x), less the punctual lights' direct light at x.
    glm::dvec3 tracePath(const glm::vec3& x, const glm::vec3& n, Random& random) const;

    const RayScene& mRays;
    ReferenceSettings mSettings;
    std::vector<Surface> mSurfaces; ///< indexed by Entity::index of the meshes in mRays
    std::vector<EmitterTriangle> mEmitters;
    std::vector<double> mEmitterCdf; ///< running share of emitted power, last entry 1
    std::vector<PunctualLight> mLights;
    glm::vec3 mEnvironment{0.f}; ///< W/(m^2 sr), zero unless includeEnvironment
};

/// One-shot forms: build an IrradianceReference and estimate.
IrradianceEstimate estimateIrradiance(const Registry& registry, const RayScene& scene,
                                      const glm::vec3& x, const glm::vec3& n,
                                      const ReferenceSettings& settings);
std::vector<IrradianceEstimate> estimateIrradiance(const Registry& registry, const RayScene& scene,
                                                   std::span<const glm::vec3> x,
                                                   std::span<const glm::vec3> n,
                                                   const ReferenceSettings& settings);

} // namespace qgi::reference
