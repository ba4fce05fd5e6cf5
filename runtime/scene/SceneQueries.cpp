#include "runtime/scene/SceneQueries.h"

#include "components/Camera.h"
#include "components/LightStandIn.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/geometric.hpp>

#include <algorithm>

namespace qgi {

Entity findActiveCamera(const Registry& registry) {
    Entity first{}, active{};
    registry.view<const Camera>().each([&](Entity e, const Camera& camera) {
        if (!first) first = e;
        if (camera.active && !active) active = e;
    });
    return active ? active : first;
}

bool hasLightStandIn(const Registry& registry, Entity surface) {
    const Mesh* mesh = registry.tryGet<Mesh>(surface);
    const WorldTransform* world = registry.tryGet<WorldTransform>(surface);
    if (!mesh || !world || mesh->positions.empty()) return false;
    Aabb bounds;
    for (const glm::vec3& p : mesh->positions)
        bounds.extend(glm::vec3(world->matrix * glm::vec4(p, 1.f)));
    const glm::vec3 reach(std::max(0.05f, 0.25f * glm::length(bounds.extent())));
    const Aabb place{bounds.min - reach, bounds.max + reach};
    bool found = false;
    registry.view<const LightStandIn, const WorldTransform>().each(
        [&](Entity light, const LightStandIn&, const WorldTransform& at) {
            const bool punctual = registry.has<PointLight>(light) || registry.has<SpotLight>(light);
            const glm::vec3 p(at.matrix[3]);
            found = found || (punctual && glm::all(glm::greaterThanEqual(p, place.min)) &&
                              glm::all(glm::lessThanEqual(p, place.max)));
        });
    return found;
}

std::string entityName(const Registry& registry, Entity e) {
    const Name* name = registry.tryGet<Name>(e);
    return name ? str("'", name->value, "'") : str("entity ", e.index);
}

SceneInfo describeMeshes(const Registry& registry) {
    SceneInfo info;
    info.name = "scene";
    info.source = "code";
    registry.view<const Mesh, const WorldTransform>().each(
        [&](Entity e, const Mesh& mesh, const WorldTransform& world) {
            if (!registry.has<StaticMesh>(e) && !registry.has<MobileMesh>(e)) return;
            // A pooled mobile out of the world may wait anywhere: not part of the scene's box.
            const bool placed = !outOfWorld(registry, e);
            std::vector<glm::vec3> points(mesh.positions.size());
            for (std::size_t i = 0; i < points.size(); ++i) {
                points[i] = glm::vec3(world.matrix * glm::vec4(mesh.positions[i], 1.f));
                if (placed) info.bounds.extend(points[i]);
            }
            for (std::size_t t = 0; t + 2 < mesh.indices.size(); t += 3)
                for (int k = 0; k < 3; ++k) {
                    const std::uint32_t a = mesh.indices[t + k], b = mesh.indices[t + (k + 1) % 3];
                    if (a < points.size() && b < points.size())
                        info.maxEdgeLength =
                            std::max(info.maxEdgeLength, glm::length(points[a] - points[b]));
                }
        });
    return info;
}

} // namespace qgi
