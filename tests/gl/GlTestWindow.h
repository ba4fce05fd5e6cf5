#pragma once
// The context every GL test and benchmark draws in: a hidden GLFW window (run under
// `xvfb-run -a` without a display), or an EGL pbuffer when QGI_GL_CONTEXT=egl is set, for a GPU
// machine without X.

#include "runtime/render/GlWindow.h"

#include <cstdlib>
#include <string>
#include <string_view>

namespace qgi::test {

inline bool eglRequested() {
    const char* platform = std::getenv("QGI_GL_CONTEXT");
    return platform && std::string_view(platform) == "egl";
}

/// Why no GL test can run here, or "" when one can.
inline std::string missingGlPlatform() {
    if (eglRequested() || GlWindow::displayAvailable()) return {};
    return "no display: run the GL tests under 'xvfb-run -a' (or with QGI_GL_CONTEXT=egl)";
}

inline WindowSettings testWindow(int width, int height, std::string title) {
    WindowSettings settings;
    settings.width = width;
    settings.height = height;
    settings.headless = true;
    settings.platform = eglRequested() ? GlPlatform::Egl : GlPlatform::Window;
    settings.title = std::move(title);
    return settings;
}

} // namespace qgi::test

/// Skips the test where no GL context can be made (test::missingGlPlatform).
#define QGI_SKIP_WITHOUT_GL()                                                                      \
    do {                                                                                           \
        if (const std::string why = ::qgi::test::missingGlPlatform(); !why.empty())                \
            GTEST_SKIP() << why;                                                                   \
    } while (false)
