#pragma once

#include "components/PathFollower.h"
#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"

#include <optional>
#include <unordered_map>

#include <glm/vec2.hpp>

struct GLFWwindow;

namespace qgi::demo {

/// What the controller reads of the keyboard and mouse, by GLFW key codes: a window's state
/// (GlfwInput), or a test's.
class Input {
public:
    virtual ~Input() = default;
    virtual bool key(int glfwKey) const = 0;
    virtual bool rightButton() const = 0;
    virtual glm::dvec2 cursor() const = 0; ///< pixels
};

/// Input polled from a GLFW window.
class GlfwInput final : public Input {
public:
    explicit GlfwInput(GLFWwindow* window) : mWindow(window) {}
    bool key(int glfwKey) const override;
    bool rightButton() const override;
    glm::dvec2 cursor() const override;

private:
    GLFWwindow* mWindow;
};

/** Interactive input: a fly camera (WASD + right-mouse look, Q/E down/up, Shift faster) and
 *  keyboard moves of the selected mobile (Tab selects, arrows and PageUp/PageDown move, H
 *  takes it out of the world and puts it back), and L switching the lamps (point and spot
 *  lights) off and on. Taking the camera stops its scripted path; C gives it back.
 *  Reads:  key and mouse state (Input)
 *  A glTF node whose primitives are several mobile meshes is selected, moved and switched as
 *  one.
 *  Writes: Transform of the active camera and of the selected mobile, MobileMesh::active of
 *          the selected mobile's meshes, PointLight and SpotLight intensity (patched) */
class FlyController {
public:
    /// `input` must outlive the controller.
    explicit FlyController(const Input& input) : mInput(input) {}
    void update(Registry& registry, const FrameContext& frame);
    /// The mobile the keys move (null before Tab), and whether the lamps are switched off.
    Entity selectedMobile() const { return mSelectedMobile; }
    bool lampsOff() const { return mLampsOff; }
    /// While set, the mouse is the overlay's: no mouse look.
    void setMouseTaken(bool taken) { mMouseTaken = taken; }

private:
    void selectNextMobile(Registry& registry);
    /// Takes the selected mobile out of the world (MobileMesh::active), or puts it back.
    void toggleSelectedMobile(Registry& registry);
    /// Switches every point and spot light off (intensity 0), or back to what it was.
    void switchLamps(Registry& registry);

    bool pressed(int glfwKey) const { return mInput.key(glfwKey); }

    const Input& mInput;
    Entity mSelectedMobile{};
    bool mLooking = false;
    double mLastX = 0, mLastY = 0;
    float mYaw = 0.f, mPitch = 0.f; ///< radians
    bool mTabDown = false, mCDown = false, mHDown = false, mLDown = false;
    bool mLampsOff = false;
    bool mMouseTaken = false;
    std::unordered_map<Entity, float> mLampIntensity; ///< while off: each lamp's intensity
    bool mCameraTaken = false;
    std::optional<PathFollower> mStashedPath; ///< the camera's script while the player flies
};

} // namespace qgi::demo
