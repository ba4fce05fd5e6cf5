#include "demo/FlyController.h"

#include "components/Camera.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/Transform.h"
#include "runtime/core/Log.h"
#include "runtime/scene/SceneQueries.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

namespace qgi::demo {

namespace {

/// What moves and switches as one: a mobile mesh, or the glTF node whose primitives several
/// mobile meshes are (the importer makes each primitive a child named "<node>#<k>" of a node
/// that has no Mesh of its own).
Entity mobileUnit(const Registry& registry, Entity mesh) {
    const Transform* t = registry.tryGet<Transform>(mesh);
    const Entity parent = t ? t->parent : Entity{};
    if (!parent || !registry.alive(parent) || registry.has<Mesh>(parent)) return mesh;
    const Name* name = registry.tryGet<Name>(mesh);
    const Name* parentName = registry.tryGet<Name>(parent);
    const bool primitive = name && parentName && name->value.starts_with(parentName->value + "#");
    return primitive ? parent : mesh;
}

} // namespace

bool GlfwInput::key(int glfwKey) const {
    return glfwGetKey(mWindow, glfwKey) == GLFW_PRESS;
}

bool GlfwInput::rightButton() const {
    return glfwGetMouseButton(mWindow, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS;
}

glm::dvec2 GlfwInput::cursor() const {
    glm::dvec2 at;
    glfwGetCursorPos(mWindow, &at.x, &at.y);
    return at;
}

void FlyController::selectNextMobile(Registry& registry) {
    std::vector<Entity> units;
    for (const Entity e : registry.view<const MobileMesh, const Transform>().entities()) {
        const Entity unit = mobileUnit(registry, e);
        if (std::find(units.begin(), units.end(), unit) == units.end()) units.push_back(unit);
    }
    if (units.empty()) return;
    auto it = std::find(units.begin(), units.end(), mSelectedMobile);
    mSelectedMobile = (it == units.end() || ++it == units.end()) ? units.front() : *it;
    const Name* name = registry.tryGet<Name>(mSelectedMobile);
    logInfo("selected mobile ", name ? name->value : std::to_string(mSelectedMobile.index));
}

void FlyController::toggleSelectedMobile(Registry& registry) {
    if (!mSelectedMobile || !registry.alive(mSelectedMobile)) return;
    // Every mobile mesh of the selected unit goes together.
    std::vector<Entity> meshes;
    for (const Entity e : registry.view<const MobileMesh>().entities())
        if (mobileUnit(registry, e) == mSelectedMobile) meshes.push_back(e);
    if (meshes.empty()) return;
    const bool active = !registry.get<MobileMesh>(meshes.front()).active;
    for (const Entity e : meshes)
        registry.patch<MobileMesh>(e).active = active;
    const Name* name = registry.tryGet<Name>(mSelectedMobile);
    logInfo(active ? "put back mobile " : "took out mobile ",
            name ? name->value : std::to_string(mSelectedMobile.index));
}

void FlyController::switchLamps(Registry& registry) {
    // Off: each lamp's intensity kept and set to 0; on: the kept intensities back. The photon
    // update re-shoots a switched lamp's photons within its budget, so the light it gave
    // others fades instead of every photon being shot again in one frame.
    mLampsOff = !mLampsOff;
    const auto lamp = [&](Entity e, float& intensity) {
        if (mLampsOff) {
            mLampIntensity[e] = intensity;
            intensity = 0.f;
        } else if (const auto it = mLampIntensity.find(e); it != mLampIntensity.end()) {
            intensity = it->second;
        }
    };
    for (const Entity e : registry.view<const PointLight>().entities())
        lamp(e, registry.patch<PointLight>(e).intensity);
    for (const Entity e : registry.view<const SpotLight>().entities())
        lamp(e, registry.patch<SpotLight>(e).intensity);
    if (!mLampsOff) mLampIntensity.clear();
    logInfo(mLampsOff ? "lamps off" : "lamps on");
}

void FlyController::update(Registry& registry, const FrameContext& frame) {
    const float dt = std::min(frame.dt, 0.1f);

    const bool tab = pressed(GLFW_KEY_TAB);
    if (tab && !mTabDown) selectNextMobile(registry);
    mTabDown = tab;
    const bool h = pressed(GLFW_KEY_H);
    if (h && !mHDown) toggleSelectedMobile(registry);
    mHDown = h;
    const bool l = pressed(GLFW_KEY_L);
    if (l && !mLDown) switchLamps(registry);
    mLDown = l;

    const Entity camera = findActiveCamera(registry);
    if (!camera || !registry.has<Transform>(camera)) return;

    const bool c = pressed(GLFW_KEY_C);
    if (c && !mCDown && mCameraTaken) { // the scripted path takes the camera back
        mCameraTaken = false;
        if (mStashedPath) registry.emplaceOrReplace<PathFollower>(camera, std::move(*mStashedPath));
        mStashedPath.reset();
    }
    mCDown = c;

    // Mouse look while the right button is held.
    const glm::dvec2 cursor = mInput.cursor();
    const double x = cursor.x, y = cursor.y;
    const bool looking = !mMouseTaken && mInput.rightButton();
    const bool moving = pressed(GLFW_KEY_W) || pressed(GLFW_KEY_A) || pressed(GLFW_KEY_S) ||
                        pressed(GLFW_KEY_D) || pressed(GLFW_KEY_Q) || pressed(GLFW_KEY_E);
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
        t.rotation =
            glm::angleAxis(mYaw, glm::vec3(0, 1, 0)) * glm::angleAxis(mPitch, glm::vec3(1, 0, 0));
        const float speed = (pressed(GLFW_KEY_LEFT_SHIFT) ? 8.f : 2.f) * dt;
        const glm::vec3 forward = t.rotation * glm::vec3(0, 0, -1);
        const glm::vec3 right = t.rotation * glm::vec3(1, 0, 0);
        if (pressed(GLFW_KEY_W)) t.translation += forward * speed;
        if (pressed(GLFW_KEY_S)) t.translation -= forward * speed;
        if (pressed(GLFW_KEY_D)) t.translation += right * speed;
        if (pressed(GLFW_KEY_A)) t.translation -= right * speed;
        if (pressed(GLFW_KEY_E)) t.translation.y += speed;
        if (pressed(GLFW_KEY_Q)) t.translation.y -= speed;
    }

    if (mSelectedMobile && registry.alive(mSelectedMobile)) {
        glm::vec3 step(0.f);
        const float speed = 0.5f * dt; // metres per second
        if (pressed(GLFW_KEY_LEFT)) step.x -= speed;
        if (pressed(GLFW_KEY_RIGHT)) step.x += speed;
        if (pressed(GLFW_KEY_UP)) step.z -= speed;
        if (pressed(GLFW_KEY_DOWN)) step.z += speed;
        if (pressed(GLFW_KEY_PAGE_UP)) step.y += speed;
        if (pressed(GLFW_KEY_PAGE_DOWN)) step.y -= speed;
        if (step != glm::vec3(0.f)) {
            registry.remove<PathFollower>(mSelectedMobile); // the player drives it now
            registry.patch<Transform>(mSelectedMobile).translation += step;
        }
    }
}

} // namespace qgi::demo
