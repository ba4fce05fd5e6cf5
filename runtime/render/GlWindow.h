#pragma once

#include <string>

struct GLFWwindow;

namespace qgi {

struct WindowSettings {
    int width = 1280;      ///< pixels
    int height = 720;      ///< pixels
    bool headless = false; ///< hidden window: renders offscreen (needs an X server, e.g. Xvfb)
    bool vsync = false;
    std::string title = "qgi";
#ifdef NDEBUG
    bool debugContext = false; ///< GL debug context whose messages go to the log
#else
    bool debugContext = true;
#endif
};

/** A GLFW window with a current OpenGL 4.5 core context (functions loaded by libepoxy).
 *  One per thread that renders; the context stays current on the constructing thread.
 *  Throws qgi::Error when GLFW cannot start (no display) or no 4.5 core context exists.  */
class GlWindow {
public:
    explicit GlWindow(const WindowSettings& settings);
    ~GlWindow();
    GlWindow(const GlWindow&) = delete;
    GlWindow& operator=(const GlWindow&) = delete;

    bool shouldClose() const;
    void pollEvents();
    void swapBuffers();

    GLFWwindow* handle() const { return mWindow; }
    int width() const;  ///< framebuffer width, pixels
    int height() const; ///< framebuffer height, pixels

private:
    GLFWwindow* mWindow = nullptr;
};

} // namespace qgi
