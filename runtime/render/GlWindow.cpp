#include "runtime/render/GlWindow.h"

#include "runtime/core/Log.h"

#include <epoxy/egl.h>
#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE // epoxy provides the GL declarations
#include <GLFW/glfw3.h>

#include <dlfcn.h>

#include <array>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace qgi {
namespace {

// GLFW is process-wide: it is initialised with the first window and terminated with the last.
int gLiveWindows = 0;

// The GlWindow whose context this thread made current (the constructor makes it current).
thread_local const GlWindow* tCurrent = nullptr;

std::string glfwErrorText() {
    const char* description = nullptr;
    glfwGetError(&description);
    return description ? description : "unknown GLFW error";
}

std::string eglErrorText() {
    return str("EGL error 0x", std::hex, eglGetError());
}

void GLAPIENTRY logGlMessage(GLenum, GLenum type, GLuint id, GLenum severity, GLsizei,
                             const GLchar* message, const void*) {
    if (type == GL_DEBUG_TYPE_ERROR || severity == GL_DEBUG_SEVERITY_HIGH)
        logError("GL error ", id, ": ", message);
    else if (severity == GL_DEBUG_SEVERITY_MEDIUM)
        logWarning("GL ", id, ": ", message);
    else
        logDebug("GL ", id, ": ", message);
}

bool hasExtension(const char* extensions, const char* name) {
    if (!extensions) return false;
    const std::size_t length = std::strlen(name);
    for (const char* at = std::strstr(extensions, name); at; at = std::strstr(at + 1, name))
        if ((at == extensions || at[-1] == ' ') && (at[length] == ' ' || at[length] == '\0'))
            return true;
    return false;
}

/** The display of the first hardware EGL device (a software one only when there is no other),
 *  or Mesa's surfaceless platform where devices cannot be listed.                          */
EGLDisplay openEglDisplay() {
    const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (hasExtension(client, "EGL_EXT_device_enumeration") &&
        hasExtension(client, "EGL_EXT_platform_device")) {
        EGLint count = 0;
        if (!eglQueryDevicesEXT(0, nullptr, &count) || count <= 0)
            fail("EGL lists no device (", eglErrorText(), "): is a GPU driver installed?");
        std::vector<EGLDeviceEXT> devices(std::size_t(count), nullptr);
        eglQueryDevicesEXT(count, devices.data(), &count);
        EGLDeviceEXT chosen = devices[0];
        for (EGLDeviceEXT device : devices) {
            const char* features = hasExtension(client, "EGL_EXT_device_query")
                                       ? eglQueryDeviceStringEXT(device, EGL_EXTENSIONS)
                                       : nullptr;
            if (!hasExtension(features, "EGL_MESA_device_software")) {
                chosen = device;
                break;
            }
        }
        return eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, chosen, nullptr);
    }
    if (hasExtension(client, "EGL_MESA_platform_surfaceless"))
        return eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY,
                                        nullptr);
    fail("this EGL offers neither devices (EGL_EXT_platform_device) nor a surfaceless platform");
}

} // namespace

struct GlWindow::Egl {
    EGLDisplay display = EGL_NO_DISPLAY;
    EGLSurface surface = EGL_NO_SURFACE;
    EGLContext context = EGL_NO_CONTEXT;
    int width = 0, height = 0;
    /// A pbuffer has no swap chain to hold the CPU back: the fence of frame N - kFramesAhead is
    /// waited on at the end of frame N, as a double-buffered window would block in its swap.
    static constexpr std::size_t kFramesAhead = 2;
    std::array<GLsync, kFramesAhead> frameDone{};
    std::size_t frame = 0;
};

GlWindow::GlWindow(const WindowSettings& settings) {
    if (settings.width <= 0 || settings.height <= 0)
        fail("window size ", settings.width, "x", settings.height, " is not positive");
    if (settings.platform == GlPlatform::Egl)
        openEgl(settings);
    else
        openWindow(settings);
    tCurrent = this;
    try {
        checkContext(settings.platform == GlPlatform::Egl ? "EGL" : "GLFW");
    } catch (...) {
        release();
        throw;
    }
}

void GlWindow::openWindow(const WindowSettings& settings) {
    if (gLiveWindows == 0 && !glfwInit())
        fail("cannot start GLFW: ", glfwErrorText(),
             " (without a display, render headless: 'qgi-demo --headless ...' does so through"
             " EGL, 'xvfb-run -a qgi-demo --headless ...' and scripts/demo under Xvfb)");
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
}

void GlWindow::openEgl(const WindowSettings& settings) {
    // libepoxy aborts the process when it cannot load libEGL: look for it first.
    if (!dlopen("libEGL.so.1", RTLD_LAZY | RTLD_GLOBAL))
        fail("an EGL context needs libEGL.so.1 (Debian: libegl1 and a driver such as"
             " libegl-mesa0 or the GPU vendor's)");
    mEgl = std::make_unique<Egl>();
    Egl& egl = *mEgl;
    try {
        egl.display = openEglDisplay();
        EGLint major = 0, minor = 0;
        if (egl.display == EGL_NO_DISPLAY || !eglInitialize(egl.display, &major, &minor))
            fail("cannot open an EGL display: ", eglErrorText());
        if (!eglBindAPI(EGL_OPENGL_API))
            fail("this EGL offers no desktop OpenGL: ", eglErrorText());

        const EGLint configAttributes[] = {EGL_SURFACE_TYPE,
                                           EGL_PBUFFER_BIT,
                                           EGL_RENDERABLE_TYPE,
                                           EGL_OPENGL_BIT,
                                           EGL_RED_SIZE,
                                           8,
                                           EGL_GREEN_SIZE,
                                           8,
                                           EGL_BLUE_SIZE,
                                           8,
                                           EGL_ALPHA_SIZE,
                                           8,
                                           EGL_NONE};
        EGLConfig config = nullptr;
        EGLint configs = 0;
        if (!eglChooseConfig(egl.display, configAttributes, &config, 1, &configs) || configs < 1)
            fail("EGL offers no 8-bit RGBA pbuffer config for OpenGL: ", eglErrorText());

        const EGLint surfaceAttributes[] = {EGL_WIDTH, settings.width, EGL_HEIGHT, settings.height,
                                            EGL_NONE};
        egl.surface = eglCreatePbufferSurface(egl.display, config, surfaceAttributes);
        if (egl.surface == EGL_NO_SURFACE)
            fail("cannot create a ", settings.width, "x", settings.height,
                 " EGL pbuffer: ", eglErrorText());
        egl.width = settings.width;
        egl.height = settings.height;

        const EGLint contextAttributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                                            4,
                                            EGL_CONTEXT_MINOR_VERSION,
                                            5,
                                            EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                            EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                            EGL_CONTEXT_OPENGL_FORWARD_COMPATIBLE,
                                            EGL_TRUE,
                                            EGL_CONTEXT_OPENGL_DEBUG,
                                            settings.debugContext ? EGL_TRUE : EGL_FALSE,
                                            EGL_NONE};
        egl.context = eglCreateContext(egl.display, config, EGL_NO_CONTEXT, contextAttributes);
        if (egl.context == EGL_NO_CONTEXT)
            fail("cannot create an OpenGL 4.5 core context on EGL ", major, ".", minor, ": ",
                 eglErrorText());
        if (!eglMakeCurrent(egl.display, egl.surface, egl.surface, egl.context))
            fail("cannot make the EGL context current: ", eglErrorText());
        eglSwapInterval(egl.display, 0);
    } catch (...) {
        closeEgl();
        throw;
    }
}

void GlWindow::closeEgl() {
    if (!mEgl) return;
    if (mEgl->display != EGL_NO_DISPLAY) {
        // Only this window's own context is let go: another may be current by now.
        if (mEgl->context != EGL_NO_CONTEXT && eglGetCurrentContext() == mEgl->context) {
            for (GLsync fence : mEgl->frameDone)
                if (fence) glDeleteSync(fence);
            eglMakeCurrent(mEgl->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        }
        if (mEgl->context != EGL_NO_CONTEXT) eglDestroyContext(mEgl->display, mEgl->context);
        if (mEgl->surface != EGL_NO_SURFACE) eglDestroySurface(mEgl->display, mEgl->surface);
        // The display stays initialised: EGL displays are per process, and another GlWindow may
        // still hold one of its contexts.
    }
    mEgl.reset();
}

void GlWindow::checkContext(const char* platform) {
    if (epoxy_gl_version() < 45) {
        const int version = epoxy_gl_version();
        fail("OpenGL 4.5 is required, the ", platform, " context offers ", version / 10, ".",
             version % 10);
    }
    GLint flags = 0;
    glGetIntegerv(GL_CONTEXT_FLAGS, &flags);
    if (flags & GL_CONTEXT_FLAG_DEBUG_BIT) {
        glEnable(GL_DEBUG_OUTPUT);
        glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS); // the log line comes from the offending call
        glDebugMessageCallback(logGlMessage, nullptr);
    }
    logInfo("OpenGL ", reinterpret_cast<const char*>(glGetString(GL_VERSION)), " on ",
            reinterpret_cast<const char*>(glGetString(GL_RENDERER)), " (", platform, ")");
}

GlWindow::~GlWindow() {
    release();
}

void GlWindow::release() {
    if (tCurrent == this) tCurrent = nullptr;
    closeEgl();
    if (mWindow) {
        glfwDestroyWindow(mWindow);
        mWindow = nullptr;
        if (--gLiveWindows == 0) glfwTerminate();
    }
}

bool GlWindow::shouldClose() const {
    return mWindow && glfwWindowShouldClose(mWindow);
}

void GlWindow::pollEvents() {
    if (mWindow) glfwPollEvents();
}

void GlWindow::swapBuffers() {
    if (mWindow)
        glfwSwapBuffers(mWindow);
    else if (mEgl)
        endPbufferFrame();
}

void GlWindow::endPbufferFrame() {
    // A pbuffer has nothing to swap, and NVIDIA's eglSwapBuffers does not flush it either:
    // without the flush the frame's last passes would wait for the next frame's first one.
    GLsync& slot = mEgl->frameDone[mEgl->frame++ % Egl::kFramesAhead];
    if (slot) {
        constexpr GLuint64 kSecond = 1'000'000'000;
        for (int seconds = 0; seconds < 10; ++seconds)
            if (glClientWaitSync(slot, GL_SYNC_FLUSH_COMMANDS_BIT, kSecond) != GL_TIMEOUT_EXPIRED)
                break;
        glDeleteSync(slot);
    }
    slot = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    glFlush();
}

int GlWindow::width() const {
    if (mEgl) return mEgl->width;
    int w = 0, h = 0;
    glfwGetFramebufferSize(mWindow, &w, &h);
    return w;
}

int GlWindow::height() const {
    if (mEgl) return mEgl->height;
    int w = 0, h = 0;
    glfwGetFramebufferSize(mWindow, &w, &h);
    return h;
}

bool GlWindow::displayAvailable() {
    return std::getenv("DISPLAY") || std::getenv("WAYLAND_DISPLAY");
}

bool GlWindow::currentFramebufferSize(int& width, int& height) {
    if (tCurrent) {
        width = tCurrent->width();
        height = tCurrent->height();
        return true;
    }
    // A GLFW window of the engine's own. (Without glfwInit this reports GLFW_NOT_INITIALIZED
    // to an error callback nobody set, and finds none.)
    GLFWwindow* window = glfwGetCurrentContext();
    if (!window) return false;
    glfwGetFramebufferSize(window, &width, &height);
    return true;
}

} // namespace qgi
