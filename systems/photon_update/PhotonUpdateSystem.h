#pragma once

#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/Hit.h"
#include "runtime/raytrace/Ray.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonEmitter.h"
#include "systems/photon_update/PhotonSettings.h"
#include "systems/photon_update/PhotonStoreSpace.h"
#include "systems/photon_update/PhotonTracer.h"

#include <glm/mat4x4.hpp>
#include <oneapi/tbb/enumerable_thread_specific.h>

#include <cstdint>
#include <map>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

namespace qgi {

class RayScene;
struct PhotonStore;
struct PhotonDelta;
class PhotonPathGrid;

/** Keeps the photon ray set in step with the scene every frame (seed 000 sections 2.2-2.3,
 *  with seed 004's emission, frame-coherent seeding and progressive refinement).
 *
 *  Full shot (first frame; lights given photons in play that the store has no room for
 *  (below); an emissive surface gaining or losing its light stand-in; every frame with
 *  fullRecompute):
 *  photons shared among the lights in proportion to power, every path traced, the path grid
 *  built (not with fullRecompute: it would cost more than it saves there, 0.4 to 1.3 times
 *  the tracing against a few per cent of DETP's full estimate; it is left empty,
 *  PhotonPathGrid::indexes() false, and DETP then walks every path); PhotonDelta::full.
 *
 *  Otherwise incremental, and the delta lists what changed:
 *   - Mobiles whose pose changed (the ray scene already holds the new pose): the paths with a
 *     segment that hit a moved mobile at its old pose (its recorded hit), or that crosses it
 *     at its new pose, are re-traced from their first such segment; the prefix is untouched.
 *     A mobile taken out (MobileMesh::active) has no new pose, one put back no old one.
 *     Candidates come from the PhotonPathGrid (old and new boxes of every moved mobile), then
 *     an exact test per segment: cost grows with the paths near the mobiles.
 *     With PhotonSettings::reuseLandedPaths (the default), a segment that hit a mobile which
 *     only translated, and still lands on it at the same point of the same plane (within a
 *     millionth of the scene's diagonal), is not an affected segment: the photon reflects as
 *     it did, so its path is kept up to its next affected segment. Such a kept landing is in
 *     the delta as a PhotonRelabel when it lands on another triangle of the plane; the kept
 *     paths then equal a fresh shot's up to that tolerance, not bit for bit. Off: the seed's
 *     rule, and the store stays bit-identical to a fresh shot.
 *   - Surfaces whose albedo was edited (Material::baseColor patched): the paths with a segment
 *     that hit one are re-traced from that segment (the same ray lands where it did and
 *     reflects with the new albedo): the edit adds no error of its own, and on a store that
 *     was a fresh shot's the result is a fresh shot's with the new albedo, bit for bit.
 *     Candidates come from the path grid over the surface's bounds where the ray scene holds
 *     it. The cost grows with the paths that hit it; an edit that leaves more than 1/16 of
 *     the paths changed (and more than 8 times the frame's other re-traced paths) also
 *     rebuilds the path grid in that frame.
 *   - Lights that moved or changed: their own photons are re-shot with the same indices,
 *     reshootBudget photons per frame in all (shared evenly among such lights), oldest first,
 *     until each has been re-shot once since its last change; the delta reports each one with
 *     its whole old and new path. Until then the light's photons mix old and new shots (a
 *     light that moves every frame shows a smear over its last photons / reshootBudget
 *     frames). A punctual light switched off (intensity 0) is such a change: its photons
 *     carry nothing, so they are re-shot empty (no segments) and wait, with their indices,
 *     for it to shine again; the lights still on keep their photons. So is a light no longer
 *     among the sources (its entity, light component or pose gone, a surface's emission set
 *     to 0, an emissive mobile taken out of the world): it is kept, *absent* and dark; once
 *     its photons are all empty they are free for other lights, and listed again it shines
 *     from those it still has, or gets new ones.
 *   - Lights added (or lighting up without photons of their own): each gets photons at the
 *     power per photon of the lights that have some, but with them never fewer than
 *     photonCount lit photons in all, shot within the same budget, so the light fades in
 *     over photons / reshootBudget frames.
 *   - Lights whose photon count drifted 4x above or below their share (of the lit lights'
 *     photons, or of photonCount when they hold fewer; a share of one photon or more): each
 *     is dealt its share anew, and with them every light 2x off. Its old photons go to a
 *     *ghost* (an emitter no source matches, dark, its hybrid flag kept), which re-shoots
 *     them empty within the budget while the new ones are shot: its light fades from the
 *     old photons to the new. The other lights keep theirs, within 2x of their shares then.
 *   Photons a light takes come from *free* ranges first (those of absent lights and ghosts
 *   once all re-shot empty; neighbours merged; the smallest that holds them), else are
 *   appended to the store, which grows to at most kMaxPhotonGrowth (3) times photonCount. A
 *   light that would get under a quarter of its share for want of room, or a ghost for want
 *   of an emitter slot (kMaxLights), has every photon shot anew (a full shot, which also
 *   drops absent lights and ghosts).
 *  Each update stamps the delta with the next PhotonDelta::sequence. The scene's bounds and its
 *  set of mobiles are captured at the first shot: a scene whose meshes are added or removed
 *  needs a new RayScene and a new system. So is the box directional lights cover
 *  (PhotonSettings::directionalBounds; by default the scene's bounds and the scripted paths of
 *  mobiles with a PathFollower); a mobile that leaves it is named in a warning, once.
 *  A re-traced path is rewritten in place when it fits, else moved to its store region's free
 *  room or the overflow; a few regions are compacted every frame (PhotonStoreSpace). The grid is
 * told which paths changed and re-indexes up to gridRefreshBudget paths a frame.
 *
 *  Every random choice comes from PhotonSettings::seed (FrameContext::seed is not read: the
 *  ray set must not change when only the frame does).
 *
 *  Reads:  const WorldTransform (and its change list), const StaticMesh, const MobileMesh (and
 *          its change list),
 *          const PathFollower, const Transform, const Name (at the first shot),
 *          const Mesh, const Material (and its change list), const PointLight,
 *          const SpotLight, const DirectionalLight, ctx<const RayScene> (synced this frame)
 *  Writes: ctx<PhotonStore>, ctx<PhotonDelta>, ctx<PhotonPathGrid> (created when missing)  */
class PhotonUpdateSystem {
public:
    /// What the last update did.
    struct FrameStats {
        bool full = false;
        std::size_t movedMobiles = 0;
        std::size_t editedSurfaces = 0; ///< whose albedo changed: their paths re-traced
        std::size_t repaintedPaths = 0; ///< of the re-traced, those first affected by an edit
        std::size_t candidatePaths = 0; ///< from the grid or near paths, before the exact test
        std::size_t nearPathsMade = 0;  ///< moved mobiles whose near paths were made anew
        std::size_t nearPathsWalked = 0; ///< grid candidates walked to make them
        std::size_t retracedPaths = 0;  ///< re-traced because a mobile moved or an albedo changed
        std::size_t landedPaths = 0;    ///< kept: every affected segment landed where it did
        std::size_t retestedSegments = 0; ///< segments tested again: did they land?
        std::size_t reshotPaths = 0;    ///< re-shot because their light changed
        std::size_t addedPaths = 0;     ///< appended to the store (lights added, shares dealt anew)
        std::size_t redealtLights = 0;  ///< lights given new photons: 4x off their share
        std::size_t tracedSegments = 0;
        std::size_t reindexedPaths = 0; ///< by the path grid's refresh
        bool compacted = false;         ///< the whole store laid out again
        std::size_t compactedRegions = 0; ///< store regions compacted (PhotonStoreSpace)
        // Wall-clock milliseconds of the frame's stages (for the profile and benchmarks).
        double findMs = 0;  ///< candidate paths from the grid, exact segment tests
        double traceMs = 0; ///< re-tracing suffixes, writing the store and the delta
        double gridMs = 0;  ///< marking changed paths, refreshing chunks, compaction
    };

    /// Throws qgi::Error on absurd settings (validatePhotonSettings).
    explicit PhotonUpdateSystem(const PhotonSettings& settings);

    void update(Registry& registry, const FrameContext& frame);

    const PhotonSettings& settings() const { return mSettings; }
    const FrameStats& lastFrame() const { return mStats; }

    /// One light's photons as the system holds them (for tools and tests): its range of the
    /// store's paths, the photons left to re-shoot since it last changed, and whether it is
    /// absent (no source lists it) or a ghost (holding a light's former photons).
    struct LightPhotons {
        std::uint32_t first = 0, count = 0, remaining = 0;
        bool absent = false, ghost = false;
    };
    /// Per light, in the order of PhotonStore::lights.
    std::vector<LightPhotons> lightPhotons() const;

private:
    struct Mobile {
        Entity entity;
        Aabb objectBounds;
        glm::mat4 pose{1.f}; ///< the pose the stored paths were traced against
        bool active = true;  ///< whether they were traced with it in the scene
        std::vector<glm::vec3> facetNormals; ///< unit, object space, per triangle (0: degenerate)
        bool warnedOutside = false;          ///< named once for leaving the directional lights' box
        /// Triangles a and b lie in one plane facing the same way (a == b included).
        bool sameFacet(std::uint32_t a, std::uint32_t b) const;
    };
    /// A landed segment's record moved to the neighbouring triangle it now lands on.
    struct Relabel {
        std::size_t segment = 0;
        std::uint32_t primitive = 0;
        std::uint32_t path = 0, k = 0; ///< the segment as (path, k), for PhotonDelta::relabels
    };
    struct MovedMobile {
        Entity entity;
        glm::mat4 pose{1.f};     ///< new pose
        glm::mat4 toObject{1.f}; ///< its inverse
        /// Object-space normals to world space (not normalised: only signs and ratios count).
        glm::mat3 normalMatrix{1.f};
        glm::vec3 shift{0.f};    ///< new minus old translation
        Aabb objectBox;          ///< object-space bounds, slightly widened
        /// World bounds at the old and new pose, slightly widened; empty where the mobile was
        /// or is inactive.
        Aabb oldBox, newBox;
        /// The mobile, when the linear part of its pose is unchanged (it only translated) and
        /// it is active at both poses; null otherwise. Points into mMobiles, which does not
        /// change between full shots.
        const Mobile* translated = nullptr;
        bool active = true; ///< in the scene at its new pose (the crossing test applies)
        /// The world segment origin + t direction, t in [0, length], in object space (an
        /// affine map keeps t).
        Ray toLocal(const glm::vec3& origin, const glm::vec3& direction, float length) const {
            return {glm::vec3(toObject * glm::vec4(origin, 1.f)), 0.f,
                    glm::mat3(toObject) * direction, length};
        }
    };
    struct Sweep {
        std::uint32_t remaining = 0; ///< photons left to re-shoot since the light last changed
        std::uint32_t cursor = 0;    ///< next photon, relative to the light's first
    };
    /// A path to re-trace from segment k on; k = 0 with `emit` re-shoots it from its light.
    struct Job {
        std::uint32_t path = 0;
        std::uint32_t k = 0;
        bool emit = false;
    };

    /// Compares this frame's light sources with those shot (matched by kind and entity);
    /// prepares changed and added lights, marks removed ones absent, starts their sweeps and
    /// gives photons to lights without (addPhotons) and new ones to lights far off their
    /// shares (redealDrifted). True when a full shot is due: a stand-in changed what hybrid
    /// mode counts, or lights found no room.
    bool detectLightChanges(const Registry& registry, PhotonStore& store, PhotonPathGrid& grid);
    /// Gives photons to every shining light that has none, at the lit lights' power per
    /// photon (takeRange); false when one would get under 1/kShareDrift of its share for want
    /// of room (a full shot is due).
    bool addPhotons(PhotonStore& store);
    /// When a shining light's photon count is more than kShareDrift times above or below its
    /// exact share (of the lit lights' photons, at least photonCount; a share of one photon or
    /// more), it and every light kRedealAlong times off hand their photons to ghosts (retire)
    /// and take ranges of their shares. False when there is no room (a full shot is due).
    bool redealDrifted(PhotonStore& store);
    /// Photon ranges. A *free* range belongs to an absent light (removed, or a ghost) whose
    /// photons are all re-shot empty: its paths hold nothing and it can be handed on.
    /// mergeFreeRanges lists them in mFree, neighbours merged into one.
    void mergeFreeRanges(PhotonStore& store);
    /// The most photons, up to `count`, that takeRange can give one light: the largest free
    /// range, or what the store may still grow by (to kMaxPhotonGrowth times photonCount; a
    /// path that holds nothing costs 8 bytes and a few bits in the path grid).
    std::uint32_t roomFor(const PhotonStore& store, std::uint32_t count) const;
    /// Gives light `owner` (which has none) `count` photons, all empty paths, and starts its
    /// sweep: the smallest free range that holds them, else appended. count <= roomFor.
    void takeRange(PhotonStore& store, std::size_t owner, std::uint32_t count);
    /// Light l (which has none) takes its `share` (>= 1) of photons, or what room there is down
    /// to a quarter of it (the drift redealDrifted tolerates); false when there is less.
    bool takeShare(PhotonStore& store, std::size_t l, std::uint32_t share);
    /// Hands light l's photons to a ghost, which re-shoots them empty within the budget (the
    /// light's old light fades while its new photons are shot); false when no emitter slot is
    /// left (kMaxLights).
    bool retire(PhotonStore& store, std::size_t l);
    void setRange(PhotonStore& store, std::size_t l, std::uint32_t first, std::uint32_t count);
    /// Photons [first, first + count) now belong to emitter `owner` (PhotonPath::light).
    static void handOver(PhotonStore& store, std::uint32_t first, std::uint32_t count,
                         std::size_t owner);
    /// The index of the light shot from `source` (same kind and entity), or -1.
    std::int64_t emitterOf(const PhotonEmitter& source) const;
    void indexEmitters();
    std::uint64_t mStandIns = 0;      ///< standInSignature at the last check
    /// Surfaces whose albedo changed since they were traced (a patched Material): mEdits, with
    /// mAlbedo brought up to date.
    void findAlbedoEdits(const Registry& registry);
    bool edited(Entity e) const {
        return e.index < mEditedByIndex.size() && mEditedByIndex[e.index] == e;
    }
    void shootAll(const Registry& registry, const RayScene& scene, PhotonStore& store,
                  PhotonPathGrid& grid);
    void captureScene(const Registry& registry, const RayScene& scene);
    void findMovedMobiles(const Registry& registry, const RayScene& scene, PhotonDelta& delta);
    void scheduleReshoots();
    void findAffectedPaths(const RayScene& scene, const PhotonStore& store,
                           const PhotonPathGrid& grid);
    /// mCandidates from the moved mobiles' near paths (made anew from the grid where a mobile
    /// left its box).
    void candidatesNearMobiles(const PhotonStore& store, const PhotonPathGrid& grid);
    /// After the frame's re-trace: each mobile's near paths take the re-traced paths whose new
    /// segments meet their box; those of mobiles still for kNearIdleFrames are dropped.
    void updateNearPaths(const PhotonDelta& delta);
    /// The first segment k >= from of path p that hit a moved mobile at its old pose or
    /// crosses one at its new pose; -1 when there is none.
    std::int32_t nextAffected(const RayScene& scene, const PhotonStore& store, std::uint32_t p,
                              std::uint32_t from) const;
    /// What one thread's landing tests produce: triangles to relabel, and counts.
    struct LandingScratch {
        std::vector<Relabel> relabels;
        std::size_t kept = 0;    ///< paths every affected segment of which landed as recorded
        std::size_t checked = 0; ///< segments tested again
    };
    /// The segment path p is re-traced from, -1 for none: its first affected segment
    /// (nextAffected), or with reuseLandedPaths, the first affected one that does not land as
    /// recorded. Each affected segment that hit a mobile which only translated is tested again
    /// against the moved mobiles alone; while one lands as recorded, the path's next affected
    /// segment is taken. Done in the same walk as nextAffected, while the path is in cache.
    std::int32_t firstToRetrace(const RayScene& scene, const PhotonStore& store, std::uint32_t p,
                                float tolerance, LandingScratch& scratch) const;
    /// The moved mobile that segment s hit, when that mobile only translated and the plane of
    /// the triangle hit slid along the segment by no more than a few times `tolerance`; null
    /// when the segment cannot land as recorded.
    const MovedMobile* mayLand(const PhotonSegments& segments, std::size_t s,
                               float tolerance) const;
    /// Whether segment s, which hit `mobile` at its old pose, lands as recorded at the new
    /// one; the triangle it now hits goes to `primitive`.
    bool lands(const RayScene& scene, const PhotonSegments& segments, std::size_t s,
               const MovedMobile& mobile, float tolerance, std::uint32_t& primitive) const;
    void retrace(const RayScene& scene, PhotonStore& store, PhotonDelta& delta);
    /// Whether a directional light has photons in the store.
    bool litByDirectionalLight() const;
    PhotonTracer::Surfaces surfaces() const;

    PhotonSettings mSettings;
    PhotonTracer mTracer;
    bool mShot = false;
    bool mLoggedShot = false; ///< the first shot's size was logged
    Aabb mSceneBox;           ///< every mesh in the world at the first shot: the path grid's box
    Aabb mDirectionalBox; ///< what directional lights cover (PhotonSettings::directionalBounds)
    std::vector<PhotonEmitter> mEmitters; ///< as shot; index = PhotonPath::light
    /// mEmitters by kind and entity.
    std::map<std::pair<EmitterKind, Entity>, std::uint32_t> mEmitterIndex;
    std::vector<Sweep> mSweeps;           ///< per emitter
    std::vector<glm::vec3> mAlbedo;       ///< by Entity::index, as shot
    std::vector<Mobile> mMobiles;
    std::unordered_map<Entity, std::size_t> mMobileIndex;
    PhotonStoreSpace mSpace;
    FrameStats mStats;

    // Per-frame working memory, kept to reuse its capacity.
    std::vector<PhotonEmitter> mSources;
    std::vector<std::int64_t> mSourceOf; ///< per emitter: its source this frame, or -1
    std::vector<std::size_t> mAdded;     ///< sources with no emitter yet
    std::vector<std::size_t> mFree;      ///< emitters holding free ranges (mergeFreeRanges)
    std::vector<std::pair<std::size_t, std::uint32_t>> mDrifted; ///< light and its share
    std::vector<MovedMobile> mMoved;
    /// A moving mobile's near paths: every path with a segment that met `box` when they were
    /// made from the grid, and every path re-traced since whose new segments meet it, in
    /// increasing order. A superset of the paths that meet the box now: while the mobile's old
    /// and new boxes stay inside it, its candidates need no grid query, and fewer of them are
    /// read than the grid's cells hand out (PhotonSettings::nearPathMargin).
    struct NearPaths {
        Aabb box;
        std::vector<std::uint32_t> paths;
        std::size_t made = 0;   ///< paths held when made from the grid
        std::uint32_t idle = 0; ///< frames since its mobile last moved
        bool worth = true;      ///< false: its mobile queries the grid (kNearPathsPerGridPath)
        std::uint32_t retryIn = 0; ///< while not worth: moves until near paths are tried again
    };
    std::unordered_map<Entity, NearPaths> mNearPaths;
    std::vector<std::uint32_t> mNearScratch, mNearAdded;
    std::vector<std::uint8_t> mNearMeets;
    /// A surface whose albedo was edited this frame, and its world bounds, slightly widened.
    struct AlbedoEdit {
        Entity entity;
        Aabb box;
    };
    std::vector<AlbedoEdit> mEdits;
    std::vector<Entity> mEditedByIndex; ///< by Entity::index: the entity when edited this frame
    std::unordered_map<Entity, Aabb> mStaticBoxes; ///< world bounds of each static, widened
    std::vector<Aabb> mQueryBoxes;
    std::vector<std::uint32_t> mCandidates;
    std::vector<std::int32_t> mFirstAffected;
    std::vector<Relabel> mRelabels;
    tbb::enumerable_thread_specific<LandingScratch> mLandingScratch;
    std::vector<Job> mJobs;
    std::vector<std::uint32_t> mEnds;
    std::vector<std::uint64_t> mWrite;      ///< per job: where its path goes in the store
    std::vector<std::uint64_t> mReshooting; ///< one bit per path: re-shot this frame
};

} // namespace qgi
