#pragma once

#include "components/Material.h"
#include "components/Transform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/scene/ProceduralMesh.h"

#include <glm/vec3.hpp>

#include <string>
#include <vector>

namespace qgi {

/// Populates a registry with a scene described in code. Entities are created as they are
/// added; their meshes are kept raw until finish(), which processes all of them in parallel
/// (each one independently, so the result does not depend on thread timing), then records
/// the SceneInfo and an empty TextureLibrary. Built-in scenes are flat: every entity is a root,
/// so its WorldTransform is its Transform's matrix.
class BuiltinSceneBuilder {
public:
    BuiltinSceneBuilder(Registry& registry, std::string name, float maxEdgeLength);

    Registry& registry() { return mRegistry; }

    /// An entity with Name, Transform and the matching WorldTransform.
    Entity addEntity(std::string name, const Transform& transform);
    /// addEntity plus the raw Mesh (processed in finish()) and its Material. The caller adds
    /// StaticMesh, MobileMesh or Avatar.
    Entity addMesh(std::string name, const Transform& transform, ProceduralMesh&& mesh,
                   const Material& material);

    /// Processes the meshes and emplaces SceneInfo (bounds, edge bound, `environment` sky
    /// radiance in W/(m^2 sr)) and TextureLibrary.
    void finish(const glm::vec3& environment);

private:
    Registry& mRegistry;
    std::string mName;
    float mMaxEdgeLength;
    std::vector<Entity> mMeshEntities;
};

} // namespace qgi
