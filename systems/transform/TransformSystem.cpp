#include "systems/transform/TransformSystem.h"

#include "components/Transform.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/scene/SceneQueries.h"

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtx/quaternion.hpp>

#include <optional>
#include <vector>

namespace qgi {

glm::mat4 localMatrix(const Transform& t) {
    return glm::translate(glm::mat4(1.f), t.translation) * glm::toMat4(t.rotation) *
           glm::scale(glm::mat4(1.f), t.scale);
}

namespace {

// True when e or one of its ancestors had its Transform changed this frame.
bool chainChanged(const Registry& registry, Entity e) {
    for (int depth = 0; e && depth < kMaxTransformDepth; ++depth) {
        if (registry.wasChanged<Transform>(e)) return true;
        const Transform* t = registry.tryGet<Transform>(e);
        if (!t) return false;
        e = t->parent;
    }
    return false;
}

/// The entity's world matrix; nullopt when its parent chain does not end within kMaxTransformDepth
/// links (a loop: the importer rejects them, game code can make one).
std::optional<glm::mat4> worldMatrix(const Registry& registry, Entity e) {
    glm::mat4 m(1.f);
    for (int depth = 0; depth < kMaxTransformDepth; ++depth) {
        if (!e) return m;
        const Transform* t = registry.tryGet<Transform>(e);
        if (!t) return m;
        m = localMatrix(*t) * m;
        e = t->parent;
    }
    return std::nullopt;
}

} // namespace

void TransformSystem::update(Registry& registry, const FrameContext& /*frame*/) {
    if (registry.changed<Transform>().empty()) return; // a still scene costs nothing

    std::vector<std::pair<Entity, glm::mat4>> updates;
    registry.view<const Transform>().each([&](Entity e, const Transform& local) {
        if (!chainChanged(registry, e)) return;
        if (const std::optional<glm::mat4> world = worldMatrix(registry, e)) {
            updates.emplace_back(e, *world);
            return;
        }
        // Placed as a root until the loop is broken.
        updates.emplace_back(e, localMatrix(local));
        if (mWarnedLoop) return;
        mWarnedLoop = true;
        logWarning("TransformSystem: the parent chain of ", entityName(registry, e),
                   " loops (or runs past ", kMaxTransformDepth,
                   " parents); it is placed as a root");
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
