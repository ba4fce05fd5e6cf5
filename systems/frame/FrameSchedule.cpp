#include "systems/frame/FrameSchedule.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/StaticMesh.h"
#include "components/Transform.h"
#include "runtime/core/Log.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/render/SceneRenderer.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneQueries.h"

namespace qgi {

FrameSchedule::FrameSchedule(Registry& registry, const FrameSettings& settings)
    : mRegistry(&registry) {
    if (!registry.ctx().contains<FrameProfiler>()) registry.ctx().emplace<FrameProfiler>();
    // Photon and hybrid mode split the light differently: every part must agree on which.
    const bool hybrid = settings.irradiance.hybrid;
    if ((settings.probes && settings.probes->hybrid != hybrid) ||
        (settings.render && (settings.render->mode == ShadingMode::Hybrid) != hybrid))
        logWarning("FrameSettings: irradiance.hybrid is ", hybrid ? "on" : "off",
                   " but probes.hybrid or render.mode says otherwise: light will be counted "
                   "twice or not at all");
    // Entities built in code may have a Transform and no WorldTransform yet.
    mTransform.update(registry, FrameContext{});
    if (!registry.ctx().contains<SceneInfo>()) {
        SceneInfo& info = registry.ctx().emplace<SceneInfo>(describeMeshes(registry));
        logInfo("FrameSchedule: no SceneInfo (the loaders write one); described the meshes: ",
                "longest edge ", info.maxEdgeLength, " m");
    }
    {
        // Rebuilt even when there is one: a new schedule is how meshes added or removed since
        // the last one get traced (in place, so the Embree device systems hold stays valid).
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.raytrace");
        RayScene* scene = registry.ctx().find<RayScene>();
        (scene ? *scene : registry.ctx().emplace<RayScene>()).build(registry);
    }
    mMeshes = registry.view<const StaticMesh>().entities();
    mStaticCount = mMeshes.size();
    const std::vector<Entity> mobiles = registry.view<const MobileMesh>().entities();
    mMobileCount = mobiles.size();
    mMeshes.insert(mMeshes.end(), mobiles.begin(), mobiles.end());
    if (settings.photons) {
        mPhotons = std::make_unique<PhotonUpdateSystem>(*settings.photons);
        DetpSettings irradiance = settings.irradiance;
        if (irradiance.photonCount == 0) irradiance.photonCount = settings.photons->photonCount;
        mIrradiance = std::make_unique<DetpIrradianceSystem>(irradiance);
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.irradiance");
        mIrradiance->build(registry);
    }
    if (settings.vlf) {
        VlfSystemSettings vlf = *settings.vlf;
        // The renderer holds the field's tiles in one texture: a field too large for this GL
        // context fails before its bake, not minutes later at the upload.
        if (settings.render && vlf.bake.maxAtlasSize == 0)
            vlf.bake.maxAtlasSize = SceneRenderer::maxTextureSize();
        mVlf = std::make_unique<VlfSystem>(vlf);
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.vlf");
        mVlf->build(registry);
    }
    // A scene without meshes has no bounds to lay probes over (and nothing to light them).
    const SceneInfo* info = registry.ctx().find<SceneInfo>();
    if (settings.probes && info && !info->bounds.empty()) {
        mProbes = std::make_unique<ShProbeSystem>(*settings.probes);
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.probes");
        mProbes->build(registry);
    }
    if (settings.pointCache) {
        mPointCache = std::make_unique<PointCacheSystem>(*settings.pointCache);
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.pointcache");
        mPointCache->build(registry);
    }
    if (settings.render) mRender = std::make_unique<RenderSystem>(*settings.render);

    mSchedule.addPhase("input")
        .addPhase("animation")
        .addPhase("transform")
        .addPhase("raytrace.sync")
        .addPhase("photon.update")
        .addPhase("detp.irradiance")
        .addPhase("sh.probes")
        .addPhase("point.cache")
        .addPhase("render");

    mSchedule.add("animation", "animation",
                  [this](Registry& r, const FrameContext& f) { mAnimation.update(r, f); });
    mSchedule.add("transform", "transform",
                  [this](Registry& r, const FrameContext& f) { mTransform.update(r, f); });
    mSchedule.add("raytrace.sync", "raytrace.sync", [](Registry& r, const FrameContext&) {
        r.ctx().get<RayScene>().syncMoved(r);
    });
    if (mPhotons) {
        mSchedule.add("photon.update", "photon.update",
                      [this](Registry& r, const FrameContext& f) { mPhotons->update(r, f); });
        mSchedule.add("detp.irradiance", "detp.irradiance",
                      [this](Registry& r, const FrameContext& f) { mIrradiance->update(r, f); });
    }
    if (mProbes)
        mSchedule.add("sh.probes", "sh.probes",
                      [this](Registry& r, const FrameContext& f) { mProbes->update(r, f); });
    if (mPointCache)
        mSchedule.add("point.cache", "point.cache",
                      [this](Registry& r, const FrameContext& f) { mPointCache->update(r, f); });
    if (mRender)
        mSchedule.add("render", "render",
                      [this](Registry& r, const FrameContext& f) { mRender->update(r, f); });
}

void FrameSchedule::run(Registry& registry, const FrameContext& frame) {
    QGI_ASSERT(&registry == mRegistry,
               "FrameSchedule::run was given a Registry other than the one it was built for "
               "(build a FrameSchedule for each registry)");
    checkMeshesUnchanged(registry);
    followUnpatchedSwitches(registry);
    mSchedule.run(registry, frame);
}

void FrameSchedule::followUnpatchedSwitches(Registry& registry) {
    const RayScene* scene = registry.ctx().find<RayScene>();
    if (!scene) return;
    for (std::size_t i = mStaticCount; i < mMeshes.size(); ++i) {
        const Entity e = mMeshes[i];
        const MobileMesh* mobile = registry.alive(e) ? registry.tryGet<MobileMesh>(e) : nullptr;
        if (!mobile || !scene->isMobile(e) || mobile->active == scene->mobileActive(e) ||
            registry.wasChanged<MobileMesh>(e))
            continue;
        registry.patch<MobileMesh>(e);
        if (mWarnedUnpatched) continue;
        mWarnedUnpatched = true;
        logWarning("FrameSchedule: MobileMesh::active of ", entityName(registry, e),
                   " was written without patch; followed now, but write it through "
                   "registry.patch<MobileMesh>(e) so that systems run outside a FrameSchedule "
                   "see it too");
    }
}

void FrameSchedule::checkMeshesUnchanged(const Registry& registry) {
    // Game code's changes since the last frame (the first frame's are the scene's creation).
    if (mFramesRun++ > 0 && !mWarnedStaticEdit) {
        std::string edit;
        for (const Entity e : registry.changed<Transform>())
            if (registry.has<StaticMesh>(e)) {
                edit = str("static mesh ", entityName(registry, e),
                           " moved; a mesh that moves must be a MobileMesh");
                break;
            }
        for (const Entity e : registry.changed<Mesh>())
            if (edit.empty() && (registry.has<StaticMesh>(e) || registry.has<MobileMesh>(e)))
                edit = str("the Mesh of ", entityName(registry, e), " changed");
        if (!edit.empty()) {
            mWarnedStaticEdit = true;
            logWarning("FrameSchedule: ", edit,
                       "; lighting keeps what the schedule was built "
                       "with until a new FrameSchedule is built");
        }
    }
    if (mWarnedMeshChange) return;
    std::string change;
    for (const Entity e : mMeshes)
        if (!registry.alive(e)) {
            change = str("mesh entity ", e.index, " was destroyed");
            break;
        }
    const std::size_t statics = registry.view<const StaticMesh>().sizeHint();
    const std::size_t mobiles = registry.view<const MobileMesh>().sizeHint();
    if (change.empty() && (statics != mStaticCount || mobiles != mMobileCount))
        change = str(statics, " static and ", mobiles, " mobile meshes where there were ",
                     mStaticCount, " and ", mMobileCount);
    if (change.empty()) return;
    mWarnedMeshChange = true;
    logWarning("FrameSchedule: the scene's meshes changed since it was built (", change,
               "); lighting keeps tracing and lighting the meshes it was built with until a "
               "new FrameSchedule is built (objects that come and go during play: create them "
               "up front and switch MobileMesh::active)");
}

} // namespace qgi
