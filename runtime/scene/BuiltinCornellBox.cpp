#include "runtime/scene/BuiltinCornellBox.h"

#include "components/Avatar.h"
#include "components/Camera.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/LightStandIn.h"
#include "runtime/scene/SceneInfo.h"
#include "components/PointLight.h"
#include "components/StaticMesh.h"
#include "runtime/scene/BuiltinPaths.h"

#include <glm/gtc/constants.hpp>

#include <array>
#include <cmath>

namespace qgi {
namespace {

using Quad = std::array<glm::vec3, 4>;

/// A point of the published data (millimetres, the data's frame) in scene metres.
glm::vec3 fromData(float x, float y, float z) {
    return glm::vec3(278.f - x, y, -z) * 0.001f;
}

Quad quadFromData(const std::array<float, 12>& mm) {
    return {fromData(mm[0], mm[1], mm[2]), fromData(mm[3], mm[4], mm[5]),
            fromData(mm[6], mm[7], mm[8]), fromData(mm[9], mm[10], mm[11])};
}

glm::vec3 centroid(const Quad& q) {
    return 0.25f * (q[0] + q[1] + q[2] + q[3]);
}

ProceduralMesh quadMesh(const Quad& q, const glm::vec3& facing) {
    ProceduralMesh mesh;
    mesh.addQuad(q[0], q[1], q[2], q[3], facing);
    return mesh;
}

// A block from its published top face and four sides; it stands on the floor, so there is no
// bottom. Faces look away from the block's centre; positions are taken relative to `origin`.
ProceduralMesh blockMesh(const std::array<Quad, 5>& faces, const glm::vec3& origin) {
    glm::vec3 center(0.f);
    for (const Quad& q : faces)
        center += 0.2f * centroid(q);
    ProceduralMesh mesh;
    for (const Quad& q : faces)
        mesh.addQuad(q[0] - origin, q[1] - origin, q[2] - origin, q[3] - origin,
                     centroid(q) - center);
    return mesh;
}

// Reflectances: RGB approximations of the published spectral reflectance curves.
Material diffuse(const glm::vec3& albedo) {
    Material m;
    m.baseColor = albedo;
    return m;
}
const Material kWhite = diffuse({0.725f, 0.71f, 0.68f});
const Material kRed = diffuse({0.63f, 0.065f, 0.05f});
const Material kGreen = diffuse({0.14f, 0.45f, 0.091f});

// The luminaire: 130 x 105 mm, hung 0.5 mm below the ceiling so the two never share a depth.
// A Lambertian emitter of radiance L and area A emits pi * L * A watts; 15 W (white) puts it
// in the 10-20 W range of a small lamp.
constexpr float kLightPower = 15.f;           // W
constexpr float kLightArea = 0.130f * 0.105f; // m^2
constexpr float kLightDrop = 0.5f;            // mm below the ceiling
constexpr float kCeiling = 548.8f;            // mm
// The punctual stand-in for hybrid mode's direct light, 2 cm below the luminaire, with the
// same total power (4 pi I = kLightPower). Tagged LightStandIn: it shoots no photons.
constexpr float kPointLightDrop = 20.f; // mm below the luminaire

// Standard camera: 35 mm focal length on a 25 mm film.
const float kCameraFov = 2.f * std::atan(12.5f / 35.f); // ~39.3 degrees

} // namespace

void buildCornellBox(BuiltinSceneBuilder& builder) {
    Registry& registry = builder.registry();
    const auto addStatic = [&](const char* name, ProceduralMesh&& mesh, const Material& material) {
        registry.emplace<StaticMesh>(builder.addMesh(name, Transform{}, std::move(mesh), material));
    };
    const glm::vec3 up(0.f, 1.f, 0.f);
    const glm::vec3 right(1.f, 0.f, 0.f);

    addStatic("floor",
              quadMesh(quadFromData({552.8f, 0, 0, 0, 0, 0, 0, 0, 559.2f, 549.6f, 0, 559.2f}), up),
              kWhite);
    addStatic("ceiling",
              quadMesh(quadFromData({556, kCeiling, 0, 556, kCeiling, 559.2f, 0, kCeiling, 559.2f,
                                     0, kCeiling, 0}),
                       -up),
              kWhite);
    addStatic("back wall",
              quadMesh(quadFromData({549.6f, 0, 559.2f, 0, 0, 559.2f, 0, kCeiling, 559.2f, 556,
                                     kCeiling, 559.2f}),
                       glm::vec3(0.f, 0.f, 1.f)),
              kWhite);
    addStatic("left wall (red)",
              quadMesh(quadFromData({552.8f, 0, 0, 549.6f, 0, 559.2f, 556, kCeiling, 559.2f, 556,
                                     kCeiling, 0}),
                       right),
              kRed);
    addStatic("right wall (green)",
              quadMesh(quadFromData({0, 0, 559.2f, 0, 0, 0, 0, kCeiling, 0, 0, kCeiling, 559.2f}),
                       -right),
              kGreen);
    addStatic("tall block",
              blockMesh({quadFromData({423, 330, 247, 265, 330, 296, 314, 330, 456, 472, 330, 406}),
                         quadFromData({423, 0, 247, 423, 330, 247, 472, 330, 406, 472, 0, 406}),
                         quadFromData({472, 0, 406, 472, 330, 406, 314, 330, 456, 314, 0, 456}),
                         quadFromData({314, 0, 456, 314, 330, 456, 265, 330, 296, 265, 0, 296}),
                         quadFromData({265, 0, 296, 265, 330, 296, 423, 330, 247, 423, 0, 247})},
                        glm::vec3(0.f)),
              kWhite);

    const float lightY = kCeiling - kLightDrop;
    // The diffuser only emits (albedo 0): with the published 0.78 the point light hung 2 cm below
    // would light it to about twice its own emitted radiance.
    Material luminaire = diffuse(glm::vec3(0.f));
    luminaire.emission = glm::vec3(kLightPower / (glm::pi<float>() * kLightArea));
    addStatic("light",
              quadMesh(quadFromData({343, lightY, 227, 343, lightY, 332, 213, lightY, 332, 213,
                                     lightY, 227}),
                       -up),
              luminaire);
    const Entity lamp = builder.addEntity(
        "light (point)", Transform{fromData(278, lightY - kPointLightDrop, 279.5f)});
    registry.emplace<PointLight>(
        lamp, PointLight{glm::vec3(1.f), kLightPower / (4.f * glm::pi<float>())});
    registry.emplace<LightStandIn>(lamp); // the luminaire's photons carry its light

    // The short block, mobile: its origin is the centre of its footprint, and it slides 5 cm
    // towards the green wall and back at 2 cm/s.
    const std::array<Quad, 5> shortBlock{
        quadFromData({130, 165, 65, 82, 165, 225, 240, 165, 272, 290, 165, 114}),
        quadFromData({290, 0, 114, 290, 165, 114, 240, 165, 272, 240, 0, 272}),
        quadFromData({130, 0, 65, 130, 165, 65, 290, 165, 114, 290, 0, 114}),
        quadFromData({82, 0, 225, 82, 165, 225, 130, 165, 65, 130, 0, 65}),
        quadFromData({240, 0, 272, 240, 165, 272, 82, 165, 225, 82, 0, 225})};
    const glm::vec3 rest = centroid(shortBlock[0]) * glm::vec3(1.f, 0.f, 1.f);
    const Entity block =
        builder.addMesh("short block", Transform{rest}, blockMesh(shortBlock, rest), kWhite);
    registry.emplace<MobileMesh>(block);
    const glm::vec3 slid = rest + glm::vec3(0.05f, 0.f, 0.f);
    registry.emplace<PathFollower>(block, PathFollower{{{0.f, rest}, {2.5f, slid}, {5.f, rest}}});

    // A 15 cm character walking a 14 x 15 cm loop at 10 cm/s between the red wall, the tall
    // block and the open front; its origin is its centre, 75 mm above the floor.
    constexpr float kAvatarHeight = 0.15f, kAvatarRadius = 0.03f;
    ProceduralMesh body;
    body.addCapsule(glm::vec3(0.f), kAvatarRadius, kAvatarHeight, 12, 3);
    const std::array<glm::vec3, 4> loop{fromData(480, 75, 40), fromData(480, 75, 190),
                                        fromData(340, 75, 190), fromData(340, 75, 40)};
    PathFollower walk = walkingLoop(loop, 0.1f, 0.4f);
    const Entity avatar = builder.addMesh("avatar", Transform{loop[0], walk.keys[0].rotation},
                                          std::move(body), diffuse({0.2f, 0.3f, 0.7f}));
    registry.emplace<Avatar>(avatar, Avatar{0.5f * kAvatarHeight});
    registry.emplace<PathFollower>(avatar, std::move(walk));

    // The standard view, swaying 6 cm to each side while keeping the back wall's centre in view.
    const glm::vec3 eye = fromData(278, 273, -800);
    const glm::vec3 target = fromData(278, 273, 559.2f);
    const auto view = [&](float time, const glm::vec3& offset) {
        return PathKey{time, eye + offset, facing(target - eye - offset)};
    };
    PathFollower sway{{view(0.f, glm::vec3(0.f)), view(4.f, {0.06f, 0.012f, -0.02f}),
                       view(8.f, glm::vec3(0.f)), view(12.f, {-0.06f, -0.008f, -0.02f}),
                       view(16.f, glm::vec3(0.f))}};
    const Entity camera = builder.addEntity("camera", Transform{eye, sway.keys[0].rotation});
    registry.emplace<Camera>(camera, Camera{kCameraFov, 0.05f, 20.f, true});
    registry.emplace<PathFollower>(camera, std::move(sway));

    builder.finish(glm::vec3(0.f)); // nothing outside: the open front looks into the dark
    // 15 W in a box half a metre wide: walls reach a few hundred W/m^2.
    registry.ctx().get<SceneInfo>().exposure = 0.3f;
}

void buildCornellBoxGlossy(BuiltinSceneBuilder& builder) {
    buildCornellBox(builder);
    Registry& registry = builder.registry();
    registry.view<const Name, Material>().each([](Entity, const Name& name, Material& m) {
        if (name.value == "floor") {
            m.baseColor *= 0.4f;
            m.specular = glm::vec3(0.5f);
            m.phongExponent = 40.f;
            m.metallic = 0.5f;
            m.roughness = 0.467f; // (2 / (n_s + 2))^(1/4): the matching glTF roughness
        } else if (name.value == "tall block") {
            m.baseColor = glm::vec3(0.05f);
            m.specular = glm::vec3(0.85f);
            m.phongExponent = 0.f;
            m.metallic = 0.85f;
            m.roughness = 0.f;
        }
    });
}

} // namespace qgi
