#pragma once

#include "runtime/ecs/Entity.h"
#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/SphericalHarmonics.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/sh_probes/ProbeVolume.h"
#include "systems/sh_probes/ShProbeSettings.h"

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include <cstdint>
#include <span>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace qgi {

class RayScene;

/** Lights avatars from an irradiance volume of order-2 SH probes that follows the scene
 *  (seed 002 section 3.4: an irradiance volume over the scene bounds, queried by trilinear
 *  interpolation of the 8 nearest probes, shaded per pixel).
 *
 *  Volume (build()): a ProbeGrid over SceneInfo::bounds at the settings' spacing, held in the
 *  ProbeVolume world resource. A probe is projected from raysPerProbe rays cast with Embree in
 *  a spherical Fibonacci set turned by a rotation drawn from (seed, probe index), so a
 *  re-projection of an unchanged scene is bit-identical. Each ray brings the radiance the
 *  scene shows, W/(m^2 sr):
 *   - a front face: Material::emission + Material::baseColor / pi x E, with E the hit
 *     triangle's VertexIrradiance interpolated at the hit's barycentrics (0 without one); in
 *     hybrid mode E also takes the direct light of the punctual lights at the hit, by one
 *     shadow ray to a light picked in proportion to its unshadowed contribution and weighted
 *     by the inverse of that probability (the renderer draws direct light on surfaces, so
 *     per-vertex irradiance then has only the rest);
 *   - a back face: nothing (no surface's back side is lit in the engine); the share of back
 *     faces decides whether the probe is inside geometry (settings.backFaceShare: disabled);
 *   - a miss: SceneInfo::environment.
 *  Photon mode adds, per probe, each punctual light that shoots photons (not LightStandIn) as
 *  a directional source with one shadow ray, since the avatar shader draws no direct light.
 *  Textures are not sampled (albedo = baseColor), as in the photon transport.
 *
 *  Following the scene (update()): the first update projects every probe. Later frames mark
 *  probes stale
 *   - within influenceDistance of the end points (hits) of this frame's PhotonDelta segments
 *     (each delta read once, by PhotonDelta::sequence),
 *     old and new, the only places where per-vertex irradiance can have changed, wherever
 *     minDeltaEndPoints of them have fallen in one half-spacing cell (over this and earlier
 *     frames, since the cell last marked; counts halve every 32 frames);
 *   - near a moved mobile's old or new world bounds (or its bounds, when it was taken out or
 *     put back: MobileMesh::active): within influenceDistance, or as far as
 *     its bounding sphere covers mobileSolidAngleShare of a probe's sphere of directions
 *     (what it hides, shows or bleeds onto changed; the visibility masks of cells it
 *     overlaps are dropped); in photon mode also the probes whose shadow ray to a light
 *     crosses those bounds (their own direct light changed);
 *   - all of them when the delta is full or one was missed (its sequence skipped), a
 *     punctual light changed or moved, or a Material changed;
 *  and re-project at most updateBudget stale probes a frame, nearest (in cells) to an avatar
 *  first, ties by index; besides them a sweep visits sweepPerFrame probes round robin over the
 *  volume and re-projects each one the budget did not choose, stale or not, so every probe is
 *  projected afresh within ceil(probeCount / sweepPerFrame) frames of any change: whatever the
 *  marking rules let through is put right in that time, and so is a stale probe far from
 *  every avatar that the budget keeps passing over. The sweep goes on while the scene changes
 *  and for one round after its last change, then rests: by then every probe has been
 *  projected since that change, so an unchanged scene costs the avatar lookups only.
 *
 *  Avatars (every frame): the radiance SH at the avatar's origin (WorldTransform translation)
 *  from ProbeVolume::interpolate: trilinear weights, zero for disabled probes and for probes
 *  hidden from the avatar by geometry (per-cell visibility lattice, computed on the first
 *  visit of a cell, spacing / visibilitySubdivisions apart), written to ShLighting. An avatar
 *  whose probes are all disabled or all hidden (a closet narrower than the spacing) keeps the
 *  ShLighting it had: blending hidden probes would light it through the walls.
 *
 *  Reads:  const Avatar, const WorldTransform (and its change list), const Mesh,
 *          const Material (and its change list), const MobileMesh (and its change list),
 *          const VertexIrradiance,
 *          const PointLight, const SpotLight, const DirectionalLight, const LightStandIn,
 *          ctx<const RayScene>, ctx<const SceneInfo>, ctx<const PhotonDelta> (when present),
 *          ctx<FrameProfiler> (sub-scopes, when present)
 *  Writes: ShLighting (emplaced on avatars), ctx<ProbeVolume> (emplaced by build())       */
class ShProbeSystem {
public:
    /// What the last update() did, for profiling and tests.
    struct FrameStats {
        bool full = false;               ///< every probe was projected (first update)
        std::size_t markedStale = 0;     ///< probes newly marked stale this frame
        std::size_t staleBefore = 0;     ///< stale probes before this frame's refresh
        std::size_t refreshed = 0;       ///< probes re-projected this frame
        std::size_t swept = 0;           ///< of them, added by the sweep (sweepPerFrame)
        std::size_t sweptFresh = 0;      ///< of those, probes that were not marked stale
        std::size_t staleAfter = 0;      ///< stale probes left for later frames
        std::size_t visibilityCells = 0; ///< cell visibility masks computed this frame
        std::size_t avatars = 0;         ///< avatars written
        std::size_t fallbacks = 0;       ///< avatars blended without their corners' weights
        std::size_t hidden = 0;          ///< of them, those whose probes all hid: kept their light
        std::size_t unlit = 0;           ///< avatars among 8 disabled probes (left as they were)
        std::size_t outside = 0;         ///< avatars over a probe spacing outside the volume
    };

    /// Throws qgi::Error for settings out of range (see validate()).
    explicit ShProbeSystem(const ShProbeSettings& settings);

    /// Set-up once the scene, its WorldTransforms, SceneInfo and the RayScene exist: lays out
    /// the grid and emplaces (replaces) ProbeVolume; the projection waits for the first
    /// update() (per-vertex irradiance is ready only then). Throws qgi::Error on a missing
    /// resource, empty bounds without a spacing, or more probes than settings.maxProbes.
    void build(Registry& registry);

    /// The frame. Never throws. Does nothing before build().
    void update(Registry& registry, const FrameContext& frame);

    /// Parts of update(), public for tests and benchmarks.
    /// Re-projects `probes` now (parallel over probes).
    void projectProbes(const Registry& registry, std::span<const std::uint32_t> probes);
    /// Re-projects every probe.
    void projectAll(const Registry& registry);
    /// Interpolates every avatar's ShLighting (computing missing cell visibility first).
    void lightAvatars(Registry& registry);
    /// Marks every probe stale (refreshed over the next frames within the budget).
    void markAllStale();

    const ShProbeSettings& settings() const { return mSettings; }
    float spacing() const { return mSpacing; }
    float influenceDistance() const { return mInfluence; }
    const FrameStats& lastFrame() const { return mStats; }
    std::size_t staleCount() const { return mStaleCount; }
    bool isStale(std::uint32_t probe) const { return mStale[probe] != 0; }
    /// The probes re-projected by the last update, in the order chosen.
    std::span<const std::uint32_t> lastRefreshed() const { return mRefresh; }

private:
    struct Surface {
        glm::vec3 albedo{0.f};
        glm::vec3 emission{0.f}; ///< W/(m^2 sr), front side
        const std::uint32_t* indices = nullptr;
        std::size_t indexCount = 0;
        const glm::vec3* irradiance = nullptr; ///< W/m^2 per vertex; null: none
        std::size_t vertexCount = 0;
    };
    struct Light {
        enum class Kind { Point, Spot, Directional } kind = Kind::Point;
        glm::vec3 position{0.f};
        glm::vec3 direction{0.f}; ///< unit, where the light travels (spot axis, directional)
        glm::vec3 radiance{0.f};  ///< W/sr (point, spot) or W/m^2 (directional)
        float coneScale = 0.f, coneOffset = 0.f;
        bool standIn = false;
    };
    struct Mobile {
        Aabb objectBounds;
        Aabb worldBounds;    ///< at the pose the probes last saw
        glm::mat4 pose{1.f}; ///< the pose the probes last saw (a turn may keep the bounds)
        bool active = true;  ///< MobileMesh::active as the probes last saw it
    };

    void snapshot(const Registry& registry);
    void snapshotLights(const Registry& registry);
    void markShadowed(const Aabb& box);
    /// Irradiance at normal incidence from `light` at x, W/m^2, and the unit direction toward
    /// it; false when it sends nothing to x.
    static bool lightAt(const Light& light, const glm::vec3& x, glm::vec3& toward, float& distance,
                        glm::vec3& irradiance);
    /// Projects one probe; returns how many of its rays met vertex irradiance that is not
    /// finite (read as none).
    std::uint32_t projectProbe(std::uint32_t probe, ProbeVolume& volume) const;
    void computeVisibility(std::uint32_t cell, ProbeVolume& volume) const;
    void markNear(const glm::vec3& point, float radius);
    void markNearBox(const Aabb& box, float radius);
    /// Marks the probes this frame's changes reach; true when the scene changed at all (a
    /// light, a material, a mobile's pose or presence, a photon delta with paths), whether or
    /// not the rules marked a probe for it.
    bool markChanges(const Registry& registry);
    void chooseRefresh(const Registry& registry);
    /// Visits the next sweepPerFrame probes round robin, while the sweep still owes visits
    /// (mSweepOwed), and appends to mRefresh each one that chooseRefresh did not put there.
    void sweep();

    ShProbeSettings mSettings;
    float mSpacing = 0.f;
    float mInfluence = 0.f;
    bool mBuilt = false;
    bool mProjected = false;
    const RayScene* mRays = nullptr;
    ProbeVolume* mVolume = nullptr;
    glm::vec3 mEnvironment{0.f};
    std::unordered_map<Entity, Mobile> mMobiles;
    std::vector<std::uint8_t> mStale;   ///< per probe
    std::vector<std::uint32_t> mChosen; ///< sweep(): the budget's choices, sorted
    std::size_t mStaleCount = 0;
    std::uint32_t mSweepCursor = 0;  ///< next probe the sweep visits
    /// Visits the sweep still owes: a whole round from each change on, so that it rests once
    /// it has gone round the volume after the scene's last change.
    std::uint32_t mSweepOwed = 0;
    PhotonDeltaReader mDeltaReader;
    FrameStats mStats;

    // Snapshot of the scene the projection reads (rebuilt before each projection batch).
    std::vector<Surface> mSurfaces; ///< by Entity::index
    std::vector<Light> mLights;
    /// Which punctual lights there were at the last frame, and which were stand-ins
    /// (lightSetSignature): a light removed (entity destroyed, component or pose taken off) or
    /// tagged is no entry of the change lists.
    std::uint64_t mLightSet = 0;

    // Frame scratch.
    std::vector<std::uint32_t> mRefresh;
    std::vector<std::uint32_t> mCandidates;
    std::vector<std::uint32_t> mDistance;
    std::vector<std::uint32_t> mQueue;
    /// Delta end points counted per half-spacing cell since the cell last marked its probes,
    /// halved every kEndPointHalfLife frames.
    static constexpr std::uint32_t kEndPointHalfLife = 32;
    std::vector<std::uint16_t> mFineTouched;
    std::uint32_t mFramesSinceHalving = 0;
    std::vector<std::uint32_t> mPendingCells;
    std::vector<std::uint8_t> mCellQueued;
    std::vector<Entity> mAvatarEntities;
    std::unordered_set<Entity> mWarnedOutside; ///< avatars named for leaving the probe volume
    std::unordered_set<Entity> mWarnedHidden;  ///< avatars named for standing among hidden probes
    std::unordered_set<Entity> mWarnedNoPosition; ///< avatars named for a position not finite
    bool mWarnedNonFinite = false;      ///< non-finite vertex irradiance reported once
};

} // namespace qgi
