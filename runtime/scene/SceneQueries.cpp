#include "runtime/scene/SceneQueries.h"

#include "components/Camera.h"

namespace qgi {

Entity findActiveCamera(const Registry& registry) {
    Entity first{}, active{};
    registry.view<const Camera>().each([&](Entity e, const Camera& camera) {
        if (!first) first = e;
        if (camera.active && !active) active = e;
    });
    return active ? active : first;
}

} // namespace qgi
