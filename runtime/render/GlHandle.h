#pragma once

#include <epoxy/gl.h>

#include <utility>

namespace qgi {

/// Owns one OpenGL object name; move-only, deleted with `Traits::destroy` when dropped.
/// Creation goes through the create* functions below (GL 4.5 direct state access: the objects
/// exist, with their type fixed, as soon as they are created, no bind needed).
template <typename Traits> class GlHandle {
public:
    GlHandle() = default;
    explicit GlHandle(GLuint id) : mId(id) {}
    ~GlHandle() { reset(); }

    GlHandle(GlHandle&& other) noexcept : mId(std::exchange(other.mId, 0)) {}
    GlHandle& operator=(GlHandle&& other) noexcept {
        if (this != &other) {
            reset();
            mId = std::exchange(other.mId, 0);
        }
        return *this;
    }
    GlHandle(const GlHandle&) = delete;
    GlHandle& operator=(const GlHandle&) = delete;

    GLuint id() const { return mId; }
    explicit operator bool() const { return mId != 0; }

    void reset() {
        if (mId != 0) Traits::destroy(mId);
        mId = 0;
    }

private:
    GLuint mId = 0;
};

struct GlBufferTraits {
    static void destroy(GLuint id) { glDeleteBuffers(1, &id); }
};
struct GlVertexArrayTraits {
    static void destroy(GLuint id) { glDeleteVertexArrays(1, &id); }
};
struct GlTextureTraits {
    static void destroy(GLuint id) { glDeleteTextures(1, &id); }
};
struct GlFramebufferTraits {
    static void destroy(GLuint id) { glDeleteFramebuffers(1, &id); }
};
struct GlProgramTraits {
    static void destroy(GLuint id) { glDeleteProgram(id); }
};
struct GlShaderTraits {
    static void destroy(GLuint id) { glDeleteShader(id); }
};
struct GlQueryTraits {
    static void destroy(GLuint id) { glDeleteQueries(1, &id); }
};

using GlBuffer = GlHandle<GlBufferTraits>;
using GlVertexArray = GlHandle<GlVertexArrayTraits>;
using GlTexture = GlHandle<GlTextureTraits>;
using GlFramebuffer = GlHandle<GlFramebufferTraits>;
using GlProgram = GlHandle<GlProgramTraits>;
using GlShader = GlHandle<GlShaderTraits>;
using GlQuery = GlHandle<GlQueryTraits>;

inline GlBuffer createBuffer() {
    GLuint id = 0;
    glCreateBuffers(1, &id);
    return GlBuffer(id);
}
inline GlVertexArray createVertexArray() {
    GLuint id = 0;
    glCreateVertexArrays(1, &id);
    return GlVertexArray(id);
}
inline GlTexture createTexture(GLenum target) {
    GLuint id = 0;
    glCreateTextures(target, 1, &id);
    return GlTexture(id);
}
inline GlFramebuffer createFramebuffer() {
    GLuint id = 0;
    glCreateFramebuffers(1, &id);
    return GlFramebuffer(id);
}
inline GlQuery createQuery(GLenum target) {
    GLuint id = 0;
    glCreateQueries(target, 1, &id);
    return GlQuery(id);
}

} // namespace qgi
