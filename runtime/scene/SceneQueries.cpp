#include "runtime/scene/SceneQueries.h"

#include "components/Camera.h"
#include "components/LightStandIn.h"
#include "components/Mesh.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
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

} // namespace qgi
