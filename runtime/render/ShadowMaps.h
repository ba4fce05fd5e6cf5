#pragma once

#include "runtime/render/GlHandle.h"
#include "runtime/render/RenderScene.h"
#include "runtime/render/ShaderInterface.h"

#include <glm/mat4x4.hpp>

#include <array>
#include <span>
#include <string>
#include <vector>

namespace qgi {

class PassTimer;

/// The shadow-map layers a light was given this frame.
struct LightShadow {
    int layer = -1; ///< first layer in the shadow array; -1: unshadowed
    int faces = 0;  ///< 6: cube faces in +X -X +Y -Y +Z -Z order; 1: one map
    /// World size of one shadow texel: per metre of distance from the light (perspective maps)
    /// or in metres (directional).
    float texelScale = 0.f;
};

/** Shadow maps for hybrid mode, all layers of one 2D depth array (one sampler, one code path
 *  in the shader: llvmpipe executes both sides of a branch it cannot prove uniform):
 *  - point lights, and spots wider than one map covers: six 90-degree perspective faces;
 *  - spot lights: one perspective map around the cone;
 *  - directional lights: one orthographic map over the bounds of all casters.
 *  Layers go to lights in order, up to shader::kMaxShadowLayers; lights past the limit are
 *  drawn unshadowed (logged once). Casters are every draw item, both faces, with a
 *  slope-scaled depth bias.
 *  Quasi-static scenes: the depth of static casters is kept in its own array and redrawn only
 *  when a static caster or a light changes. When movable casters move, only the layers that
 *  see one (now or at their last refresh) are refreshed: static depth copied, movables drawn
 *  over it.                                                                                */
class ShadowMaps {
public:
    ShadowMaps(int size, const std::string& defines);

    /// Assigns layers to `lights` and redraws what changed (see RenderScene for the flags).
    void update(std::span<const RenderLight> lights, std::span<const DrawItem> casters,
                bool staticCastersChanged, bool movableCastersChanged, PassTimer& timer);

    /// Per light of the last update, in order.
    std::span<const LightShadow> shadows() const { return mShadows; }
    /// World to clip space of each layer in use.
    std::span<const glm::mat4> matrices() const { return {mMatrices.data(), mLayers}; }

    void bindTexture(GLuint unit) const;

private:
    struct Sphere {
        glm::vec3 center;
        float radius; ///< negative: nothing to draw
    };

    void assign(std::span<const RenderLight> lights, std::span<const DrawItem> casters);
    bool allocate(int layers);
    bool seesMovable(int layer, std::span<const DrawItem> casters) const;
    /// Draws the casters whose `movable` flag matches into a layer; static ones start afresh.
    void drawLayer(const GlTexture& array, int layer, std::span<const DrawItem> casters,
                   bool movable);

    int mSize;
    GlProgram mProgram;
    GlFramebuffer mFramebuffer;
    GlTexture mStatic; ///< depth of the static casters
    GlTexture mArray;  ///< static and movable casters: what the shader samples
    int mAllocatedLayers = -1;
    std::array<bool, shader::kMaxShadowLayers> mSawMovable{}; ///< at the layer's last refresh

    std::vector<LightShadow> mShadows;
    std::array<glm::mat4, shader::kMaxShadowLayers> mMatrices{};
    std::size_t mLayers = 0;
    std::vector<Sphere> mCasterSpheres;    ///< world bounding sphere per caster, for culling
    std::vector<RenderLight> mDrawnLights; ///< the lights the maps were drawn for
    bool mWarnedLimit = false;
};

} // namespace qgi
