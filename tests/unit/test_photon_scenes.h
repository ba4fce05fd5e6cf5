#pragma once
// Small hand-built scenes for the photon tests: meshes, registries, frames.

#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "test_detp_world.h"
#include "test_meshes.h"

#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <cstring>
#include <string>

namespace qgi::test {

inline glm::mat4 translation(const glm::vec3& t) {
    return glm::translate(glm::mat4(1.f), t);
}

inline Material grey(float albedo) {
    Material m;
    m.baseColor = glm::vec3(albedo);
    return m;
}

inline Entity addMesh(Registry& registry, Mesh mesh, const glm::mat4& world,
                      const Material& material, bool mobile, const char* name) {
    const Entity e = addReceiverMesh(registry, std::move(mesh), world, mobile, name);
    registry.emplace<Material>(e, material);
    return e;
}

inline Entity addPointLight(Registry& registry, const glm::vec3& at, float intensity,
                            const glm::vec3& color = glm::vec3(1.f)) {
    const Entity e = registry.create();
    registry.emplace<WorldTransform>(e, translation(at));
    registry.emplace<PointLight>(e, PointLight{color, intensity});
    return e;
}

/// Builds the RayScene world resource from the registry's meshes.
inline RayScene& buildRayScene(Registry& registry) {
    RayScene& scene = registry.ctx().emplace<RayScene>();
    scene.build(registry);
    return scene;
}

/// A room open at the top (some photons escape) with a static pillar, a point light and two
/// mobile cubes; the frame's first update is left to the caller.
struct Room {
    Entity walls, pillar, cube, crate, light;
};

inline Room buildRoom(Registry& registry, const glm::vec3& cubeAt, const glm::vec3& crateAt) {
    Room room;
    room.walls = addMesh(registry, boxMesh({2.f, 1.5f, 2.f}, true, true), glm::mat4(1.f),
                         grey(0.7f), false, "walls");
    Material red;
    red.baseColor = {0.8f, 0.3f, 0.2f};
    room.pillar = addMesh(registry, boxMesh({0.2f, 1.5f, 0.2f}), translation({1.f, 0.f, 1.f}), red,
                          false, "pillar");
    room.cube =
        addMesh(registry, boxMesh(glm::vec3(0.25f)), translation(cubeAt), grey(0.6f), true, "cube");
    room.crate = addMesh(registry, boxMesh(glm::vec3(0.2f)), translation(crateAt), grey(0.5f), true,
                         "crate");
    room.light = addPointLight(registry, {0.f, 1.2f, 0.f}, 10.f);
    return room;
}

/// One frame the way the schedule runs it: the pose change is recorded, the ray scene synced,
/// then the photon system updates; the change lists are cleared at the end.
inline void moveAndUpdate(Registry& registry, PhotonUpdateSystem& system, Entity mobile,
                          const glm::mat4& pose, std::uint64_t frameIndex) {
    registry.patch<WorldTransform>(mobile).matrix = pose;
    registry.ctx().get<RayScene>().syncMoved(registry);
    system.update(registry, FrameContext{frameIndex, 0.0, 0.f, 0});
    registry.clearChanges();
}

inline void firstUpdate(Registry& registry, PhotonUpdateSystem& system) {
    system.update(registry, FrameContext{});
    registry.clearChanges();
}

/// Bitwise equality of segment s of a and segment t of b, every field.
inline bool sameSegment(const PhotonSegments& a, std::size_t s, const PhotonSegments& b,
                        std::size_t t) {
    const auto same = [](const auto& x, const auto& y) {
        return std::memcmp(&x, &y, sizeof x) == 0;
    };
    return same(a.origin[s], b.origin[t]) && same(a.direction[s], b.direction[t]) &&
           same(a.length[s], b.length[t]) && same(a.power[s], b.power[t]) &&
           a.hitEntity[s] == b.hitEntity[t] && a.hitPrimitive[s] == b.hitPrimitive[t] &&
           a.bounce[s] == b.bounce[t];
}

/// Every path of a equals the same path of b, bit for bit (wherever the stores keep them).
inline ::testing::AssertionResult sameStore(const PhotonStore& a, const PhotonStore& b) {
    if (a.pathCount() != b.pathCount())
        return ::testing::AssertionFailure()
               << a.pathCount() << " vs " << b.pathCount() << " paths";
    for (std::size_t p = 0; p < a.pathCount(); ++p) {
        const PhotonPath& pa = a.paths[p];
        const PhotonPath& pb = b.paths[p];
        if (pa.count != pb.count || pa.light != pb.light)
            return ::testing::AssertionFailure()
                   << "path " << p << ": " << pa.count << " vs " << pb.count << " segments";
        for (std::size_t k = 0; k < pa.count; ++k)
            if (!sameSegment(a.segments, pa.first + k, b.segments, pb.first + k))
                return ::testing::AssertionFailure() << "path " << p << " differs at segment " << k;
    }
    return ::testing::AssertionSuccess();
}

/// The stores keep every path at the same place, in stores of the same size (what lies
/// between paths, room for re-traced ones, is not compared: it holds nothing).
inline ::testing::AssertionResult sameLayout(const PhotonStore& a, const PhotonStore& b) {
    if (a.segments.size() != b.segments.size())
        return ::testing::AssertionFailure()
               << a.segments.size() << " vs " << b.segments.size() << " segments";
    for (std::size_t p = 0; p < std::min(a.pathCount(), b.pathCount()); ++p)
        if (a.paths[p].first != b.paths[p].first)
            return ::testing::AssertionFailure() << "path " << p << " starts at "
                                                 << a.paths[p].first << " vs " << b.paths[p].first;
    return ::testing::AssertionSuccess();
}

} // namespace qgi::test
