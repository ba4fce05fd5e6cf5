#pragma once

#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"
#include "systems/detp/CompensatedSum.h"
#include "systems/detp/DetpSettings.h"
#include "systems/detp/DiscCrossing.h"
#include "systems/detp/DiscIndex.h"
#include "systems/detp/ImpactCounter.h"
#include "systems/detp/NearSegments.h"
#include "systems/detp/PhotonKdTree.h"
#include "systems/detp/ReceiverSet.h"
#include "systems/photon_update/PhotonStore.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace qgi {

struct PhotonDelta;
struct PhotonStore;
struct PhotonSegments;

/** Per-vertex irradiance of every StaticMesh and MobileMesh from the photon ray set
 *  (seed 000 sections 2.4-2.7).
 *
 *  DETP (the default estimator): E(v) = sum of the power of the segments that cross the disc
 *  of radius r on v's tangent plane from the front (crossesDisc(), segments that left the
 *  scene included) / (pi r^2). It is additive per segment, so:
 *   - when the ray set was rebuilt (PhotonDelta::full, or the first frame) every vertex is
 *     estimated in full;
 *   - otherwise static vertices, and those of mobiles that did not move, take
 *     E += E(new segments) - E(old segments): only the delta goes through the disc indices,
 *     and a vertex whose disc no delta segment crosses is not written (bit-identical). A
 *     re-traced path's old and new heads are one ray stopped at two lengths (a mobile moved
 *     into or out of its way); the crossings they share cancel exactly, so only the longer
 *     head is traced, beyond the shorter one's end;
 *   - the vertices of a mobile that moved (its WorldTransform changed, or it is in
 *     PhotonDelta::movedMobiles) are re-estimated in full at the new pose from the segments of
 *     the paths the PhotonPathGrid finds near the mobile, so the whole ray set is never
 *     scanned. Without a PhotonPathGrid resource that indexes the current ray set (none is
 *     built with PhotonSettings::fullRecompute) every stored path is a candidate. A mobile
 *     keeps a copy of the segments near it (NearSegments, over a box a margin wider than its
 *     reach) while that costs less to keep up than the walk over the paths costs
 *     (kNearCopiesPerWalkedPath): the moves that stay inside the box read the copy, which each
 *     delta updates, and neither query the grid nor walk the store;
 *   - a mobile taken out of the light (MobileMesh::active) holds zero until it is put back,
 *     which re-estimates it like a move. The same holds for the comparison estimators.
 *  A segment that starts on a convex mobile (ReceiverSet::Receiver::convex) is not traced
 *  through that mobile's discs, in full estimates and deltas alike: it cannot cross one from the
 *  front, save from an origin lifted a hair off the surface or lying on a disc's plane, and
 *  such a crossing is light leaving the surface, not arriving.
 *  Sums are kept per vertex in double precision and applied in a fixed order (DiscIndex), so
 *  the same frames give bit-identical irradiance on any thread count.
 *
 *  Drift policy: a vertex's power sum S carries its own rounding error (CompensatedSum), so
 *  after n additions of at most p W a channel it is within 2^-53 |S| + n^3 2^-106 p of the
 *  exact sum, in full estimates and incremental updates alike. Once any vertex has taken
 *  maxIncrementalUpdates additions since its last full estimate (default 2^30: within
 *  2^-53 |S| plus a sixty-five-thousandth of the largest segment power it added) the next frame
 *  re-estimates everything: one frame that costs a full estimate. The cornell box's busiest
 *  vertex takes about 450 additions a frame while its block moves every frame (1M photons), so
 *  that is once in 2.4 million frames, eleven hours at 60 fps. (With plain double sums the bound
 *  was (n - 1) 2^-53 times the sum of every term added, and a re-estimate came every 2^24
 *  additions, ten minutes of that play.)

 *  The comparison estimators (settings.estimator):
 *   - impact count (ImpactCounter): additive per triangle, so it is updated from the delta
 *     alone, static and mobile triangles alike (the seed's Add/Subtract);
 *   - photon map (PhotonKdTree, Jensen's k-nearest estimate): not additive (the radius
 *     depends on the whole set), so any change to the ray set rebuilds the tree from every
 *     stored hit and re-estimates every vertex; a mobile that moved without changing the
 *     ray set is re-estimated alone. That full cost every frame is the point of comparing.
 *  Hybrid mode skips the segments that leave a light the renderer draws (bounce 0 of a path
 *  whose PhotonLight::directDrawn is set: punctual lights, and emissive surfaces with a
 *  LightStandIn) in all three. Other emissive surfaces' first segments still count, so an
 *  area light's direct light (which the renderer cannot draw) comes from photons in both
 *  modes.
 *
 *  Reads:  ctx<const PhotonStore>, ctx<const PhotonDelta>, ctx<const PhotonPathGrid> (when
 *          present), const WorldTransform and const MobileMesh (and their change lists),
 *          ctx<const RayScene> (which mobiles are active, when present);
 *          build(): also const StaticMesh, const Mesh, const Name, ctx<RayScene> (its device),
 *          ctx<const SceneInfo> (default radius)
 *  Writes: VertexIrradiance (irradiance and dirty ranges; emplaced by build())          */
class DetpIrradianceSystem {
public:
    /// What the last update() did, for profiling and tests.
    struct FrameStats {
        bool full = false;                 ///< every vertex was estimated from scratch
        std::size_t deltaSegments = 0;     ///< old + new segments traced incrementally
        std::size_t movedMobiles = 0;      ///< mobiles re-estimated in full
        std::size_t mobilesWalked = 0;     ///< of them, those that walked the paths near them
        std::size_t candidatePaths = 0;    ///< paths those walks read (PhotonPathGrid)
        std::size_t nearSegments = 0;      ///< segments in the others' copies, scanned
        std::size_t candidateSegments = 0; ///< of them, those that reach the mobile, traced
        std::size_t crossings = 0;         ///< (segment, disc) pairs applied
        std::size_t verticesWritten = 0;
        double deltaMs = 0;  ///< wall-clock: the delta applied to static and unmoved vertices
        double mobileMs = 0; ///< wall-clock: moved mobiles re-estimated in full
    };

    /// Throws qgi::Error for settings out of range (see validate()).
    explicit DetpIrradianceSystem(const DetpSettings& settings);
    DetpIrradianceSystem(const DetpIrradianceSystem&) = delete;
    DetpIrradianceSystem& operator=(const DetpIrradianceSystem&) = delete;
    ~DetpIrradianceSystem();

    /// Set-up, once the scene, its WorldTransforms and the RayScene exist: reads the meshes,
    /// resolves the disc radius and builds the disc indices. Throws qgi::Error on a mesh it
    /// cannot use or a missing resource. (Meshes added or removed later need the photon ray set
    /// rebuilt too: see PhotonUpdateSystem.)
    void build(Registry& registry);

    /// The frame: applies this frame's PhotonDelta (nothing to do while there is no
    /// PhotonStore/PhotonDelta). Each delta is applied once (PhotonDeltaReader); after a
    /// missed one every vertex is re-estimated. Never throws.
    void update(Registry& registry, const FrameContext& frame);

    const DetpSettings& settings() const { return mSettings; }
    /// The disc radius r in use, metres (after build()).
    float discRadius() const { return mRadius; }
    const FrameStats& lastFrame() const { return mStats; }

private:
    /// The mobiles whose pose or MobileMesh::active changed (mMoved); keeps mActive.
    void collectMovedMobiles(const Registry& registry, const PhotonDelta& delta);
    /// Whether `mobile` is in the light: the RayScene's view when it holds the mobile (the
    /// photons were traced against it), else MobileMesh::active.
    static bool mobileActive(const Registry& registry, Entity mobile);
    /// Zeroes a receiver's sums and irradiance.
    void clearReceiver(std::uint32_t receiver);
    Aabb discBounds(std::uint32_t receiver) const;
    /// The entity whose leaving segments the receiver's discs skip: itself when it is a convex
    /// mobile (ReceiverSet::Receiver::convex: they cannot cross its discs from the front), else
    /// null.
    Entity leavingSkippedFrom(std::uint32_t receiver) const;
    /// Whether a segment that starts on `from` is skipped by the discs of the receiver whose
    /// leavingSkippedFrom() is `skipped`.
    static bool skipsLeaving(Entity from, Entity skipped) {
        return !skipped.isNull() && from == skipped;
    }
    float crossingTail() const;

    void updateDetp(Registry& registry, const PhotonStore& store, const PhotonDelta& delta,
                    bool full);
    void splitDelta(const PhotonStore& store, const PhotonDelta& delta);
    /// Whether the first segments of `light`'s paths count: not in hybrid mode when the
    /// renderer draws the light (PhotonLight::directDrawn).
    bool countsFirst(std::uint16_t light) const;
    /// Whether segment s of a path from `light` counts: not in hybrid mode when it is a
    /// first segment of a light the renderer draws (PhotonLight::directDrawn).
    bool counted(const PhotonSegments& segments, std::size_t s, std::uint16_t light) const;
    /// Every live segment of the store that counts, path by path (re-traced paths leave
    /// garbage behind in the segment array).
    void listCountedSegments(const PhotonStore& store, std::vector<std::uint32_t>& out) const;
    void accumulateDiscs(DiscIndex& discs, std::uint32_t firstVertex, SegmentRays segments,
                         Strided<glm::vec3> power, std::span<const std::uint32_t> indices,
                         std::span<const float> beyond, double sign, bool incremental);
    /// The box a mobile's new copy of the segments near it covers: its discs' reach `reach`,
    /// widened by DetpSettings::nearSegmentMargin (or more when it moves fast).
    Aabb nearBox(std::uint32_t receiver, const Aabb& reach) const;
    /// Walks the paths near the mobiles mWalked, over mMobileBoxes: one path-grid query and one
    /// walk for all of them (a path near several mobiles is read once). Each takes a new copy
    /// of the segments near it (mWalkCopies) or its segments' store indices (mDirect), and
    /// learns whether a copy is worth keeping (mCopyWorthIt).
    void walkNear(const Registry& registry, const PhotonStore& store);
    /// Brings every mobile's copy up to date with the delta (after splitDelta), and drops the
    /// copies of mobiles that moved out of them or have been still for kNearIdleFrames.
    void updateNear(const PhotonDelta& delta);
    /// Re-estimates the listed mobile receivers in full against the current ray set; inactive
    /// ones are zeroed. `full`: part of a full estimate (no copies made).
    void estimateMobiles(const Registry& registry, const PhotonStore& store,
                         std::span<const std::uint32_t> requested, bool full);
    void updateImpacts(Registry& registry, const PhotonStore& store, const PhotonDelta& delta,
                       bool full);
    void updatePhotonMap(Registry& registry, const PhotonStore& store, const PhotonDelta& delta,
                         bool full);
    void estimatePhotonMap(std::uint32_t firstVertex, std::uint32_t count);
    void publishAll(Registry& registry);

    DetpSettings mSettings;
    float mRadius = 0.f;
    float mPhotonMapRadius = 0.f;
    bool mBuilt = false;
    bool mNeedsFull = true;
    PhotonDeltaReader mDeltaReader;
    FrameStats mStats;

    ReceiverSet mReceivers;
    std::unique_ptr<DiscIndex> mStaticDiscs;
    std::vector<std::unique_ptr<DiscIndex>> mMobileDiscs; ///< per receiver; null for static
    std::vector<CompensatedSum> mPowerSum;                ///< DETP: W crossing each vertex's disc
    std::vector<std::uint32_t> mUpdateCount; ///< DETP: additions since the last full estimate
    std::vector<glm::vec3> mIrradiance;      ///< W/m^2 per vertex, staged for publishing
    ImpactCounter mImpacts;
    PhotonKdTree mPhotonMap;

    /// What the incremental update applies: the old segments with sign -1, the new with +1;
    /// each listed segment counts beyond a length (-inf: whole; see splitDelta).
    struct DeltaPart {
        const PhotonSegments* segments = nullptr;
        double sign = 1.0;
        std::vector<std::uint32_t> indices;
        std::vector<float> beyond;
        std::vector<Entity> from; ///< per listed segment: what its origin lies on (or null)
    };

    // Frame scratch, kept so the frame path does not allocate once warm.
    DeltaPart mDeltaParts[2] = {{nullptr, -1.0, {}, {}, {}}, {nullptr, 1.0, {}, {}, {}}};
    std::vector<float> mBeyondList;
    std::vector<Entity> mPrefixEnd;        ///< splitDelta: per delta path, where its suffix starts
    std::vector<std::uint16_t> mPathLight; ///< splitDelta: per delta path, its light
    std::vector<std::uint32_t> mMoved;  ///< receiver indices of mobiles that moved
    std::vector<std::uint8_t> mIsMoved; ///< per receiver
    /// Per receiver: in the light (static meshes always; mobiles per MobileMesh::active as the
    /// RayScene holds it). An inactive mobile's vertices hold zero and are not estimated.
    std::vector<std::uint8_t> mActive;
    std::vector<std::uint32_t> mEstimated;  ///< estimateMobiles: the active ones it was given
    std::vector<std::uint8_t> mSkipsDirect; ///< per store light: its first segments do not count
    std::vector<std::uint32_t> mSegmentList;
    std::vector<std::uint32_t> mCandidatePaths;
    std::vector<std::uint32_t> mAllPaths; ///< 0, 1, ...: the candidates without a path grid
    /// Per receiver: the stored segments near a mobile that moved lately (NearSegments), the
    /// reach of its discs when it was last estimated, and the frames it has been still since.
    std::vector<NearSegments> mNear;
    std::vector<Aabb> mLastReach;
    std::vector<std::uint32_t> mNearIdle;
    std::vector<std::uint8_t> mCopyWorthIt; ///< per receiver: keep a copy (learnt by walks)
    NearSegments mNearScratch;
    DeltaByPath mDeltaByPath;
    // walkNear: per mobile walked, its receiver, whether it takes a copy, its box, what its
    // segments may not start on, and its store indices when it takes no copy.
    std::vector<std::uint32_t> mWalked;
    std::vector<std::uint8_t> mWalkCopies;
    std::vector<Aabb> mMobileBoxes;
    std::vector<Entity> mLeavesFrom;
    std::vector<std::vector<std::uint32_t>> mDirect;
    std::vector<std::vector<NearSegments::Pick>> mChunkLists; ///< walkNear: per task and mobile
    std::vector<NearSegments::Pick> mPicks;
    std::vector<std::uint32_t> mOwnCandidates;           ///< walkNear: one mobile's, for its worth
    std::vector<std::uint32_t> mAllMobiles;              ///< receiver indices, full estimates
    std::vector<DiscCrossing> mCrossings;
    std::vector<std::uint32_t> mTouched;
    std::vector<std::uint8_t> mIsTouched; ///< per vertex
};

} // namespace qgi
