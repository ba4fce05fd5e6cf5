#pragma once

#include <memory>
#include <string>

struct GLFWwindow;

namespace qgi {

/** Where the OpenGL context comes from. */
enum class GlPlatform {
    Window, ///< a GLFW window (hidden when headless; needs an X server, e.g. Xvfb)
    Egl,    ///< an EGL pbuffer on the first GPU, no window system: headless only
};

struct WindowSettings {
    int width = 1280;      ///< pixels
    int height = 720;      ///< pixels
    bool headless = false; ///< renders offscreen; GlPlatform::Egl always does
    GlPlatform platform = GlPlatform::Window;
    bool vsync = false;
    std::string title = "qgi";
#ifdef NDEBUG
    bool debugContext = false; ///< GL debug context whose messages go to the log
#else
    bool debugContext = true;
#endif
};

/** A current OpenGL 4.5 core context (functions loaded by libepoxy) with a default framebuffer
 *  of the requested size: a GLFW window, or an EGL pbuffer for GPU machines without a display
 *  server. One per thread that renders; the context stays current on the constructing thread.
 *  Throws qgi::Error when no platform starts (no display, no EGL device) or no 4.5 core context
 *  exists.                                                                                   */
class GlWindow {
public:
    explicit GlWindow(const WindowSettings& settings);
    ~GlWindow();
    GlWindow(const GlWindow&) = delete;
    GlWindow& operator=(const GlWindow&) = delete;

    bool shouldClose() const;
    void pollEvents();
    void swapBuffers();

    GLFWwindow* handle() const { return mWindow; } ///< null for an EGL pbuffer
    int width() const;  ///< framebuffer width, pixels
    int height() const; ///< framebuffer height, pixels

    /** The default framebuffer's size of the GlWindow current on this thread, else of the
     *  current GLFW window (an engine's own); false when there is neither.                  */
    static bool currentFramebufferSize(int& width, int& height);

    /// Whether a window system is there to open windows on (DISPLAY or WAYLAND_DISPLAY set);
    /// without one only GlPlatform::Egl makes a context.
    static bool displayAvailable();

private:
    struct Egl; // EGL handles, kept out of this header
    void openWindow(const WindowSettings& settings);
    void openEgl(const WindowSettings& settings);
    void closeEgl();
    void endPbufferFrame();
    void release();
    void checkContext(const char* platform);

    GLFWwindow* mWindow = nullptr;
    std::unique_ptr<Egl> mEgl;
};

} // namespace qgi
