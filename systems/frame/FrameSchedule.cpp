#include "systems/frame/FrameSchedule.h"

#include "runtime/profile/FrameProfiler.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"

namespace qgi {

FrameSchedule::FrameSchedule(Registry& registry, const FrameSettings& settings) {
    if (!registry.ctx().contains<FrameProfiler>()) registry.ctx().emplace<FrameProfiler>();
    if (!registry.ctx().contains<RayScene>()) {
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.raytrace");
        registry.ctx().emplace<RayScene>().build(registry);
    }
    if (settings.photons) {
        mPhotons = std::make_unique<PhotonUpdateSystem>(*settings.photons);
        DetpSettings irradiance = settings.irradiance;
        if (irradiance.photonCount == 0) irradiance.photonCount = settings.photons->photonCount;
        mIrradiance = std::make_unique<DetpIrradianceSystem>(irradiance);
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.irradiance");
        mIrradiance->build(registry);
    }
    if (settings.vlf) {
        mVlf = std::make_unique<VlfSystem>(*settings.vlf);
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

} // namespace qgi
