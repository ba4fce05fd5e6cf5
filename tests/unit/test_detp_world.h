#pragma once
// The bare worlds the DETP and estimator tests build: receiver meshes without materials and the
// world resources the irradiance system reads.

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "systems/photon_update/PhotonStore.h"

#include <glm/mat4x4.hpp>

namespace qgi::test {

/// A mesh entity to be lit: Name, Mesh, WorldTransform and StaticMesh or MobileMesh (no
/// Material). Unnamed: "mobile" or "static".
inline Entity addReceiverMesh(Registry& registry, Mesh mesh, const glm::mat4& world, bool mobile,
                              const char* name = nullptr) {
    const Entity e = registry.create();
    registry.emplace<Name>(e, name ? name : (mobile ? "mobile" : "static"));
    registry.emplace<Mesh>(e, std::move(mesh));
    registry.emplace<WorldTransform>(e, world);
    if (mobile)
        registry.emplace<MobileMesh>(e);
    else
        registry.emplace<StaticMesh>(e);
    return e;
}

/// The world resources the irradiance system reads: the RayScene (its Embree device hosts the
/// discs), an empty ray set and a delta that asks for a full estimate.
inline void addDetpResources(Registry& registry) {
    registry.ctx().emplace<RayScene>();
    registry.ctx().emplace<PhotonStore>();
    registry.ctx().emplace<PhotonDelta>().full = true;
}

} // namespace qgi::test
