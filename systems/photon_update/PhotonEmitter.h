#pragma once

#include "runtime/ecs/Entity.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonHead.h"
#include "systems/photon_update/PhotonSampling.h"
#include "systems/photon_update/PhotonSettings.h"

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include <cstdint>
#include <cstring>
#include <vector>

namespace qgi {

class Registry;

enum class EmitterKind : std::uint8_t { Point, Spot, Directional, Surface };

/** One light as the photon tracer shoots it (seed 004 section 3; seed 000's "lights").
 *
 *  The *source* fields are the light's component values and pose: the system reads them every
 *  frame and compares them with those it shot, to notice a light that moved or changed.
 *  prepareEmitter derives the rest: the power and what sampling needs, in world space.
 *
 *  Emission, with (h0 .. h4) the seeded Halton point of the photon's index:
 *   - Point: uniform on the sphere; power 4 pi I.
 *   - Spot: a true cone about the axis, cos(angle) distributed as the renderer's falloff, so
 *     photons keep equal power; power = I times the falloff's integral over the sphere.
 *   - Directional: parallel rays from a rectangle across the light's direction that covers
 *     the scene box's shadow; power = E times the rectangle's area.
 *   - Surface (an emissive StaticMesh or MobileMesh): a triangle with probability in
 *     proportion to its area (radiance is uniform over one Material), a point uniform on it
 *     (seed 004 Eq 11), a cosine-weighted direction on its front side; power = pi L A.       */
struct PhotonEmitter {
    /// One triangle of an emissive mesh, world space.
    struct Triangle {
        glm::vec3 corner{0.f}; ///< v0
        glm::vec3 edge1{0.f};  ///< v1 - v0
        glm::vec3 edge2{0.f};  ///< v2 - v0
        glm::vec3 normal{0.f}; ///< unit, on the emitting (front) side
    };

    // ---- source ----------------------------------------------------------------------------
    EmitterKind kind = EmitterKind::Point;
    Entity entity;
    glm::mat4 world{1.f}; ///< the entity's WorldTransform
    /// Point, spot: colour x intensity, W/sr. Directional: colour x irradiance, W/m^2.
    /// Surface: Material::emission, W/(m^2 sr).
    glm::vec3 radiant{0.f};
    float innerAngle = 0.f; ///< spot, radians, half angle
    float outerAngle = 0.f; ///< spot, radians, half angle
    /// Kept by the photon update for a light that is no longer among the sources (its entity,
    /// light component, pose or emission gone, or an emissive mobile out of the world): dark,
    /// its photons re-shot empty, then free for other lights; listed again, it shines from
    /// those it still has. A full shot drops it.
    bool absent = false;
    /// Also absent: a stand-in the photon update made to hold a light's former photons when
    /// the light was given new ones (its share dealt anew); it re-shoots them empty. No source
    /// matches it.
    bool ghost = false;

    // ---- derived (prepareEmitter) ------------------------------------------------------------
    glm::vec3 power{0.f};    ///< W emitted, linear RGB; 0 for a light that cannot emit
    glm::vec3 position{0.f}; ///< point, spot
    glm::vec3 axis{0.f};     ///< spot axis; directional: the direction light travels
    photon::SpotCone cone{0.f, 0.7853982f};
    glm::vec3 footprintCorner{0.f}; ///< directional: the rectangle's corner and edges
    glm::vec3 footprintU{0.f};
    glm::vec3 footprintV{0.f};
    std::vector<Triangle> triangles; ///< surface: triangles with non-zero area
    std::vector<float> triangleCdf;  ///< surface: cumulative area fraction, last entry 1
    /// Hybrid mode's renderer draws this light's direct light: always for point, spot and
    /// directional lights; for a surface, when it has a LightStandIn (hasLightStandIn) as
    /// prepared.
    bool directDrawn = false;

    // ---- photons (the system's allocation) ---------------------------------------------------
    std::uint32_t firstPhoton = 0; ///< this light's photons are [first, first + count)
    std::uint32_t photonCount = 0;

    /// Bit for bit, so that a light left as it was is the same even where it holds a NaN
    /// (which compares unequal to itself: such a light was prepared, and warned about, anew
    /// every frame).
    bool sameSource(const PhotonEmitter& other) const {
        const auto same = [](const auto& a, const auto& b) {
            return std::memcmp(&a, &b, sizeof a) == 0;
        };
        return kind == other.kind && entity == other.entity && same(world, other.world) &&
               same(radiant, other.radiant) && same(innerAngle, other.innerAngle) &&
               same(outerAngle, other.outerAngle);
    }
};

/// Appends the sources of every light the settings enable, in a fixed order (point, spot,
/// directional, then emissive meshes, each in registry order); fields other than the source
/// ones keep their defaults. A mesh that emits nothing, or an emissive mobile out of the world
/// (MobileMesh::active false), is no source. Reads only components: cheap enough for every
/// frame.
void findEmitterSources(const Registry& registry, const PhotonSettings& settings,
                        std::vector<PhotonEmitter>& out);

/// Derives power and sampling data from the source; `sceneBox` bounds what a directional light
/// must cover. A light with a non-finite, negative or out-of-range value gets power 0 and a
/// warning naming the entity and field (the frame never throws).
void prepareEmitter(const Registry& registry, const Aabb& sceneBox, PhotonEmitter& emitter);

/// The first segment of photon `photon` (emitter.firstPhoton <= photon < first + count): its
/// share emitter.power / photonCount, and a ray drawn from the photon's Halton point.
PhotonHead emitPhoton(const PhotonEmitter& emitter, std::uint32_t photon, std::uint64_t seed);

} // namespace qgi
