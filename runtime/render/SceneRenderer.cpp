#include "runtime/render/SceneRenderer.h"

#include "runtime/core/Log.h"
#include "runtime/render/GlWindow.h"
#include "runtime/render/GpuMesh.h"
#include "runtime/render/GpuTexture.h"
#include "runtime/render/PipelineState.h"
#include "runtime/render/ShaderInterface.h"
#include "runtime/render/ShaderLoader.h"

#include <glm/gtc/matrix_inverse.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <string_view>

namespace qgi {
namespace {

using namespace shader;

// std140 mirror of LightBlock in shaders/common/lighting.glsl.
struct GpuLight {
    glm::vec4 position;
    glm::vec4 direction;
    glm::vec4 radiance;
    glm::vec4 spot;
    glm::ivec4 kind;
};
struct GpuLightBlock {
    glm::mat4 shadowMatrices[kMaxShadowLayers];
    glm::ivec4 count;
    GpuLight lights[kMaxLights];
};
static_assert(sizeof(GpuLight) == 80);
static_assert(offsetof(GpuLightBlock, count) == 64 * kMaxShadowLayers);
static_assert(offsetof(GpuLightBlock, lights) % 16 == 0);

RenderSettings validated(const RenderSettings& s) {
    const int maxSize = SceneRenderer::maxTextureSize();
    if (s.width <= 0 || s.height <= 0 || s.width > maxSize || s.height > maxSize)
        fail("render setting width x height = ", s.width, "x", s.height, " is outside 1..",
             maxSize);
    if (!std::isfinite(s.exposure) || s.exposure <= 0.f)
        fail("render setting exposure = ", s.exposure, " must be a positive multiplier");
    if (s.shadowMapSize < 16 || s.shadowMapSize > maxSize)
        fail("render setting shadowMapSize = ", s.shadowMapSize, " is outside 16..", maxSize);
    return s;
}

constexpr std::array<std::uint8_t, 4> kWhite{255, 255, 255, 255};

/// The scene shader compiles the direct-light code only in hybrid mode: llvmpipe would pay
/// for it even behind a uniform that is false.
std::string modeDefine(ShadingMode mode) {
    return mode == ShadingMode::Hybrid ? "#define HYBRID\n" : "";
}

bool cpuTiming(PassTiming timing) {
    if (timing != PassTiming::Auto) return timing == PassTiming::Cpu;
    const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    return renderer && std::string_view(renderer).find("llvmpipe") != std::string_view::npos;
}

GlTexture createTarget(GLenum format, int width, int height) {
    GlTexture texture = createTexture(GL_TEXTURE_2D);
    glTextureStorage2D(texture.id(), 1, format, width, height);
    glTextureParameteri(texture.id(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(texture.id(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    return texture;
}

GlFramebuffer createFramebufferFor(const GlTexture& color, const GlTexture* depth) {
    GlFramebuffer framebuffer = createFramebuffer();
    glNamedFramebufferTexture(framebuffer.id(), GL_COLOR_ATTACHMENT0, color.id(), 0);
    if (depth) glNamedFramebufferTexture(framebuffer.id(), GL_DEPTH_ATTACHMENT, depth->id(), 0);
    glNamedFramebufferDrawBuffer(framebuffer.id(), GL_COLOR_ATTACHMENT0);
    glNamedFramebufferReadBuffer(framebuffer.id(), GL_COLOR_ATTACHMENT0);
    const GLenum status = glCheckNamedFramebufferStatus(framebuffer.id(), GL_FRAMEBUFFER);
    if (status != GL_FRAMEBUFFER_COMPLETE)
        fail("render target incomplete (GL status 0x", std::hex, status, ")");
    return framebuffer;
}

/// Reads a whole RGBA texture, rows flipped so the top row comes first.
template <typename T>
std::vector<T> readTexture(GLuint texture, int width, int height, GLenum type) {
    const std::size_t row = std::size_t(width) * 4;
    std::vector<T> bottomUp(row * std::size_t(height));
    useTightPacking();
    glGetTextureImage(texture, 0, GL_RGBA, type, GLsizei(bottomUp.size() * sizeof(T)),
                      bottomUp.data());
    std::vector<T> topDown(bottomUp.size());
    for (int y = 0; y < height; ++y)
        std::memcpy(&topDown[std::size_t(y) * row], &bottomUp[std::size_t(height - 1 - y) * row],
                    row * sizeof(T));
    return topDown;
}

} // namespace

SceneRenderer::SceneRenderer(const RenderSettings& settings)
    : mSettings(validated(settings)), mTimer(cpuTiming(settings.passTiming)),
      mDefines(shaderInterfaceDefines()),
      mSceneProgram(
          loadProgram({"scene.vert", "scene.frag"}, mDefines + modeDefine(settings.mode))),
      mTonemapProgram(loadProgram({"fullscreen.vert", "tonemap.frag"}, mDefines)),
      mShadows(settings.shadowMapSize, mDefines),
      mHdrColor(createTarget(GL_RGBA32F, settings.width, settings.height)),
      mDepth(createTarget(GL_DEPTH_COMPONENT32F, settings.width, settings.height)),
      mHdrTarget(createFramebufferFor(mHdrColor, &mDepth)),
      mLdrColor(createTarget(GL_RGBA8, settings.width, settings.height)),
      mLdrTarget(createFramebufferFor(mLdrColor, nullptr)), mLightBlock(createBuffer()),
      mWhite(createColorTexture(1, 1, kWhite, false)), mNoVertices(createVertexArray()) {
    glNamedBufferStorage(mLightBlock.id(), sizeof(GpuLightBlock), nullptr, GL_DYNAMIC_STORAGE_BIT);
    mNoPointCache = createBuffer();
    const std::uint32_t zeros[4] = {0, 0, 0, 0};
    glNamedBufferStorage(mNoPointCache.id(), sizeof zeros, zeros, 0);
    if (mTimer.cpuTimed()) logInfo("render passes are timed on the CPU around glFinish");
}

void SceneRenderer::setExposure(float exposure) {
    QGI_ASSERT(std::isfinite(exposure) && exposure > 0.f, "exposure ", exposure);
    mSettings.exposure = exposure;
}

void SceneRenderer::render(const RenderScene& scene, FrameProfiler* profiler,
                           std::uint64_t frameIndex) {
    mTimer.beginFrame(profiler, frameIndex);
    std::span<const RenderLight> lights = scene.lights;
    if (mSettings.mode == ShadingMode::Photon) {
        lights = {}; // all light is in the per-vertex irradiance
    } else {
        if (lights.size() > std::size_t(kMaxLights)) {
            if (!mWarnedLightLimit)
                logWarning(lights.size(),
                           " lights: the shader draws the direct light of the first ", kMaxLights,
                           " only; the others light the scene through photons (light "
                           "that reflected) alone");
            mWarnedLightLimit = true;
            lights = lights.first(kMaxLights);
        }
        mShadows.update(lights, scene.items, scene.staticCastersChanged,
                        scene.movableCastersChanged, mTimer);
    }
    uploadLights(lights);
    {
        PassTimer::Scope pass(mTimer, "render/scene");
        drawScene(scene);
    }
    PassTimer::Scope pass(mTimer, "render/tonemap");
    tonemapAndPresent();
}

void SceneRenderer::uploadLights(std::span<const RenderLight> lights) {
    GpuLightBlock block;
    const std::span<const glm::mat4> matrices = mShadows.matrices();
    std::copy(matrices.begin(), matrices.end(), block.shadowMatrices);
    block.count = glm::ivec4(int(lights.size()), 0, 0, 0);
    const std::span<const LightShadow> shadows = mShadows.shadows();
    for (std::size_t i = 0; i < lights.size(); ++i) {
        const RenderLight& light = lights[i];
        const LightShadow shadow = i < shadows.size() ? shadows[i] : LightShadow{};
        const float cosInner = std::cos(light.innerConeAngle);
        const float cosOuter = std::cos(light.outerConeAngle);
        const float coneScale = 1.f / std::max(1e-3f, cosInner - cosOuter);
        block.lights[i] = GpuLight{
            glm::vec4(light.position, shadow.texelScale),
            glm::vec4(light.direction, 0.f),
            glm::vec4(light.radiance, 0.f),
            glm::vec4(coneScale, -cosOuter * coneScale, 0.f, 0.f),
            glm::ivec4(int(light.type), shadow.faces, shadow.layer, 0),
        };
    }
    glNamedBufferSubData(
        mLightBlock.id(), 0,
        GLsizeiptr(offsetof(GpuLightBlock, lights) + lights.size() * sizeof(GpuLight)), &block);
}

void SceneRenderer::drawScene(const RenderScene& scene) {
    PipelineState state;
    state.framebuffer = mHdrTarget.id();
    state.viewportWidth = mSettings.width;
    state.viewportHeight = mSettings.height;
    applyState(state);
    const float black[4] = {0.f, 0.f, 0.f, 1.f};
    const float farDepth = 1.f;
    glClearNamedFramebufferfv(mHdrTarget.id(), GL_COLOR, 0, black);
    glClearNamedFramebufferfv(mHdrTarget.id(), GL_DEPTH, 0, &farDepth);

    const GLuint program = mSceneProgram.id();
    glUseProgram(program);
    const glm::mat4 viewProjection = scene.camera.projection * scene.camera.view;
    glProgramUniformMatrix4fv(program, kViewProjection, 1, GL_FALSE,
                              glm::value_ptr(viewProjection));
    glProgramUniform3fv(program, kCameraPosition, 1, glm::value_ptr(scene.camera.position));
    glBindBufferBase(GL_UNIFORM_BUFFER, kLightBlockBinding, mLightBlock.id());
    mShadows.bindTexture(kShadowUnit);
    if (scene.vlf) {
        if (scene.vlf->version != mVlfVersion) uploadVlf(*scene.vlf);
        const GLuint bindings[5] = {kVlfDirectionsBinding, kVlfTrianglesBinding, kVlfFacesBinding,
                                    kVlfBlocksBinding, kVlfSlotsBinding};
        for (int k = 0; k < 5; ++k)
            glBindBufferBase(GL_SHADER_STORAGE_BUFFER, bindings[k], mVlfBuffers[k].id());
        glBindTextureUnit(kVlfAtlasUnit, mVlfAtlas.id());
        glProgramUniform4i(program, kVlfParams, scene.vlf->level, scene.vlf->linesPerSide,
                           scene.vlf->tileSize, scene.vlf->directionCount);
        glProgramUniform4f(program, kVlfFrame, scene.vlf->center.x, scene.vlf->center.y,
                           scene.vlf->center.z, scene.vlf->radius);
        glProgramUniform1f(program, kVlfCellScale, scene.vlf->cellScale);
    } else {
        glBindTextureUnit(kVlfAtlasUnit, mWhite.id());
    }
    const PointCacheView* cache = scene.pointCache && scene.pointCache->points ? scene.pointCache
                                                                              : nullptr;
    const GLuint none = mNoPointCache.id();
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kPointCachePointsBinding, cache ? cache->points : none);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kPointCacheCellStartBinding,
                     cache ? cache->cellStart : none);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kPointCacheCellPointsBinding,
                     cache ? cache->cellPoints : none);
    if (cache) {
        glProgramUniform4fv(program, kPointCacheGrid, 1, glm::value_ptr(cache->grid));
        glProgramUniform4iv(program, kPointCacheDims, 1, glm::value_ptr(cache->dims));
    }
    glProgramUniform4f(program, kPointCacheParams, cache ? cache->minNormalCosine : 0.f,
                       cache ? cache->planeTolerance : 0.f, cache ? 1.f : 0.f,
                       cache && cache->showPoints ? 1.f : 0.f);

    for (const DrawItem& item : scene.items) {
        const glm::mat3 linear(item.model);
        const glm::mat3 normalMatrix = glm::inverseTranspose(linear);
        glProgramUniformMatrix4fv(program, kModel, 1, GL_FALSE, glm::value_ptr(item.model));
        glProgramUniformMatrix3fv(program, kNormalMatrix, 1, GL_FALSE,
                                  glm::value_ptr(normalMatrix));
        glProgramUniform3fv(program, kAlbedo, 1, glm::value_ptr(item.albedo));
        glProgramUniform3fv(program, kEmission, 1, glm::value_ptr(item.emission));
        glProgramUniform1i(program, kLighting, int(item.lighting));
        glProgramUniform2i(program, kVlfFaces, item.vlfFirstFace, scene.vlf ? item.vlfFaceCount : 0);
        glProgramUniform1i(program, kMirrored, glm::determinant(linear) < 0.f);
        if (item.lighting == SurfaceLighting::SphericalHarmonics)
            glProgramUniform3fv(program, kSh, 9, glm::value_ptr(item.sh[0]));
        glBindTextureUnit(kBaseColorUnit,
                          item.baseColorTexture ? item.baseColorTexture : mWhite.id());
        drawGpuMesh(*item.mesh);
    }
}

int SceneRenderer::maxTextureSize() {
    GLint maxSize = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &maxSize);
    return maxSize;
}

void SceneRenderer::uploadVlf(const VlfGpuTables& vlf) {
    const auto upload = [](GlBuffer& buffer, const void* data, std::size_t bytes) {
        buffer = createBuffer();
        // An empty table still needs a buffer to bind: one zero word.
        const std::uint32_t zero = 0;
        glNamedBufferStorage(buffer.id(), GLsizeiptr(bytes ? bytes : sizeof(zero)),
                             bytes ? data : &zero, 0);
    };
    upload(mVlfBuffers[0], vlf.directions.data(), vlf.directions.size() * sizeof(glm::vec4));
    upload(mVlfBuffers[1], vlf.triangles.data(), vlf.triangles.size() * sizeof(glm::ivec4));
    upload(mVlfBuffers[2], vlf.faces.data(), vlf.faces.size() * sizeof(glm::vec4));
    upload(mVlfBuffers[3], vlf.blocks.data(), vlf.blocks.size() * sizeof(glm::ivec4));
    upload(mVlfBuffers[4], vlf.slots.data(), vlf.slots.size() * sizeof(std::int32_t));
    // Tile atlas: kVlfAtlasTiles tiles of m x m cells per row. The bake checked the size
    // against the limit already (VlfSettings::maxAtlasSize) when FrameSchedule set it; a field
    // from elsewhere is checked here.
    const int m = std::max(vlf.tileSize, 1);
    const std::size_t tiles = vlf.cells.size() / std::size_t(m * m);
    const VlfAtlasSize atlas = vlfAtlasSize(tiles, m);
    const int maxSize = maxTextureSize();
    if (atlas.width > maxSize || atlas.height > maxSize)
        fail("VLF tile atlas of ", atlas.width, "x", atlas.height, " texels exceeds the GL limit ",
             maxSize, " (fewer directions or lines, or smaller tiles)");
    const int width = int(atlas.width), rows = int(atlas.height) / m;
    std::vector<glm::u16vec4> texels(std::size_t(width) * std::size_t(rows * m),
                                     glm::u16vec4(0)); // half floats: 0 is +0
    for (std::size_t t = 0; t < tiles; ++t) {
        const std::size_t x0 = (t % kVlfAtlasTiles) * std::size_t(m);
        const std::size_t y0 = (t / kVlfAtlasTiles) * std::size_t(m);
        for (int v = 0; v < m; ++v)
            for (int u = 0; u < m; ++u)
                texels[(y0 + std::size_t(v)) * std::size_t(width) + x0 + std::size_t(u)] =
                    vlf.cells[t * std::size_t(m * m) + std::size_t(v * m + u)];
    }
    mVlfAtlas = createTexture(GL_TEXTURE_2D);
    glTextureStorage2D(mVlfAtlas.id(), 1, GL_RGBA16F, width, rows * m);
    useTightUnpacking();
    glTextureSubImage2D(mVlfAtlas.id(), 0, 0, 0, width, rows * m, GL_RGBA, GL_HALF_FLOAT,
                        texels.data());
    glTextureParameteri(mVlfAtlas.id(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(mVlfAtlas.id(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    mVlfVersion = vlf.version;
    logInfo("VLF uploaded: ", tiles, " tiles in a ", width, "x", rows * m,
            " atlas of half floats (", double(texels.size() * sizeof(glm::u16vec4)) / 1e6, " MB)");
}

void SceneRenderer::tonemapAndPresent() {
    PipelineState state;
    state.framebuffer = mLdrTarget.id();
    state.viewportWidth = mSettings.width;
    state.viewportHeight = mSettings.height;
    state.depthTest = false;
    state.depthWrite = false;
    applyState(state);
    glUseProgram(mTonemapProgram.id());
    glProgramUniform1f(mTonemapProgram.id(), kExposure, mSettings.exposure);
    glBindTextureUnit(kHdrUnit, mHdrColor.id());
    glBindVertexArray(mNoVertices.id());
    glDrawArrays(GL_TRIANGLES, 0, 3);

    // Present: scale the tonemapped image to the window's framebuffer.
    int width = 0, height = 0;
    if (!GlWindow::currentFramebufferSize(width, height)) return;
    const bool sameSize = width == mSettings.width && height == mSettings.height;
    glBlitNamedFramebuffer(mLdrTarget.id(), 0, 0, 0, mSettings.width, mSettings.height, 0, 0, width,
                           height, GL_COLOR_BUFFER_BIT, sameSize ? GL_NEAREST : GL_LINEAR);
}

ImageF SceneRenderer::readHdr() const {
    return {mSettings.width, mSettings.height,
            readTexture<float>(mHdrColor.id(), mSettings.width, mSettings.height, GL_FLOAT)};
}

Image8 SceneRenderer::readLdr() const {
    return {mSettings.width, mSettings.height,
            readTexture<std::uint8_t>(mLdrColor.id(), mSettings.width, mSettings.height,
                                      GL_UNSIGNED_BYTE)};
}

} // namespace qgi
