#include "demo/FlyController.h"

#include "components/Camera.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/Transform.h"
#include "runtime/core/Log.h"
#include "runtime/scene/SceneQueries.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <cmath>

namespace qgi::demo {

namespace {

bool pressed(GLFWwindow* w, int key) { return glfwGetKey(w, key) == GLFW_PRESS; }

} // namespace

void FlyController::selectNextMobile(Registry& registry) {
    const auto mobiles = registry.view<const MobileMesh, const Transform>().entities();
    if (mobiles.empty()) return;
    // Mobile meshes may be children of one mobile node: move the root of the selection.
    auto it = std::find(mobiles.begin(), mobiles.end(), mSelectedMobile);
    mSelectedMobile = (it == mobiles.end() || ++it == mobiles.end()) ? mobiles.front() : *it;
    const Name* name = registry.tryGet<Name>(mSelectedMobile);
    logInfo("selected mobile ", name ? name->value : std::to_string(mSelectedMobile.index));
}

void FlyController::toggleSelectedMobile(Registry& registry) {
    if (!mSelectedMobile || !registry.alive(mSelectedMobile)) return;
    // The selection and every mobile mesh below it (a glTF node's primitives) go together.
    const auto below = [&](Entity e) {
        for (int depth = 0; e && depth < 64; ++depth) {
            if (e == mSelectedMobile) return true;
            const Transform* t = registry.tryGet<Transform>(e);
            e = t ? t->parent : Entity{};
        }
        return false;
    };
    const MobileMesh* selected = registry.tryGet<MobileMesh>(mSelectedMobile);
    const bool active = !(selected ? selected->active : true);
    for (const Entity e : registry.view<const MobileMesh>().entities())
        if (below(e)) registry.patch<MobileMesh>(e).active = active;
    const Name* name = registry.tryGet<Name>(mSelectedMobile);
    logInfo(active ? "put back mobile " : "took out mobile ",
            name ? name->value : std::to_string(mSelectedMobile.index));
}

void FlyController::update(Registry& registry, const FrameContext& frame) {
    const float dt = std::min(frame.dt, 0.1f);

    const bool tab = pressed(mWindow, GLFW_KEY_TAB);
    if (tab && !mTabDown) selectNextMobile(registry);
    mTabDown = tab;
    const bool h = pressed(mWindow, GLFW_KEY_H);
    if (h && !mHDown) toggleSelectedMobile(registry);
    mHDown = h;

    const Entity camera = findActiveCamera(registry);
    if (!camera || !registry.has<Transform>(camera)) return;

    const bool c = pressed(mWindow, GLFW_KEY_C);
    if (c && !mCDown && mCameraTaken) { // the scripted path takes the camera back
        mCameraTaken = false;
        if (mStashedPath) registry.emplaceOrReplace<PathFollower>(camera, std::move(*mStashedPath));
        mStashedPath.reset();
    }
    mCDown = c;

    // Mouse look while the right button is held.
    double x, y;
    glfwGetCursorPos(mWindow, &x, &y);
    const bool looking = glfwGetMouseButton(mWindow, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS;
    const bool moving = pressed(mWindow, GLFW_KEY_W) || pressed(mWindow, GLFW_KEY_A) ||
                        pressed(mWindow, GLFW_KEY_S) || pressed(mWindow, GLFW_KEY_D) ||
                        pressed(mWindow, GLFW_KEY_Q) || pressed(mWindow, GLFW_KEY_E);
    if ((looking || moving) && !mCameraTaken) {
        // Take the camera over from its path, starting from where it is now.
        mCameraTaken = true;
        if (const PathFollower* path = registry.tryGet<PathFollower>(camera)) {
            mStashedPath = *path;
            registry.remove<PathFollower>(camera);
        }
        const glm::vec3 forward = registry.get<Transform>(camera).rotation * glm::vec3(0, 0, -1);
        mYaw = std::atan2(-forward.x, -forward.z);
        mPitch = std::asin(std::clamp(forward.y, -1.f, 1.f));
    }
    if (looking && mLooking) {
        mYaw -= float(x - mLastX) * 0.003f;
        mPitch = std::clamp(mPitch - float(y - mLastY) * 0.003f, -1.5f, 1.5f);
    }
    mLooking = looking;
    mLastX = x;
    mLastY = y;

    if (mCameraTaken) {
        Transform& t = registry.patch<Transform>(camera);
        t.rotation = glm::angleAxis(mYaw, glm::vec3(0, 1, 0)) * glm::angleAxis(mPitch, glm::vec3(1, 0, 0));
        const float speed = (pressed(mWindow, GLFW_KEY_LEFT_SHIFT) ? 8.f : 2.f) * dt;
        const glm::vec3 forward = t.rotation * glm::vec3(0, 0, -1);
        const glm::vec3 right = t.rotation * glm::vec3(1, 0, 0);
        if (pressed(mWindow, GLFW_KEY_W)) t.translation += forward * speed;
        if (pressed(mWindow, GLFW_KEY_S)) t.translation -= forward * speed;
        if (pressed(mWindow, GLFW_KEY_D)) t.translation += right * speed;
        if (pressed(mWindow, GLFW_KEY_A)) t.translation -= right * speed;
        if (pressed(mWindow, GLFW_KEY_E)) t.translation.y += speed;
        if (pressed(mWindow, GLFW_KEY_Q)) t.translation.y -= speed;
    }

    if (mSelectedMobile && registry.alive(mSelectedMobile)) {
        glm::vec3 step(0.f);
        const float speed = 0.5f * dt; // metres per second
        if (pressed(mWindow, GLFW_KEY_LEFT)) step.x -= speed;
        if (pressed(mWindow, GLFW_KEY_RIGHT)) step.x += speed;
        if (pressed(mWindow, GLFW_KEY_UP)) step.z -= speed;
        if (pressed(mWindow, GLFW_KEY_DOWN)) step.z += speed;
        if (pressed(mWindow, GLFW_KEY_PAGE_UP)) step.y += speed;
        if (pressed(mWindow, GLFW_KEY_PAGE_DOWN)) step.y -= speed;
        if (step != glm::vec3(0.f)) {
            registry.remove<PathFollower>(mSelectedMobile); // the player drives it now
            registry.patch<Transform>(mSelectedMobile).translation += step;
        }
    }
}

} // namespace qgi::demo
