#pragma once

#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/scene/SceneInfo.h"

#include <string>

namespace qgi {

/// The camera the scene is seen through: the first Camera with `active` set, else the first
/// Camera; null when there is none. Every consumer (renderer, demo input) uses this one rule.
Entity findActiveCamera(const Registry& registry);

/// Whether a point or spot light tagged LightStandIn sits at the place of the mesh `surface`:
/// within the bounds of its world-space vertices, widened by a quarter of their diagonal (at
/// least 5 cm). Hybrid mode's renderer then draws that lamp's direct light through the
/// stand-in, so nothing else may count it again (photons leaving the surface, probes seeing
/// its emission). False when `surface` has no Mesh or WorldTransform.
bool hasLightStandIn(const Registry& registry, Entity surface);

/// How messages name an entity: its Name in quotes ("'crate'"), else "entity N".
std::string entityName(const Registry& registry, Entity e);

/// Whether `mesh` is a MobileMesh taken out of the world (MobileMesh::active false): it takes
/// no part in the light, is not drawn and is no part of the scene's bounds.
inline bool outOfWorld(const Registry& registry, Entity mesh) {
    const MobileMesh* mobile = registry.tryGet<MobileMesh>(mesh);
    return mobile && !mobile->active;
}

/// Calls `visit(e)` for each entity whose WorldTransform or MobileMesh changed since the last
/// clearChanges(): the mobiles that may have moved, been taken out or been put back. The two
/// change lists come one after the other, so an entity may be visited twice.
template <typename Visit> void forEachMovedOrSwitched(const Registry& registry, Visit&& visit) {
    for (const Entity e : registry.changed<WorldTransform>())
        visit(e);
    for (const Entity e : registry.changed<MobileMesh>())
        visit(e);
}

/// A SceneInfo for meshes built in code (the loaders write their own): the world bounds of
/// every StaticMesh and MobileMesh (but mobiles out of the world: a pool may wait anywhere),
/// and their longest triangle edge as the edge bound (refine
/// meshes with processMesh first: per-vertex lighting needs vertices where light changes).
/// Named "scene", source "code", no environment light.
SceneInfo describeMeshes(const Registry& registry);

} // namespace qgi
