#include "runtime/scene/BuiltinSceneBuilder.h"

#include "components/Mesh.h"
#include "components/Name.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/scene/MeshProcessing.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/TextureLibrary.h"

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <tbb/parallel_for.h>

#include <utility>

namespace qgi {

BuiltinSceneBuilder::BuiltinSceneBuilder(Registry& registry, std::string name, float maxEdgeLength)
    : mRegistry(registry), mName(std::move(name)), mMaxEdgeLength(maxEdgeLength) {}

Entity BuiltinSceneBuilder::addEntity(std::string name, const Transform& transform) {
    QGI_ASSERT(transform.parent.isNull(), "built-in scenes have no hierarchy");
    const Entity e = mRegistry.create();
    mRegistry.emplace<Name>(e, Name{std::move(name)});
    mRegistry.emplace<Transform>(e, transform);
    const glm::mat4 matrix = glm::translate(glm::mat4(1.f), transform.translation) *
                             glm::mat4_cast(transform.rotation) *
                             glm::scale(glm::mat4(1.f), transform.scale);
    mRegistry.emplace<WorldTransform>(e, WorldTransform{matrix});
    return e;
}

Entity BuiltinSceneBuilder::addMesh(std::string name, const Transform& transform,
                                    ProceduralMesh&& mesh, const Material& material) {
    const Entity e = addEntity(std::move(name), transform);
    mRegistry.emplace<Mesh>(e, std::move(mesh).release());
    mRegistry.emplace<Material>(e, material);
    mMeshEntities.push_back(e);
    return e;
}

void BuiltinSceneBuilder::finish(const glm::vec3& environment) {
    std::vector<Mesh*> meshes;
    meshes.reserve(mMeshEntities.size());
    for (const Entity e : mMeshEntities)
        meshes.push_back(&mRegistry.get<Mesh>(e));
    // One limit for the whole scene, shared by meshes processed in parallel.
    TriangleBudget budget(kSceneMaxTriangles);
    MeshProcessingOptions options;
    options.maxEdgeLength = mMaxEdgeLength;
    options.budget = &budget;
    tbb::parallel_for(std::size_t(0), meshes.size(), [&](std::size_t i) {
        try {
            *meshes[i] = processMesh(*meshes[i], options);
        } catch (const Error& e) {
            fail("built-in scene '", mName, "': ", e.what());
        }
    });

    SceneInfo info;
    info.name = mName;
    info.source = "builtin:" + mName;
    info.environment = environment;
    info.maxEdgeLength = mMaxEdgeLength;
    for (const Entity e : mMeshEntities) {
        const glm::mat4& matrix = mRegistry.get<WorldTransform>(e).matrix;
        for (const glm::vec3& p : mRegistry.get<Mesh>(e).positions)
            info.bounds.extend(glm::vec3(matrix * glm::vec4(p, 1.f)));
    }
    mRegistry.ctx().emplace<SceneInfo>(std::move(info));
    mRegistry.ctx().emplace<TextureLibrary>();
}

} // namespace qgi
