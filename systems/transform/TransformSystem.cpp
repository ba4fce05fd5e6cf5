#include "systems/transform/TransformSystem.h"

#include "components/Transform.h"
#include "components/WorldTransform.h"

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtx/quaternion.hpp>

#include <vector>

namespace qgi {

glm::mat4 localMatrix(const Transform& t) {
    return glm::translate(glm::mat4(1.f), t.translation) * glm::toMat4(t.rotation) *
           glm::scale(glm::mat4(1.f), t.scale);
}

namespace {

// True when e or one of its ancestors had its Transform changed this frame.
bool chainChanged(const Registry& registry, Entity e) {
    for (int depth = 0; e && depth < 256; ++depth) {
        if (registry.wasChanged<Transform>(e)) return true;
        const Transform* t = registry.tryGet<Transform>(e);
        if (!t) return false;
        e = t->parent;
    }
    return false;
}

glm::mat4 worldMatrix(const Registry& registry, Entity e) {
    glm::mat4 m(1.f);
    // Parents are few levels deep in practice; the importer rejects cycles, the depth cap
    // keeps a bug from hanging the frame.
    for (int depth = 0; e && depth < 256; ++depth) {
        const Transform* t = registry.tryGet<Transform>(e);
        if (!t) break;
        m = localMatrix(*t) * m;
        e = t->parent;
    }
    return m;
}

} // namespace

void TransformSystem::update(Registry& registry, const FrameContext& /*frame*/) {
    if (registry.changed<Transform>().empty()) return; // a still scene costs nothing

    std::vector<std::pair<Entity, glm::mat4>> updates;
    registry.view<const Transform>().each([&](Entity e, const Transform&) {
        if (chainChanged(registry, e)) updates.emplace_back(e, worldMatrix(registry, e));
    });
    for (const auto& [e, m] : updates) {
        if (WorldTransform* w = registry.tryGet<WorldTransform>(e)) {
            if (w->matrix != m) registry.patch<WorldTransform>(e).matrix = m;
        } else {
            registry.emplace<WorldTransform>(e, WorldTransform{m});
        }
    }
}

} // namespace qgi
