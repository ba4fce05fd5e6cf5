#include "systems/photon_update/PhotonEmitter.h"

#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/Pose.h"
#include "runtime/scene/SceneQueries.h"

#include <glm/gtc/constants.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace qgi {
namespace {

bool isFinite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

bool isFinite(const glm::mat4& m) {
    for (int c = 0; c < 4; ++c)
        if (!isFinite(glm::vec3(m[c])) || !std::isfinite(m[c][3])) return false;
    return true;
}

bool isNonNegative(const glm::vec3& v) {
    return isFinite(v) && v.x >= 0.f && v.y >= 0.f && v.z >= 0.f;
}

const char* kindName(EmitterKind kind) {
    switch (kind) {
    case EmitterKind::Point:
        return "PointLight";
    case EmitterKind::Spot:
        return "SpotLight";
    case EmitterKind::Directional:
        return "DirectionalLight";
    case EmitterKind::Surface:
        return "Material";
    }
    return "light";
}

/// Logs why the emitter cannot shoot and leaves it dark.
void disable(PhotonEmitter& emitter, const char* field, const char* problem) {
    logWarning("photons: ", kindName(emitter.kind), " of entity ", emitter.entity.index, ": ",
               field, " ", problem, "; the light emits no photons");
    emitter.power = glm::vec3(0.f);
}

/// A rectangle across `direction`, just in front of the box, whose parallel projection along
/// `direction` covers the box.
void coverBox(const Aabb& box, PhotonEmitter& emitter) {
    const photon::Frame frame(emitter.axis);
    glm::vec3 low(std::numeric_limits<float>::max()), high(-std::numeric_limits<float>::max());
    for (int i = 0; i < 8; ++i) {
        const glm::vec3 corner(i & 1 ? box.max.x : box.min.x, i & 2 ? box.max.y : box.min.y,
                               i & 4 ? box.max.z : box.min.z);
        const glm::vec3 p(glm::dot(corner, frame.t), glm::dot(corner, frame.b),
                          glm::dot(corner, frame.n));
        low = glm::min(low, p);
        high = glm::max(high, p);
    }
    // Start a little before the box so no origin lies on a surface at its boundary.
    const float before = 1e-3f * glm::length(box.extent()) + 1e-3f;
    emitter.footprintCorner = frame.t * low.x + frame.b * low.y + frame.n * (low.z - before);
    emitter.footprintU = frame.t * (high.x - low.x);
    emitter.footprintV = frame.b * (high.y - low.y);
}

void prepareSurface(const Registry& registry, PhotonEmitter& emitter) {
    emitter.triangles.clear();
    emitter.triangleCdf.clear();
    const Mesh* mesh = registry.tryGet<Mesh>(emitter.entity);
    if (!mesh) return disable(emitter, "Mesh", "is missing");
    // A mirroring matrix flips the winding, and with it the side the cross product points to.
    const float side = glm::determinant(glm::mat3(emitter.world)) < 0.f ? -1.f : 1.f;
    double area = 0.0;
    for (std::size_t i = 0; i + 2 < mesh->indices.size(); i += 3) {
        std::array<glm::vec3, 3> v;
        for (std::size_t k = 0; k < 3; ++k) {
            const std::uint32_t index = mesh->indices[i + k];
            if (index >= mesh->positions.size())
                return disable(emitter, "Mesh.indices", "has an index out of range");
            v[k] = glm::vec3(emitter.world * glm::vec4(mesh->positions[index], 1.f));
        }
        const glm::vec3 e1 = v[1] - v[0], e2 = v[2] - v[0];
        const glm::vec3 cross = glm::cross(e1, e2);
        const float twiceArea = glm::length(cross);
        if (!(twiceArea > 0.f) || !std::isfinite(twiceArea)) continue;
        emitter.triangles.push_back({v[0], e1, e2, side * cross / twiceArea});
        area += 0.5 * double(twiceArea);
        emitter.triangleCdf.push_back(float(area));
    }
    if (emitter.triangles.empty()) return disable(emitter, "Mesh", "has no triangle with area");
    // A stand-in at the surface's place: hybrid mode's renderer draws the lamp's direct light.
    emitter.directDrawn = hasLightStandIn(registry, emitter.entity);
    for (float& c : emitter.triangleCdf)
        c = float(double(c) / area);
    emitter.triangleCdf.back() = 1.f;
    emitter.power = glm::pi<float>() * float(area) * emitter.radiant;
}

} // namespace

void findEmitterSources(const Registry& registry, const PhotonSettings& settings,
                        std::vector<PhotonEmitter>& out) {
    const auto add = [&](EmitterKind kind, Entity e, const glm::mat4& world) -> PhotonEmitter& {
        PhotonEmitter& emitter = out.emplace_back();
        emitter.kind = kind;
        emitter.entity = e;
        emitter.world = world;
        return emitter;
    };
    if (settings.punctualLights) {
        registry.view<const PointLight, const WorldTransform>().each(
            [&](Entity e, const PointLight& light, const WorldTransform& world) {
                if (registry.has<LightStandIn>(e)) return; // its surface shoots the photons
                add(EmitterKind::Point, e, world.matrix).radiant = light.color * light.intensity;
            });
        registry.view<const SpotLight, const WorldTransform>().each(
            [&](Entity e, const SpotLight& light, const WorldTransform& world) {
                if (registry.has<LightStandIn>(e)) return;
                PhotonEmitter& emitter = add(EmitterKind::Spot, e, world.matrix);
                emitter.radiant = light.color * light.intensity;
                emitter.innerAngle = light.innerConeAngle;
                emitter.outerAngle = light.outerConeAngle;
            });
        registry.view<const DirectionalLight, const WorldTransform>().each(
            [&](Entity e, const DirectionalLight& light, const WorldTransform& world) {
                if (registry.has<LightStandIn>(e)) return;
                add(EmitterKind::Directional, e, world.matrix).radiant =
                    light.color * light.irradiance;
            });
    }
    if (settings.emissiveSurfaces) {
        registry.view<const Material, const Mesh, const WorldTransform>().each(
            [&](Entity e, const Material& material, const Mesh&, const WorldTransform& world) {
                const glm::vec3& l = material.emission;
                // Only meshes the ray scene holds take part in photon transport; a mobile out of
                // the world (MobileMesh::active) shines no light.
                const bool traced = registry.has<StaticMesh>(e) ||
                                    (registry.has<MobileMesh>(e) && !outOfWorld(registry, e));
                if (traced && (l.x != 0.f || l.y != 0.f || l.z != 0.f))
                    add(EmitterKind::Surface, e, world.matrix).radiant = l;
            });
    }
}

void prepareEmitter(const Registry& registry, const Aabb& sceneBox, PhotonEmitter& emitter) {
    emitter.power = glm::vec3(0.f);
    // Set before any check can disable the light: a punctual light is the shader's either way,
    // and a dark one that changed this flag would force a full shot (and warn again).
    emitter.directDrawn = emitter.kind != EmitterKind::Surface; // prepareSurface decides
    if (!isFinite(emitter.world)) return disable(emitter, "WorldTransform.matrix", "is not finite");
    if (!isNonNegative(emitter.radiant))
        return disable(emitter,
                       emitter.kind == EmitterKind::Surface ? "emission" : "colour x intensity",
                       "is negative or not finite");
    if (!isUsableLightRadiance(emitter.radiant))
        return disable(emitter,
                       emitter.kind == EmitterKind::Surface ? "emission" : "colour x intensity",
                       "is above 1e20, past what float lighting can carry");
    emitter.position = glm::vec3(emitter.world[3]);
    if ((emitter.kind == EmitterKind::Point || emitter.kind == EmitterKind::Spot) &&
        !isUsableLightPosition(emitter.position))
        return disable(emitter, "WorldTransform.matrix", "places it more than 1e7 m away");
    switch (emitter.kind) {
    case EmitterKind::Point:
        emitter.power = 4.f * glm::pi<float>() * emitter.radiant;
        break;
    case EmitterKind::Spot: {
        const float inner = emitter.innerAngle, outer = emitter.outerAngle;
        if (!(outer > 0.f && outer <= glm::half_pi<float>()))
            return disable(emitter, "outerConeAngle", "is not in (0, pi/2]");
        if (!(inner >= 0.f && inner < outer))
            return disable(emitter, "innerConeAngle", "is not in [0, outerConeAngle)");
        emitter.axis = lightForward(emitter.world);
        if (emitter.axis == glm::vec3(0.f))
            return disable(emitter, "WorldTransform.matrix", "has no -Z axis");
        emitter.cone = photon::SpotCone(inner, outer);
        emitter.power = emitter.cone.solidAngle() * emitter.radiant;
        break;
    }
    case EmitterKind::Directional:
        emitter.axis = lightForward(emitter.world);
        if (emitter.axis == glm::vec3(0.f))
            return disable(emitter, "WorldTransform.matrix", "has no -Z axis");
        if (sceneBox.empty()) return disable(emitter, "scene", "is empty");
        coverBox(sceneBox, emitter);
        emitter.power =
            glm::length(emitter.footprintU) * glm::length(emitter.footprintV) * emitter.radiant;
        break;
    case EmitterKind::Surface:
        prepareSurface(registry, emitter);
        break;
    }
    // An intensity near float's limit overflows once spread over the sphere or a footprint.
    if (!isFinite(emitter.power)) disable(emitter, "power", "overflows a float");
}

PhotonHead emitPhoton(const PhotonEmitter& emitter, std::uint32_t photon, std::uint64_t seed) {
    const auto h = [&](std::uint32_t dimension) { return photon::halton(dimension, photon, seed); };
    PhotonHead head;
    head.photon = photon;
    // A dark light (switched off, or disabled: then its geometry may be unusable) emits a
    // photon with no power, which the tracer does not trace.
    if (!carriesPower(emitter.power)) return head;
    head.power = emitter.power / float(emitter.photonCount);
    switch (emitter.kind) {
    case EmitterKind::Point:
        head.origin = emitter.position;
        head.direction = photon::sampleSphere(h(0), h(1));
        break;
    case EmitterKind::Spot:
        head.origin = emitter.position;
        head.direction =
            photon::directionAbout(photon::Frame(emitter.axis), emitter.cone.sampleCos(h(0)), h(1));
        break;
    case EmitterKind::Directional:
        head.origin =
            emitter.footprintCorner + h(0) * emitter.footprintU + h(1) * emitter.footprintV;
        head.direction = emitter.axis;
        break;
    case EmitterKind::Surface: {
        const auto it =
            std::upper_bound(emitter.triangleCdf.begin(), emitter.triangleCdf.end(), h(0));
        const std::size_t index =
            std::min(std::size_t(it - emitter.triangleCdf.begin()), emitter.triangles.size() - 1);
        const PhotonEmitter::Triangle& tri = emitter.triangles[index];
        const glm::vec2 st = photon::sampleTriangle(h(1), h(2));
        const glm::vec3 point = tri.corner + st.x * tri.edge1 + st.y * tri.edge2;
        head.origin = photon::offsetFromSurface(point, tri.normal);
        head.direction = photon::sampleCosine(photon::Frame(tri.normal), h(3), h(4));
        break;
    }
    }
    return head;
}

} // namespace qgi
