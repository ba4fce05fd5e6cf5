#include "systems/frame/FrameSchedule.h"

#include "runtime/profile/FrameProfiler.h"
#include "runtime/raytrace/RayScene.h"

namespace qgi {

FrameSchedule::FrameSchedule(Registry& registry, const FrameSettings& settings) {
    if (!registry.ctx().contains<FrameProfiler>()) registry.ctx().emplace<FrameProfiler>();
    if (!registry.ctx().contains<RayScene>()) {
        FrameProfiler::Scope scope(&registry.ctx().get<FrameProfiler>(), "load.raytrace");
        registry.ctx().emplace<RayScene>().build(registry);
    }
    if (settings.render) mRender = std::make_unique<RenderSystem>(*settings.render);

    mSchedule.addPhase("input")
        .addPhase("animation")
        .addPhase("transform")
        .addPhase("raytrace.sync")
        .addPhase("render");

    mSchedule.add("animation", "animation",
                  [this](Registry& r, const FrameContext& f) { mAnimation.update(r, f); });
    mSchedule.add("transform", "transform",
                  [this](Registry& r, const FrameContext& f) { mTransform.update(r, f); });
    mSchedule.add("raytrace.sync", "raytrace.sync", [](Registry& r, const FrameContext&) {
        r.ctx().get<RayScene>().syncMoved(r);
    });
    if (mRender)
        mSchedule.add("render", "render",
                      [this](Registry& r, const FrameContext& f) { mRender->update(r, f); });
}

} // namespace qgi
