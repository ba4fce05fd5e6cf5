#pragma once

#include "runtime/ecs/Registry.h"
#include "runtime/ecs/Schedule.h"
#include "systems/animation/AnimationSystem.h"
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "systems/point_cache/PointCacheSystem.h"
#include "systems/render/RenderSystem.h"
#include "systems/sh_probes/ShProbeSystem.h"
#include "systems/transform/TransformSystem.h"
#include "systems/vlf/VlfSystem.h"

#include <memory>
#include <optional>
#include <vector>

namespace qgi {

/// What the frame runs. Photon mode by default (all light from photons); for hybrid mode
/// (direct light in the shader) set irradiance.hybrid, probes->hybrid and render->mode alike:
/// the schedule warns when they disagree.
struct FrameSettings {
    /// Photon transport and per-vertex irradiance; off: no global illumination (direct only).
    std::optional<PhotonSettings> photons = PhotonSettings{};
    DetpSettings irradiance;
    /// SH probe volume lighting the avatars; off: avatars keep whatever ShLighting they have.
    /// Set `hybrid` to match the render mode.
    std::optional<ShProbeSettings> probes = ShProbeSettings{};
    /// The point cache (soft shadows of area lights and indirect light blended per fragment on
    /// surfaces tagged PointCacheShaded); off unless set. Built (or loaded) at construction.
    std::optional<PointCacheSettings> pointCache;
    /// Draw with the renderer (needs a current GL 4.5 context); off for lighting-only runs.
    std::optional<RenderSettings> render = RenderSettings{.mode = ShadingMode::Photon};
    /// Virtual Light Field of the static scene for glossy and mirror surfaces: baked (or
    /// loaded from its cache) at construction, looked up by the renderer; off by default.
    std::optional<VlfSystemSettings> vlf;
};

/** The frame, in one place: owns the systems and lists them in the order they run.
 *
 *    input             (added by the application: player input)
 *    animation         scripted paths move cameras, mobiles, avatars, lights
 *    transform         world matrices; WorldTransform patched only where a pose changed
 *    raytrace.sync     Embree instances of moved or switched mobiles, one top-level commit
 *    photon.update     re-traces the photon paths a moved mobile touched; PhotonDelta
 *    detp.irradiance   per-vertex irradiance: static E += E(new) - E(old), moved mobiles in full
 *    (vlf: baked or loaded at construction; static, so no per-frame entry)
 *    sh.probes         stale probes re-projected within a budget; every avatar's ShLighting
 *    point.cache       point cache: indirect from the photon delta, soft shadows around moved
 *                      mobiles within a per-frame budget
 *    render            uploads dirty ranges, draws, tonemaps
 *
 *  Construction (re)builds the world resources the systems share from the registry as it is
 *  now: the RayScene (rebuilt in place when there is one, keeping its Embree device), the
 *  ProbeVolume when the scene has a SceneInfo, and a FrameProfiler unless there is one.
 *  Meshes added or destroyed afterwards are not traced or lit until a new FrameSchedule is
 *  built; run() says so in a warning, once. Mobiles switched with MobileMesh::active are
 *  followed frame by frame (the pool for objects that come and go). Systems never call each
 *  other.                                                                                   */
class FrameSchedule {
public:
    FrameSchedule(Registry& registry, const FrameSettings& settings);

    Schedule& schedule() { return mSchedule; }
    /// One frame. `registry` must be the one the schedule was built for (asserted).
    void run(Registry& registry, const FrameContext& frame);
    RenderSystem* renderer() { return mRender.get(); }
    PhotonUpdateSystem* photons() { return mPhotons.get(); }
    DetpIrradianceSystem* irradiance() { return mIrradiance.get(); }
    ShProbeSystem* probes() { return mProbes.get(); }
    PointCacheSystem* pointCache() { return mPointCache.get(); }

private:
    /// Warns, once each, when mesh entities came or went since construction, and when game
    /// code moved a static mesh or edited a Mesh: changes the lighting does not follow.
    void checkMeshesUnchanged(const Registry& registry);
    /// Patches MobileMesh of mobiles whose `active` game code wrote without patch (the ray
    /// scene, which only follows patches, disagrees), so every system sees the switch this
    /// frame; warns once.
    void followUnpatchedSwitches(Registry& registry);

    const Registry* mRegistry = nullptr;
    std::vector<Entity> mMeshes; ///< StaticMesh and MobileMesh entities at construction
    std::size_t mStaticCount = 0, mMobileCount = 0;
    bool mWarnedMeshChange = false, mWarnedStaticEdit = false, mWarnedUnpatched = false;
    std::uint64_t mFramesRun = 0;
    Schedule mSchedule;
    AnimationSystem mAnimation;
    TransformSystem mTransform;
    std::unique_ptr<PhotonUpdateSystem> mPhotons;
    std::unique_ptr<DetpIrradianceSystem> mIrradiance;
    std::unique_ptr<ShProbeSystem> mProbes;
    std::unique_ptr<PointCacheSystem> mPointCache;
    std::unique_ptr<RenderSystem> mRender;
    std::unique_ptr<VlfSystem> mVlf;
};

} // namespace qgi
