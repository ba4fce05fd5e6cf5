#include "runtime/render/ShadowMaps.h"

#include "runtime/core/Log.h"
#include "runtime/render/GpuMesh.h"
#include "runtime/render/PassTimer.h"
#include "runtime/render/PipelineState.h"
#include "runtime/render/ShaderLoader.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <cmath>

namespace qgi {
namespace {

using namespace shader;

// Casters closer to a light than this are clipped from its perspective maps, metres.
constexpr float kNear = 0.01f;
// Spots wider than this (half angle) get cube faces: one perspective map would stretch.
constexpr float kMaxMapHalfAngle = glm::radians(75.f);
// Depth bias of the shadow pass: slope factor and constant units of glPolygonOffset.
constexpr float kBiasSlope = 2.5f;
constexpr float kBiasConstant = 4.f;

// Cube faces in the order the shader's cubeFace() numbers them: forward, up.
constexpr std::array<std::array<glm::vec3, 2>, 6> kCubeFaces{{
    {glm::vec3(1, 0, 0), glm::vec3(0, 1, 0)},
    {glm::vec3(-1, 0, 0), glm::vec3(0, 1, 0)},
    {glm::vec3(0, 1, 0), glm::vec3(0, 0, 1)},
    {glm::vec3(0, -1, 0), glm::vec3(0, 0, 1)},
    {glm::vec3(0, 0, 1), glm::vec3(0, 1, 0)},
    {glm::vec3(0, 0, -1), glm::vec3(0, 1, 0)},
}};

glm::vec3 upFor(const glm::vec3& forward) {
    return std::abs(forward.y) < 0.99f ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0);
}

/// True when the sphere lies entirely outside one of the frustum planes of `viewProjection`
/// (planes from its rows, Gribb and Hartmann).
bool outsideFrustum(const glm::mat4& viewProjection, const glm::vec3& center, float radius) {
    const auto row = [&](int i) {
        return glm::vec4(viewProjection[0][i], viewProjection[1][i], viewProjection[2][i],
                         viewProjection[3][i]);
    };
    for (int axis = 0; axis < 3; ++axis)
        for (const float sign : {1.f, -1.f}) {
            const glm::vec4 plane = row(3) + sign * row(axis);
            const float length = glm::length(glm::vec3(plane));
            if (glm::dot(glm::vec3(plane), center) + plane.w < -radius * length) return true;
        }
    return false;
}

} // namespace

ShadowMaps::ShadowMaps(int size, const std::string& defines)
    : mSize(size), mProgram(loadProgram({"shadow.vert", "shadow.frag"}, defines)),
      mFramebuffer(createFramebuffer()) {
    glNamedFramebufferDrawBuffer(mFramebuffer.id(), GL_NONE);
    glNamedFramebufferReadBuffer(mFramebuffer.id(), GL_NONE);
    allocate(0);
}

void ShadowMaps::bindTexture(GLuint unit) const {
    glBindTextureUnit(unit, mArray.id());
}

bool ShadowMaps::allocate(int layers) {
    if (layers == mAllocatedLayers) return false;
    // With no shadowed light, a 1x1 layer stays bound so the shader's sampler is complete.
    const int size = layers > 0 ? mSize : 1;
    for (GlTexture* array : {&mStatic, &mArray}) {
        *array = createTexture(GL_TEXTURE_2D_ARRAY);
        const GLuint id = array->id();
        glTextureStorage3D(id, 1, GL_DEPTH_COMPONENT32F, size, size, std::max(layers, 1));
        glTextureParameteri(id, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
        glTextureParameteri(id, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
        glTextureParameteri(id, GL_TEXTURE_MIN_FILTER, GL_LINEAR); // 2x2 PCF per lookup
        glTextureParameteri(id, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
        glTextureParameteri(id, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
        glTextureParameteri(id, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    }
    mAllocatedLayers = layers;
    return true;
}

void ShadowMaps::assign(std::span<const RenderLight> lights, std::span<const DrawItem> casters) {
    mShadows.assign(lights.size(), LightShadow{});
    mLayers = 0;

    Aabb bounds;
    mCasterSpheres.clear();
    for (const DrawItem& item : casters) {
        const Aabb& local = item.mesh->bounds;
        if (local.empty()) {
            mCasterSpheres.push_back({glm::vec3(0.f), -1.f});
            continue;
        }
        Aabb world;
        for (int corner = 0; corner < 8; ++corner) {
            const glm::vec3 p((corner & 1) ? local.max.x : local.min.x,
                              (corner & 2) ? local.max.y : local.min.y,
                              (corner & 4) ? local.max.z : local.min.z);
            world.extend(glm::vec3(item.model * glm::vec4(p, 1.f)));
        }
        bounds.extend(world);
        mCasterSpheres.push_back({world.center(), 0.5f * glm::length(world.extent())});
    }
    if (bounds.empty()) return; // nothing casts a shadow
    const glm::vec3 center = bounds.center();
    const float radius = std::max(0.5f * glm::length(bounds.extent()), 1e-3f);

    bool unshadowed = false;
    for (std::size_t i = 0; i < lights.size(); ++i) {
        const RenderLight& light = lights[i];
        const bool cube =
            light.type == LightType::Point ||
            (light.type == LightType::Spot && light.outerConeAngle > kMaxMapHalfAngle);
        const int faces = cube ? 6 : 1;
        if (mLayers + faces > std::size_t(kMaxShadowLayers)) {
            unshadowed = true;
            continue;
        }
        LightShadow& shadow = mShadows[i];
        shadow.layer = int(mLayers);
        shadow.faces = faces;
        const float far =
            std::max((glm::length(center - light.position) + radius) * 1.01f, 2.f * kNear);
        if (cube) {
            const glm::mat4 projection = glm::perspective(glm::radians(90.f), 1.f, kNear, far);
            for (const auto& [forward, up] : kCubeFaces)
                mMatrices[mLayers++] =
                    projection * glm::lookAt(light.position, light.position + forward, up);
            shadow.texelScale = 2.f / float(mSize);
        } else if (light.type == LightType::Spot) {
            // One texel of margin around the cone, so PCF taps at its rim stay on the map.
            const float fov = std::max(2.f * light.outerConeAngle, glm::radians(1.f)) *
                              (1.f + 2.f / float(mSize));
            mMatrices[mLayers++] = glm::perspective(fov, 1.f, kNear, far) *
                                   glm::lookAt(light.position, light.position + light.direction,
                                               upFor(light.direction));
            shadow.texelScale = 2.f * std::tan(0.5f * fov) / float(mSize);
        } else {
            const glm::vec3 eye = center - light.direction * (2.f * radius);
            mMatrices[mLayers++] =
                glm::ortho(-radius, radius, -radius, radius, radius, 3.f * radius) *
                glm::lookAt(eye, center, upFor(light.direction));
            shadow.texelScale = 2.f * radius / float(mSize);
        }
    }
    if (unshadowed && !mWarnedLimit) {
        logWarning("lights need more than ", kMaxShadowLayers,
                   " shadow layers (6 per point light, 1 per spot or directional light): the "
                   "rest are drawn without shadows");
        mWarnedLimit = true;
    }
}

void ShadowMaps::update(std::span<const RenderLight> lights, std::span<const DrawItem> casters,
                        bool staticCastersChanged, bool movableCastersChanged, PassTimer& timer) {
    assign(lights, casters);
    const bool reallocated = allocate(int(mLayers));
    const bool redrawAll =
        reallocated || staticCastersChanged || !std::ranges::equal(lights, mDrawnLights);
    if (!redrawAll && !movableCastersChanged) return;

    PassTimer::Scope scope(timer, "render/shadow");
    for (int layer = 0; layer < int(mLayers); ++layer) {
        const bool movable = seesMovable(layer, casters);
        if (!redrawAll && !movable && !mSawMovable[layer]) continue;
        if (redrawAll) drawLayer(mStatic, layer, casters, false);
        glCopyImageSubData(mStatic.id(), GL_TEXTURE_2D_ARRAY, 0, 0, 0, layer, mArray.id(),
                           GL_TEXTURE_2D_ARRAY, 0, 0, 0, layer, mSize, mSize, 1);
        if (movable) drawLayer(mArray, layer, casters, true);
        mSawMovable[layer] = movable;
    }
    mDrawnLights.assign(lights.begin(), lights.end());
}

bool ShadowMaps::seesMovable(int layer, std::span<const DrawItem> casters) const {
    for (std::size_t i = 0; i < casters.size(); ++i) {
        const Sphere& sphere = mCasterSpheres[i];
        if (casters[i].movable && sphere.radius >= 0.f &&
            !outsideFrustum(mMatrices[std::size_t(layer)], sphere.center, sphere.radius))
            return true;
    }
    return false;
}

void ShadowMaps::drawLayer(const GlTexture& array, int layer, std::span<const DrawItem> casters,
                           bool movable) {
    glNamedFramebufferTextureLayer(mFramebuffer.id(), GL_DEPTH_ATTACHMENT, array.id(), 0, layer);
    PipelineState state;
    state.framebuffer = mFramebuffer.id();
    state.viewportWidth = mSize;
    state.viewportHeight = mSize;
    state.depthBiasSlope = kBiasSlope;
    state.depthBiasConstant = kBiasConstant;
    applyState(state);
    if (!movable) {
        const float farDepth = 1.f;
        glClearNamedFramebufferfv(mFramebuffer.id(), GL_DEPTH, 0, &farDepth);
    }

    const GLuint program = mProgram.id();
    const glm::mat4& viewProjection = mMatrices[std::size_t(layer)];
    glUseProgram(program);
    glProgramUniformMatrix4fv(program, kViewProjection, 1, GL_FALSE,
                              glm::value_ptr(viewProjection));
    for (std::size_t i = 0; i < casters.size(); ++i) {
        const Sphere& sphere = mCasterSpheres[i];
        if (casters[i].movable != movable || sphere.radius < 0.f ||
            outsideFrustum(viewProjection, sphere.center, sphere.radius))
            continue;
        glProgramUniformMatrix4fv(program, kModel, 1, GL_FALSE, glm::value_ptr(casters[i].model));
        drawGpuMesh(*casters[i].mesh);
    }
}

} // namespace qgi
