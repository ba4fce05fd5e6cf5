#include "runtime/render/GlWindow.h"

#include "runtime/core/Log.h"

#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE // epoxy provides the GL declarations
#include <GLFW/glfw3.h>

namespace qgi {
namespace {

// GLFW is process-wide: it is initialised with the first window and terminated with the last.
int gLiveWindows = 0;

std::string glfwErrorText() {
    const char* description = nullptr;
    glfwGetError(&description);
    return description ? description : "unknown GLFW error";
}

void GLAPIENTRY logGlMessage(GLenum, GLenum type, GLuint id, GLenum severity, GLsizei,
                             const GLchar* message, const void*) {
    if (type == GL_DEBUG_TYPE_ERROR || severity == GL_DEBUG_SEVERITY_HIGH)
        logError("GL error ", id, ": ", message);
    else if (severity != GL_DEBUG_SEVERITY_NOTIFICATION)
        logDebug("GL ", id, ": ", message);
}

} // namespace

GlWindow::GlWindow(const WindowSettings& settings) {
    if (settings.width <= 0 || settings.height <= 0)
        fail("window size ", settings.width, "x", settings.height, " is not positive");
    if (gLiveWindows == 0 && !glfwInit())
        fail("cannot start GLFW: ", glfwErrorText(),
             " (without a display, run headless under Xvfb: 'xvfb-run -a qgi-demo --headless ...',"
             " or use scripts/demo, which does that)");
    ++gLiveWindows;

    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_OPENGL_DEBUG_CONTEXT, settings.debugContext ? GLFW_TRUE : GLFW_FALSE);
    glfwWindowHint(GLFW_VISIBLE, settings.headless ? GLFW_FALSE : GLFW_TRUE);
    // The renderer draws into its own targets and blits; the window needs no depth or MSAA.
    glfwWindowHint(GLFW_DEPTH_BITS, 0);
    glfwWindowHint(GLFW_STENCIL_BITS, 0);
    mWindow =
        glfwCreateWindow(settings.width, settings.height, settings.title.c_str(), nullptr, nullptr);
    if (!mWindow) {
        const std::string reason = glfwErrorText();
        if (--gLiveWindows == 0) glfwTerminate();
        fail("cannot create an OpenGL 4.5 core context: ", reason);
    }
    glfwMakeContextCurrent(mWindow);
    glfwSwapInterval(settings.vsync ? 1 : 0);

    if (epoxy_gl_version() < 45) {
        const int version = epoxy_gl_version();
        glfwDestroyWindow(mWindow);
        if (--gLiveWindows == 0) glfwTerminate();
        fail("OpenGL 4.5 is required, the context offers ", version / 10, ".", version % 10);
    }

    GLint flags = 0;
    glGetIntegerv(GL_CONTEXT_FLAGS, &flags);
    if (flags & GL_CONTEXT_FLAG_DEBUG_BIT) {
        glEnable(GL_DEBUG_OUTPUT);
        glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS); // the log line comes from the offending call
        glDebugMessageCallback(logGlMessage, nullptr);
    }
    logInfo("OpenGL ", reinterpret_cast<const char*>(glGetString(GL_VERSION)), " on ",
            reinterpret_cast<const char*>(glGetString(GL_RENDERER)));
}

GlWindow::~GlWindow() {
    glfwDestroyWindow(mWindow);
    if (--gLiveWindows == 0) glfwTerminate();
}

bool GlWindow::shouldClose() const {
    return glfwWindowShouldClose(mWindow);
}

void GlWindow::pollEvents() {
    glfwPollEvents();
}

void GlWindow::swapBuffers() {
    glfwSwapBuffers(mWindow);
}

int GlWindow::width() const {
    int w = 0, h = 0;
    glfwGetFramebufferSize(mWindow, &w, &h);
    return w;
}

int GlWindow::height() const {
    int w = 0, h = 0;
    glfwGetFramebufferSize(mWindow, &w, &h);
    return h;
}

} // namespace qgi
