// The demo's interactive controls, driven by scripted input: what each key and the mouse do to
// the camera, the selected mobile and the lamps.
#include "components/Camera.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/Transform.h"
#include "demo/FlyController.h"
#include "runtime/ecs/Registry.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <set>

namespace qgi::demo {
namespace {

/// Keys held and the mouse, as a test sets them.
struct ScriptedInput final : Input {
    std::set<int> held;
    bool right = false;
    glm::dvec2 at{0.0};
    bool key(int glfwKey) const override { return held.contains(glfwKey); }
    bool rightButton() const override { return right; }
    glm::dvec2 cursor() const override { return at; }
};

constexpr float kDt = 0.05f; // seconds a frame

struct Level {
    Registry world;
    Entity camera, crate, lidOfCrate, lamp, spot;
    Level() {
        camera = world.create();
        world.emplace<Camera>(camera).active = true;
        world.emplace<Transform>(camera).translation = {0.f, 1.f, 5.f}; // looking along -z
        world.emplace<PathFollower>(camera).keys.push_back({});
        // A glTF node whose two primitives are mobile meshes "crate#0" and "crate#1".
        crate = world.create();
        world.emplace<Transform>(crate).translation = {1.f, 0.f, 0.f};
        world.emplace<Name>(crate, Name{"crate"});
        world.emplace<PathFollower>(crate).keys.push_back({});
        for (int k = 0; k < 2; ++k) {
            const Entity part = world.create();
            world.emplace<Transform>(part).parent = crate;
            world.emplace<Name>(part, Name{"crate#" + std::to_string(k)});
            world.emplace<Mesh>(part);
            world.emplace<MobileMesh>(part);
            if (k == 1) lidOfCrate = part;
        }
        lamp = world.create();
        world.emplace<Transform>(lamp);
        world.emplace<PointLight>(lamp).intensity = 7.f;
        spot = world.create();
        world.emplace<Transform>(spot);
        world.emplace<SpotLight>(spot).intensity = 3.f;
    }
};

/// Runs `frames` frames with the input as it is.
void run(FlyController& controller, Registry& world, int frames) {
    for (int f = 0; f < frames; ++f)
        controller.update(world, FrameContext{std::uint64_t(f), 0.0, kDt, 0});
}

TEST(FlyController, WFliesForwardAtTwoMetresASecondAndCHandsTheCameraBack) {
    Level level;
    ScriptedInput input;
    FlyController controller(input);
    run(controller, level.world, 3); // nothing held: the path keeps the camera
    EXPECT_TRUE(level.world.has<PathFollower>(level.camera));

    input.held = {GLFW_KEY_W};
    run(controller, level.world, 10); // half a second
    EXPECT_FALSE(level.world.has<PathFollower>(level.camera)) << "the player took the camera";
    const glm::vec3 at = level.world.get<Transform>(level.camera).translation;
    EXPECT_NEAR(at.x, 0.f, 1e-5f);
    EXPECT_NEAR(at.y, 1.f, 1e-5f);
    EXPECT_NEAR(at.z, 5.f - 2.f * 10 * kDt, 1e-5f);

    input.held = {GLFW_KEY_W, GLFW_KEY_LEFT_SHIFT}; // faster
    run(controller, level.world, 1);
    EXPECT_NEAR(level.world.get<Transform>(level.camera).translation.z, at.z - 8.f * kDt, 1e-5f);
    input.held = {GLFW_KEY_E};
    run(controller, level.world, 1);
    EXPECT_NEAR(level.world.get<Transform>(level.camera).translation.y, 1.f + 2.f * kDt, 1e-5f);

    input.held = {GLFW_KEY_C};
    run(controller, level.world, 1);
    EXPECT_TRUE(level.world.has<PathFollower>(level.camera)) << "C gives the path back";
}

TEST(FlyController, RightDragTurnsTheCameraUnlessTheOverlayHasTheMouse) {
    Level level;
    ScriptedInput input;
    FlyController controller(input);
    const auto forward = [&] {
        return level.world.get<Transform>(level.camera).rotation * glm::vec3(0, 0, -1);
    };
    input.right = true;
    run(controller, level.world, 1); // grabs the camera where the cursor is
    input.at = {-100.0, 0.0};        // dragged left: turns left, towards -x
    run(controller, level.world, 1);
    EXPECT_NEAR(glm::length(forward()), 1.f, 1e-5f);
    EXPECT_NEAR(std::atan2(-forward().x, -forward().z), 0.3f, 1e-4f); // 0.003 rad a pixel
    controller.setMouseTaken(true);
    input.at = {-300.0, 0.0};
    run(controller, level.world, 2);
    EXPECT_NEAR(std::atan2(-forward().x, -forward().z), 0.3f, 1e-4f) << "the overlay's drag";
}

TEST(FlyController, TabSelectsAMobileUnitThatTheArrowsMoveAndHTakesOutAndBack) {
    Level level;
    ScriptedInput input;
    FlyController controller(input);
    input.held = {GLFW_KEY_RIGHT}; // nothing selected: nothing moves
    run(controller, level.world, 2);
    EXPECT_EQ(level.world.get<Transform>(level.crate).translation, glm::vec3(1.f, 0.f, 0.f));

    input.held = {GLFW_KEY_TAB};
    run(controller, level.world, 3); // one press, held: selected once
    EXPECT_EQ(controller.selectedMobile(), level.crate) << "the node, not one of its primitives";
    input.held = {GLFW_KEY_RIGHT, GLFW_KEY_PAGE_UP};
    run(controller, level.world, 4);
    EXPECT_FALSE(level.world.has<PathFollower>(level.crate)) << "the player drives it";
    const glm::vec3 at = level.world.get<Transform>(level.crate).translation;
    EXPECT_NEAR(at.x, 1.f + 0.5f * 4 * kDt, 1e-5f);
    EXPECT_NEAR(at.y, 0.5f * 4 * kDt, 1e-5f);

    input.held = {GLFW_KEY_H};
    run(controller, level.world, 2);
    for (const Entity e : level.world.view<const MobileMesh>().entities())
        EXPECT_FALSE(level.world.get<MobileMesh>(e).active) << "every primitive goes";
    input.held = {};
    run(controller, level.world, 1);
    input.held = {GLFW_KEY_H};
    run(controller, level.world, 1);
    EXPECT_TRUE(level.world.get<MobileMesh>(level.lidOfCrate).active) << "and comes back";
}

TEST(FlyController, LSwitchesTheLampsOffAndBackToTheirIntensities) {
    Level level;
    ScriptedInput input;
    FlyController controller(input);
    input.held = {GLFW_KEY_L};
    run(controller, level.world, 2);
    EXPECT_TRUE(controller.lampsOff());
    EXPECT_EQ(level.world.get<PointLight>(level.lamp).intensity, 0.f);
    EXPECT_EQ(level.world.get<SpotLight>(level.spot).intensity, 0.f);
    input.held = {};
    run(controller, level.world, 1);
    input.held = {GLFW_KEY_L};
    run(controller, level.world, 1);
    EXPECT_FALSE(controller.lampsOff());
    EXPECT_EQ(level.world.get<PointLight>(level.lamp).intensity, 7.f);
    EXPECT_EQ(level.world.get<SpotLight>(level.spot).intensity, 3.f);
}

} // namespace
} // namespace qgi::demo
