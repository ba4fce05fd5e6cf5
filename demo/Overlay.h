#pragma once

#include <chrono>
#include <string>

struct GLFWwindow;

namespace qgi {
class FrameProfiler;
}

namespace qgi::demo {

/// What the overlay states about the run besides the profile.
struct OverlayInfo {
    std::string scene;    ///< the scene's name
    std::string lighting; ///< mode, photons, estimator: one line
    std::string selected; ///< the mobile the keys move, or empty
    bool lampsOff = false;
    bool pointsShown = false;
};

/** The interactive demo's overlay (Dear ImGui, drawn into the window's framebuffer after the
 *  frame, so never into screenshots): the frame rate, and each schedule entry's time in the
 *  newest frame the profiler holds complete (GPU pass times arrive a few frames late), what is
 *  lit and how, the selected mobile and the keys. F1 hides and shows it. Needs a GLFW window
 *  with its GL context current; one per process (ImGui's context is global). The constructor
 *  throws qgi::Error when ImGui cannot start on the context, leaving GLFW as it was. */
class Overlay {
public:
    explicit Overlay(GLFWwindow* window);
    ~Overlay();
    Overlay(const Overlay&) = delete;
    Overlay& operator=(const Overlay&) = delete;

    /// Draws over the frame just rendered, from the profiler's last recorded frame.
    void draw(const FrameProfiler& profiler, const OverlayInfo& info);
    /// Whether the overlay holds the mouse (the fly camera should leave it alone).
    bool wantsMouse() const;

private:
    GLFWwindow* mWindow;
    bool mVisible = true;
    bool mF1Down = false;
    /// Wall time between draws (the whole frame: schedule, overlay, swap, waits) and the
    /// schedule's own time, exponentially smoothed for readable numbers.
    double mFrameMs = 0.0, mScheduleMs = 0.0;
    std::chrono::steady_clock::time_point mLastDraw{};
};

} // namespace qgi::demo
