#pragma once

#include "runtime/io/Image8.h"
#include "runtime/io/ImageF.h"
#include "runtime/render/GlHandle.h"
#include "runtime/render/PassTimer.h"
#include "runtime/render/RenderScene.h"
#include "runtime/render/RenderSettings.h"
#include "runtime/render/ShadowMaps.h"

#include <cstdint>

namespace qgi {

class FrameProfiler;

/** Draws a RenderScene: shadow maps (hybrid mode), the scene into an RGBA32F target of
 *  radiance in W/(m^2 sr), then exposure and the filmic tonemap (shaders/tonemap.frag) into an
 *  sRGB-encoded RGBA8 target, which is blitted to the default framebuffer of the GlWindow
 *  current on this thread (a window or an EGL pbuffer) or of the current GLFW window (with
 *  neither, the image stays in its target).
 *  Every pass sets its full GL state (PipelineState); passes are timed as "render/shadow",
 *  "render/scene" and "render/tonemap". Needs a current GL 4.5 context for its whole life.
 *  Lights past shader::kMaxLights are ignored (logged once).                              */
class SceneRenderer {
public:
    /// Throws qgi::Error naming the setting for bad settings, or for a shader that fails.
    explicit SceneRenderer(const RenderSettings& settings);
    /// GL_MAX_TEXTURE_SIZE of the current context: the largest render target, shadow map and
    /// VLF tile atlas side, texels.
    static int maxTextureSize();

    void render(const RenderScene& scene, FrameProfiler* profiler, std::uint64_t frameIndex);

    const RenderSettings& settings() const { return mSettings; }
    void setExposure(float exposure); ///< a positive multiplier (RenderSettings::exposure)
    bool cpuTimedPasses() const { return mTimer.cpuTimed(); }

    /// The last frame's radiance, W/(m^2 sr) (alpha 1), top row first.
    ImageF readHdr() const;
    /// The last frame after tonemapping, sRGB-encoded (alpha 255), top row first.
    Image8 readLdr() const;

private:
    void uploadLights(std::span<const RenderLight> lights);
    void drawScene(const RenderScene& scene);
    void uploadVlf(const VlfGpuTables& vlf);
    void tonemapAndPresent();

    RenderSettings mSettings;
    PassTimer mTimer;
    std::string mDefines;
    GlProgram mSceneProgram;
    GlProgram mTonemapProgram;
    ShadowMaps mShadows;
    GlTexture mHdrColor;
    GlTexture mDepth;
    GlFramebuffer mHdrTarget;
    GlTexture mLdrColor;
    GlFramebuffer mLdrTarget;
    GlBuffer mLightBlock;
    GlTexture mWhite;          ///< bound where an item has no base colour texture
    GlBuffer mNoPointCache;    ///< 16 zero bytes on the point-cache bindings when there is none
    GlVertexArray mNoVertices; ///< the fullscreen triangle needs a vertex array, not data
    bool mWarnedLightLimit = false;
    std::uint64_t mVlfVersion = 0;  ///< of the uploaded tables; 0: none
    GlBuffer mVlfBuffers[5];        ///< directions, triangles, faces, blocks, slots
    GlTexture mVlfAtlas;
};

} // namespace qgi
