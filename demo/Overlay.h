#pragma once

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
 *  frame, so never into screenshots): the frame time and each schedule entry's share of the
 *  last frame, what is lit and how, the selected mobile and the keys. F1 hides and shows it.
 *  Needs a GLFW window with its GL context current; one per process (ImGui's context is
 *  global). */
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
    double mSmoothedMs = 0.0; ///< frame time, exponentially smoothed for a readable number
};

} // namespace qgi::demo
