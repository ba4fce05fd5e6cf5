#pragma once

#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"
#include "runtime/io/Image8.h"
#include "runtime/io/ImageF.h"
#include "runtime/render/RenderScene.h"
#include "runtime/render/RenderSettings.h"
#include "runtime/render/SceneRenderer.h"

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace qgi {

struct GpuResources;

/** Draws the registry's scene from the active Camera (local -Z forward, Y up) with the
 *  SceneRenderer: outgoing radiance = albedo / pi * E + emission, where E is the entity's
 *  per-vertex irradiance (VertexIrradiance, else 0), or for avatars the irradiance of their
 *  ShLighting at the shading normal; hybrid mode adds the direct light of point, spot and
 *  directional lights with shadow maps. Albedo is Material::baseColor times the base colour
 *  texture; entities without Material get Material{}. Both sides of every triangle are drawn.
 *  Spot cones fall off as glTF KHR_lights_punctual suggests (see shaders/common/lighting.glsl).
 *  Meshes reach the GPU lazily and are rebuilt when their Mesh is patched; only the dirty
 *  ranges of VertexIrradiance are uploaded each frame. Shadow maps keep the depth of static
 *  casters; MobileMesh and Avatar entities are redrawn over it in the maps that see them. A
 *  mobile taken out (MobileMesh::active false) is neither drawn nor casts shadows.
 *  Reads:  const Camera, const WorldTransform, const Mesh, const Material, const MobileMesh
 *          (and its change list),
 *          const Avatar, const ShLighting, const PointLight, const SpotLight,
 *          const DirectionalLight, const Name (logs), ctx<const TextureLibrary>,
 *          ctx<FrameProfiler> (pass times)
 *  Surfaces tagged PointCacheShaded are shaded from ctx<PointCache> per fragment (hybrid
 *  mode), its points and grid uploaded as shader storage buffers when they change.
 *  Writes: VertexIrradiance::dirty (uploaded, then cleared), ctx<GpuResources>
 *  Needs a current GL 4.5 context from construction to destruction.                      */
class RenderSystem {
public:
    /// Throws qgi::Error for bad settings or a shader that does not compile.
    explicit RenderSystem(const RenderSettings& settings);

    void update(Registry& registry, const FrameContext& frame);

    /// At the end of the next update, writes `base`.exr (the HDR radiance, float, linear) and
    /// `base`.png (the tonemapped image). Throws qgi::Error now if base's folder does not
    /// exist; a write that still fails is logged (the frame does not throw).
    void requestScreenshot(const std::filesystem::path& base);
    /// What became of the last screenshot taken: written, or why not (empty until one is).
    struct ScreenshotOutcome {
        std::filesystem::path base;
        std::string error; ///< empty: both files were written
    };
    const std::optional<ScreenshotOutcome>& lastScreenshot() const { return mLastScreenshot; }

    void setExposure(float exposure) { mRenderer.setExposure(exposure); }
    /// Debug view: draw the point cache's points as dots over the surfaces.
    void setShowPointCache(bool show) { mPointCacheView.showPoints = show; }
    bool showPointCache() const { return mPointCacheView.showPoints; }
    const RenderSettings& settings() const { return mRenderer.settings(); }

    /// The last frame: radiance W/(m^2 sr), and tonemapped sRGB; top row first.
    ImageF readHdr() const { return mRenderer.readHdr(); }
    Image8 readLdr() const { return mRenderer.readLdr(); }

private:
    void syncMeshes(Registry& registry, GpuResources& gpu, RenderScene& scene);
    void collectLights(const Registry& registry);
    bool findCamera(const Registry& registry, RenderCamera& camera);
    void sortFrontToBack(const glm::vec3& eye);
    GLuint baseColorTexture(const Registry& registry, GpuResources& gpu, int index);
    void writeScreenshot(const std::filesystem::path& base);
    /// The VlfField resource in the renderer's layout (rebuilt when the field is replaced).
    const VlfGpuTables* vlfTables(const Registry& registry);
    bool syncPointCache(const Registry& registry);

    SceneRenderer mRenderer;
    std::vector<DrawItem> mItems;
    std::vector<RenderLight> mLights;
    std::vector<Entity> mStale;
    std::optional<std::filesystem::path> mScreenshot;
    std::optional<ScreenshotOutcome> mLastScreenshot;
    // The point cache's GPU copy (shaders/common/pointcache.glsl).
    GlBuffer mCachePoints, mCacheCellStart, mCacheCellPoints;
    PointCacheView mPointCacheView;
    std::uint64_t mCacheSet = ~0ull;       ///< pointSetVersion of the uploaded point set
    std::uint64_t mCacheVersion = ~0ull;   ///< its shadingVersion at the last upload
    std::vector<glm::vec4> mCacheStaging;
    bool mWarnedNoCamera = false;
    /// The camera's last pose that isUsablePose() accepted: a pose past it (a runaway camera
    /// animation at 1e30 m, where nothing can be seen) keeps the view there, as meshes keep
    /// theirs.
    std::optional<glm::mat4> mCameraPose;
    bool mWarnedTexture = false;
    VlfGpuTables mVlf;
    const void* mVlfSource = nullptr; ///< the VlfField the tables were built from
    std::uint64_t mVlfKey = 0;        ///< and its bake key
};

} // namespace qgi
