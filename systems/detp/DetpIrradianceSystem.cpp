#include "systems/detp/DetpIrradianceSystem.h"

#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/profile/StageTimer.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneQueries.h"
#include "systems/photon_update/PhotonPathGrid.h"
#include "systems/photon_update/PhotonStore.h"

#include <glm/gtc/constants.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>

namespace qgi {
namespace {

/// Segments handed to a disc index at once: bounds the index's scratch during a full estimate.
constexpr std::size_t kBatchSize = std::size_t(1) << 16;
/// Vertices per task of the photon-map estimate.
constexpr std::size_t kVertexGrain = 256;
/// Candidate paths per task when listing the segments that reach a moved mobile's discs.
constexpr std::size_t kPathGrain = 2048;

/// The float a vertex publishes for a sum of signed additions: incremental updates that
/// cancel exactly can leave a rounding error below zero, and irradiance is never negative.
glm::vec3 published(const glm::dvec3& irradiance) {
    return glm::vec3(glm::max(irradiance, glm::dvec3(0.0)));
}

} // namespace

DetpIrradianceSystem::DetpIrradianceSystem(const DetpSettings& settings) : mSettings(settings) {
    validate(settings);
}

DetpIrradianceSystem::~DetpIrradianceSystem() = default;

void DetpIrradianceSystem::build(Registry& registry) {
    RayScene* rayScene = registry.ctx().find<RayScene>();
    if (!rayScene) fail("DETP: the registry has no RayScene (its Embree device hosts the discs)");

    ReceiverSet receivers;
    receivers.build(registry);
    double area = 0.0; // m^2 of every receiver's triangles
    for (const float a : receivers.triangleAreas())
        area += double(a);
    const SceneInfo* info = registry.ctx().find<SceneInfo>();
    float radius = mSettings.discRadius;
    if (radius == 0.f) {
        if (!info)
            fail("DETP: DetpSettings.discRadius is 0 (scene default) but the registry has no "
                 "SceneInfo to scale it from");
        radius = defaultDiscRadius(*info, area, mSettings.photonCount);
        // The default widens with the mesh edge bound and as photons get scarce: past a tenth
        // of the scene it blurs the light over whole walls and reads low near their edges.
        const float diagonal = info->bounds.empty() ? 0.f : glm::length(info->bounds.extent());
        if (mSettings.estimator == IrradianceEstimator::Detp && diagonal > 0.f &&
            radius > kMaxDefaultRadiusShare * diagonal)
            logWarning("DETP: the default disc radius, ", radius, " m, is ",
                       std::lround(100.f * radius / diagonal), "% of the scene (", diagonal,
                       " m across) for ", mSettings.photonCount,
                       " photons and a mesh edge bound of ", info->maxEdgeLength,
                       " m: irradiance is blurred over that and reads low near edges; shoot more "
                       "photons (--photons), refine the meshes (--max-edge) or set the radius "
                       "(--disc-radius)");
    } else {
        if (info && !info->bounds.empty() && radius > glm::length(info->bounds.extent()))
            fail("DETP: DetpSettings.discRadius = ", radius, " m is wider than the whole scene (",
                 glm::length(info->bounds.extent()),
                 " m across): every disc would average all of it");
        // Photons spread evenly over every surface would land this often in a disc; the default
        // radius aims at kDefaultDiscLandings.
        const double landings = double(mSettings.photonCount) * glm::pi<double>() * double(radius) *
                                double(radius) / area;
        if (mSettings.estimator == IrradianceEstimator::Detp && mSettings.photonCount > 0 &&
            area > 0.0 && landings < kFewDiscLandings)
            logWarning("DETP: a disc radius of ", radius, " m catches about ", landings,
                       " photon landings per disc (", mSettings.photonCount, " photons over ", area,
                       " m^2; the default radius aims at ", kDefaultDiscLandings,
                       "): the vertices read a Poisson count of that mean, many of them 0; "
                       "widen the radius or shoot more photons");
    }
    auto staticDiscs = std::make_unique<DiscIndex>(rayScene->device(), DiscIndex::Motion::Static);
    const std::uint32_t staticCount = receivers.staticVertexCount();
    staticDiscs->build(receivers.positions().first(staticCount),
                       receivers.normals().first(staticCount), radius);
    std::vector<std::unique_ptr<DiscIndex>> mobileDiscs(receivers.receivers().size());
    for (std::size_t r = 0; r < mobileDiscs.size(); ++r) {
        const auto& receiver = receivers.receivers()[r];
        if (!receiver.mobile) continue;
        mobileDiscs[r] = std::make_unique<DiscIndex>(rayScene->device(), DiscIndex::Motion::Moving);
        mobileDiscs[r]->build(
            receivers.positions().subspan(receiver.firstVertex, receiver.vertexCount),
            receivers.normals().subspan(receiver.firstVertex, receiver.vertexCount), radius);
    }

    mRadius = radius;
    mPhotonMapRadius = mSettings.photonMapMaxRadius > 0.f ? mSettings.photonMapMaxRadius
                                                          : kPhotonMapRadiusPerDisc * radius;
    mReceivers = std::move(receivers);
    mStaticDiscs = std::move(staticDiscs);
    mMobileDiscs = std::move(mobileDiscs);
    const std::size_t vertices = mReceivers.vertexCount();
    mPowerSum.assign(vertices, CompensatedSum{});
    mUpdateCount.assign(vertices, 0);
    mIrradiance.assign(vertices, glm::vec3(0.f));
    mIsTouched.assign(vertices, 0);
    mIsMoved.assign(mReceivers.receivers().size(), 0);
    mActive.assign(mReceivers.receivers().size(), 1);
    mNear.assign(mReceivers.receivers().size(), NearSegments{});
    mLastReach.assign(mReceivers.receivers().size(), Aabb{});
    mNearIdle.assign(mReceivers.receivers().size(), 0);
    mCopyWorthIt.assign(mReceivers.receivers().size(), 1);
    for (std::size_t r = 0; r < mActive.size(); ++r) {
        const auto& receiver = mReceivers.receivers()[r];
        if (receiver.mobile) mActive[r] = mobileActive(registry, receiver.entity);
    }
    mBuilt = true;
    mNeedsFull = true;
    std::size_t mobiles = 0, convex = 0;
    for (const auto& receiver : mReceivers.receivers()) {
        mobiles += receiver.mobile ? 1 : 0;
        convex += receiver.convex ? 1 : 0;
    }
    const std::string estimatorRadius =
        mSettings.estimator == IrradianceEstimator::Detp ? str("disc radius ", mRadius, " m")
        : mSettings.estimator == IrradianceEstimator::PhotonMap
            ? str(mSettings.photonMapNeighbours, " nearest hits within ", mPhotonMapRadius, " m")
            : std::string("per triangle");
    logInfo("DETP: ", irradianceEstimatorName(mSettings.estimator), " over ", vertices,
            " vertices (", staticCount, " static) in ", mReceivers.receivers().size(), " meshes (",
            mobiles, " mobile, ", convex, " of them convex), ", estimatorRadius,
            mSettings.hybrid ? ", hybrid" : "");
}

void DetpIrradianceSystem::update(Registry& registry, const FrameContext&) {
    QGI_ASSERT(mBuilt, "DetpIrradianceSystem::build must run before update");
    mStats = {};
    const PhotonStore* store = registry.ctx().find<PhotonStore>();
    const PhotonDelta* delta = registry.ctx().find<PhotonDelta>();
    if (!store || !delta) return;
    mSkipsDirect.assign(store->lights.size(), 0);
    for (std::size_t l = 0; l < store->lights.size(); ++l)
        mSkipsDirect[l] = mSettings.hybrid && store->lights[l].directDrawn;
    // A delta applied twice (the photon update skipped a frame) would count its change twice;
    // one missed (DETP skipped a frame) would leave it out: apply each once, re-estimate in
    // full after a gap. Hand-made deltas (sequence 0) are always new.
    static const PhotonDelta kNothingNew;
    const PhotonDeltaReader::News news = mDeltaReader.read(*delta);
    const bool gap = news == PhotonDeltaReader::News::AfterGap;
    if (news == PhotonDeltaReader::News::Repeated) delta = &kNothingNew;
    collectMovedMobiles(registry, *delta);
    const bool full = delta->full || mNeedsFull || gap;
    mNeedsFull = false;
    switch (mSettings.estimator) {
    case IrradianceEstimator::Detp:
        updateDetp(registry, *store, *delta, full);
        break;
    case IrradianceEstimator::ImpactCount:
        updateImpacts(registry, *store, *delta, full);
        break;
    case IrradianceEstimator::PhotonMap:
        updatePhotonMap(registry, *store, *delta, full);
        break;
    }
    mStats.full = full;
}

bool DetpIrradianceSystem::mobileActive(const Registry& registry, Entity mobile) {
    // The ray scene's view, which the photons were traced against, when it has the mobile.
    if (const RayScene* scene = registry.ctx().find<RayScene>(); scene && scene->isMobile(mobile))
        return scene->mobileActive(mobile);
    return !outOfWorld(registry, mobile);
}

void DetpIrradianceSystem::collectMovedMobiles(const Registry& registry, const PhotonDelta& delta) {
    for (const std::uint32_t r : mMoved)
        mIsMoved[r] = 0;
    mMoved.clear();
    // `posed`: the entity's pose may have changed; otherwise only its switch counts.
    const auto consider = [&](Entity e, bool posed) {
        const std::int64_t found = mReceivers.find(e);
        if (found < 0) return;
        const auto r = std::size_t(found);
        if (!mReceivers.receivers()[r].mobile || mIsMoved[r]) return;
        const bool active = mobileActive(registry, e);
        const bool switched = active != bool(mActive[r]);
        mActive[r] = active;
        if (!switched && !posed) return;
        // A pose the ray scene would refuse too: keep the mobile's light where it was.
        const bool placed = posed && mReceivers.refreshPose(registry, std::uint32_t(r));
        // Out of the world before and after: its zeros stand, wherever it went.
        if (!switched && (!placed || !active)) return;
        mIsMoved[r] = 1;
        mMoved.push_back(std::uint32_t(r));
    };
    for (const Entity e : registry.changed<WorldTransform>())
        consider(e, true);
    for (const Entity e : delta.movedMobiles)
        consider(e, true);
    for (const Entity e : registry.changed<MobileMesh>())
        consider(e, false);
    std::sort(mMoved.begin(), mMoved.end());
    if (mSettings.estimator != IrradianceEstimator::Detp) return;
    for (const std::uint32_t r : mMoved) {
        const auto& receiver = mReceivers.receivers()[r];
        mMobileDiscs[r]->move(
            mReceivers.positions().subspan(receiver.firstVertex, receiver.vertexCount),
            mReceivers.normals().subspan(receiver.firstVertex, receiver.vertexCount));
    }
}

bool DetpIrradianceSystem::countsFirst(std::uint16_t light) const {
    // A path naming a light the store does not list is treated as one the renderer draws.
    return !mSettings.hybrid || (light < mSkipsDirect.size() && !mSkipsDirect[light]);
}

bool DetpIrradianceSystem::counted(const PhotonSegments& segments, std::size_t s,
                                   std::uint16_t light) const {
    return segments.bounce[s] != 0 || countsFirst(light);
}

void DetpIrradianceSystem::listCountedSegments(const PhotonStore& store,
                                               std::vector<std::uint32_t>& out) const {
    out.clear();
    for (const PhotonPath& path : store.paths)
        for (std::uint32_t k = 0; k < path.count; ++k)
            if (counted(store.segments, path.first + k, path.light)) out.push_back(path.first + k);
}

// ---- DETP ---------------------------------------------------------------------------------

Entity DetpIrradianceSystem::leavingSkippedFrom(std::uint32_t receiver) const {
    const auto& r = mReceivers.receivers()[receiver];
    return r.mobile && r.convex ? r.entity : Entity{};
}

void DetpIrradianceSystem::accumulateDiscs(DiscIndex& discs, std::uint32_t firstVertex,
                                           SegmentRays segments, Strided<glm::vec3> power,
                                           std::span<const std::uint32_t> indices,
                                           std::span<const float> beyond, double sign,
                                           bool incremental) {
    for (std::size_t begin = 0; begin < indices.size(); begin += kBatchSize) {
        const std::size_t count = std::min(kBatchSize, indices.size() - begin);
        discs.collectCrossings(segments, indices.subspan(begin, count), mCrossings,
                               beyond.empty() ? beyond : beyond.subspan(begin, count));
        mStats.crossings += mCrossings.size();
        // A moved mobile's segments lie anywhere in the store: ask for a later crossing's
        // power ahead of use (this loop is serial, so each miss would be waited out).
        constexpr std::size_t kAhead = 16;
        for (std::size_t i = 0; i < mCrossings.size(); ++i) {
            if (i + kAhead < mCrossings.size())
                __builtin_prefetch(&power[mCrossings[i + kAhead].segment]);
            const DiscCrossing& c = mCrossings[i];
            const std::uint32_t v = firstVertex + c.disc;
            mPowerSum[v].add(sign * glm::dvec3(power[c.segment]));
            if (!incremental) continue;
            if (++mUpdateCount[v] >= mSettings.maxIncrementalUpdates) mNeedsFull = true;
            if (!mIsTouched[v]) {
                mIsTouched[v] = 1;
                mTouched.push_back(v);
            }
        }
    }
}

Aabb DetpIrradianceSystem::discBounds(std::uint32_t receiver) const {
    // A crossing point lies within r of a vertex (1% more covers rounding), and the segment
    // that crosses may end up to crossingTail() before it: the box reaches every such
    // segment's end, so that paths found by their segments' boxes (the path grid) include it.
    Aabb box = mReceivers.receivers()[receiver].bounds;
    const glm::vec3 reach(1.01f * mRadius + crossingTail());
    box.min -= reach;
    box.max += reach;
    return box;
}

float DetpIrradianceSystem::crossingTail() const {
    // How far past its end a segment may still cross a disc (crossesDisc), with DiscIndex's slack.
    return (kDiscEndTolerance + DiscIndex::kEmbreeSlack) * mRadius;
}

void DetpIrradianceSystem::clearReceiver(std::uint32_t receiver) {
    const auto& r = mReceivers.receivers()[receiver];
    const std::uint32_t first = r.firstVertex, end = first + r.vertexCount;
    std::fill(mPowerSum.begin() + first, mPowerSum.begin() + end, CompensatedSum{});
    std::fill(mUpdateCount.begin() + first, mUpdateCount.begin() + end, 0u);
    std::fill(mIrradiance.begin() + first, mIrradiance.begin() + end, glm::vec3(0.f));
}

void DetpIrradianceSystem::estimateMobiles(const Registry& registry, const PhotonStore& store,
                                           std::span<const std::uint32_t> requested, bool full) {
    mEstimated.clear();
    for (const std::uint32_t r : requested) {
        clearReceiver(r); // an inactive mobile stays so
        if (mActive[r]) mEstimated.push_back(r);
    }
    if (mEstimated.empty()) return;
    // Mobiles whose reach left their copy of the segments near them, or that keep none, walk
    // the paths near them: into a new copy, or straight into the sums.
    mWalked.clear();
    mWalkCopies.clear();
    mMobileBoxes.clear();
    for (const std::uint32_t r : mEstimated) {
        const Aabb reach = discBounds(r);
        if (mNear[r].covers(reach)) continue;
        // A full estimate makes no copies: the ray set changes whole at every one.
        const bool copy = !full && mCopyWorthIt[r] && mSettings.nearSegmentMargin > 0.f;
        mWalked.push_back(r);
        mWalkCopies.push_back(copy);
        mMobileBoxes.push_back(copy ? nearBox(r, reach) : reach);
    }
    if (!mWalked.empty()) walkNear(registry, store);

    // A walk lists the segments in path order, and so does a copy, as a full estimate sums
    // them: the same sums, bit for bit.
    const double toIrradiance = 1.0 / (glm::pi<double>() * double(mRadius) * double(mRadius));
    std::size_t j = 0;
    for (const std::uint32_t r : mEstimated) {
        const bool walked = j < mWalked.size() && mWalked[j] == r;
        const bool direct = walked && !mWalkCopies[j];
        const Aabb reach = discBounds(r);
        const auto& receiver = mReceivers.receivers()[r];
        NearSegments& near = mNear[r];
        if (direct) {
            mStats.candidateSegments += mDirect[j].size();
            accumulateDiscs(*mMobileDiscs[r], receiver.firstVertex, store.segments,
                            store.segments.power.data(), mDirect[j], {}, 1.0, false);
        } else {
            near.select(
                reach, !leavingSkippedFrom(r).isNull(),
                [&](std::uint16_t light) { return countsFirst(light); }, mSegmentList);
            mStats.nearSegments += near.size();
            mStats.candidateSegments += mSegmentList.size();
            accumulateDiscs(*mMobileDiscs[r], receiver.firstVertex, near.rays(), near.power(),
                            mSegmentList, {}, 1.0, false);
            if (!mCopyWorthIt[r]) near.clear(); // dearer to keep than to walk
        }
        j += walked ? 1 : 0;
        const std::uint32_t end = receiver.firstVertex + receiver.vertexCount;
        for (std::uint32_t v = receiver.firstVertex; v < end; ++v)
            mIrradiance[v] = published(mPowerSum[v].value() * toIrradiance);
        mLastReach[r] = reach;
        mNearIdle[r] = 0;
    }
}

Aabb DetpIrradianceSystem::nearBox(std::uint32_t receiver, const Aabb& reach) const {
    const Aabb& last = mLastReach[receiver];
    return neighbourhoodBox(reach, mSettings.nearSegmentMargin,
                            last.empty() ? glm::vec3(0.f) : reach.center() - last.center());
}

namespace {

/// Surface area of a box: proportional to the number of long segments that cross it (by
/// Cauchy's formula, its mean projected area is a quarter of it).
double surfaceArea(const Aabb& box) {
    const glm::dvec3 e(box.extent());
    return 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
}

} // namespace

void DetpIrradianceSystem::walkNear(const Registry& registry, const PhotonStore& store) {
    std::span<const std::uint32_t> candidates;
    const PhotonPathGrid* grid = registry.ctx().find<PhotonPathGrid>();
    if (grid && grid->indexes(store)) {
        grid->pathsOverlapping(mMobileBoxes, mCandidatePaths);
        candidates = mCandidatePaths;
    } else {
        mAllPaths.resize(store.paths.size());
        std::iota(mAllPaths.begin(), mAllPaths.end(), 0u);
        candidates = mAllPaths;
    }
    mStats.candidatePaths += candidates.size();
    mStats.mobilesWalked += mWalked.size();
    // Per mobile, the segments that meet its box, in parallel chunks of paths; the chunks are
    // joined in order, so each list is in (path, k) order. A copy takes them all; a mobile
    // that keeps none takes only those that count and that do not leave it. List (chunk c,
    // mobile j) is mChunkLists[c * count + j].
    const std::size_t count = mWalked.size();
    mLeavesFrom.clear();
    for (std::size_t j = 0; j < count; ++j)
        mLeavesFrom.push_back(mWalkCopies[j] ? Entity{} : leavingSkippedFrom(mWalked[j]));
    const float tail = crossingTail();
    const PhotonSegments& segments = store.segments;
    const std::size_t chunks = (candidates.size() + kPathGrain - 1) / kPathGrain;
    if (mChunkLists.size() < chunks * count) mChunkLists.resize(chunks * count);
    tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
        const std::span lists(mChunkLists.data() + c * count, count);
        for (std::vector<NearSegments::Pick>& list : lists)
            list.clear();
        const std::size_t last = std::min(candidates.size(), (c + 1) * kPathGrain);
        walkPathsPrefetched(store, candidates, c * kPathGrain, last, [&](std::size_t i) {
            const PhotonPath& path = store.paths[candidates[i]];
            const bool first = countsFirst(path.light);
            for (std::uint32_t k = 0; k < path.count; ++k) {
                const std::uint32_t s = path.first + k;
                const Entity from = k > 0 ? segments.hitEntity[s - 1] : Entity{};
                const glm::vec3& d = segments.direction[s];
                const glm::vec3 inverse = 1.f / d;
                for (std::size_t j = 0; j < count; ++j)
                    if ((mWalkCopies[j] ||
                         ((k > 0 || first) && !skipsLeaving(from, mLeavesFrom[j]))) &&
                        segmentMeetsBox(segments.origin[s], d, inverse, segments.length[s] + tail,
                                        mMobileBoxes[j]))
                        lists[j].push_back({candidates[i], s});
            }
        });
    });
    if (mDirect.size() < count) mDirect.resize(count);
    for (std::size_t j = 0; j < count; ++j) {
        const std::uint32_t r = mWalked[j];
        std::size_t picked = 0;
        for (std::size_t c = 0; c < chunks; ++c)
            picked += mChunkLists[c * count + j].size();
        // Whether a copy is worth its upkeep, for the walks to come: it costs about as much a
        // frame per segment held as a walk does per candidate path (ARCHITECTURE.md). A mobile
        // that walked without one estimates what one would hold from the surface areas of the
        // two boxes. Its own candidates: where several mobiles walked together, its box's alone.
        double held = double(picked);
        if (!mWalkCopies[j]) {
            const Aabb reach = mMobileBoxes[j];
            held *= surfaceArea(nearBox(r, reach)) / surfaceArea(reach);
        }
        std::size_t own = candidates.size();
        if (count > 1 && candidates.data() == mCandidatePaths.data()) {
            grid->pathsOverlapping(mMobileBoxes[j], mOwnCandidates);
            own = mOwnCandidates.size();
        }
        mCopyWorthIt[r] = held <= kNearCopiesPerWalkedPath * double(own);
        if (mWalkCopies[j]) {
            mPicks.clear();
            for (std::size_t c = 0; c < chunks; ++c)
                mPicks.insert(mPicks.end(), mChunkLists[c * count + j].begin(),
                              mChunkLists[c * count + j].end());
            mNear[r].build(store, mMobileBoxes[j], tail, mReceivers.receivers()[r].entity, mPicks);
        } else {
            mNear[r].clear();
            mDirect[j].clear();
            for (std::size_t c = 0; c < chunks; ++c)
                for (const NearSegments::Pick& pick : mChunkLists[c * count + j])
                    mDirect[j].push_back(pick.segment);
        }
    }
}

void DetpIrradianceSystem::updateNear(const PhotonDelta& delta) {
    bool arranged = false;
    for (std::uint32_t r = 0; r < mNear.size(); ++r) {
        NearSegments& near = mNear[r];
        if (!near.valid()) continue;
        // Still too long, moved out of it, or grown: dropped (a new one is made at its next
        // move).
        if ((!mIsMoved[r] && mNearIdle[r] >= kNearIdleFrames) ||
            (mIsMoved[r] && !near.covers(discBounds(r))) || near.outgrown()) {
            near.clear();
            continue;
        }
        if (!mIsMoved[r]) ++mNearIdle[r];
        if (delta.paths.empty()) continue;
        if (!arranged) mDeltaByPath.arrange(delta);
        arranged = true;
        near.apply(delta, mDeltaByPath, mPrefixEnd, mPathLight, mNearScratch);
    }
}

void DetpIrradianceSystem::splitDelta(const PhotonStore& store, const PhotonDelta& delta) {
    QGI_ASSERT(delta.oldFirst.size() == delta.paths.size() + 1 &&
                   delta.newFirst.size() == delta.paths.size() + 1,
               "PhotonDelta: oldFirst and newFirst hold one entry per path, plus one");
    constexpr float kWhole = -std::numeric_limits<float>::infinity();
    DeltaPart& subtract = mDeltaParts[0];
    DeltaPart& add = mDeltaParts[1];
    subtract.segments = &delta.oldSegments;
    add.segments = &delta.newSegments;
    for (DeltaPart* part : {&subtract, &add}) {
        part->indices.clear();
        part->beyond.clear();
        part->from.clear();
    }
    const PhotonSegments& before = delta.oldSegments;
    const PhotonSegments& after = delta.newSegments;
    // Where each suffix starts: the hit of the kept prefix's last segment (segment k of a
    // stored path has bounce k), and within a suffix the hit of the segment before. The
    // prefixes lie anywhere in the store: read in parallel, the rest in order.
    const std::size_t paths = delta.paths.size();
    mPrefixEnd.resize(paths);
    mPathLight.resize(paths);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, paths, kPathGrain),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t i = range.begin(); i != range.end(); ++i) {
                              const PhotonPath& path = store.paths[delta.paths[i]];
                              const auto head = std::uint32_t(std::max(delta.head(i), 0));
                              mPrefixEnd[i] = head > 0 && head <= path.count
                                                  ? store.segments.hitEntity[path.first + head - 1]
                                                  : Entity{};
                              mPathLight[i] = path.light;
                          }
                      });
    for (std::size_t i = 0; i < paths; ++i) {
        std::uint32_t o = delta.oldFirst[i], n = delta.newFirst[i];
        const std::uint32_t oldEnd = delta.oldFirst[i + 1], newEnd = delta.newFirst[i + 1];
        const Entity prefixEnd = mPrefixEnd[i];
        const std::uint16_t light = mPathLight[i];
        const auto list = [&](DeltaPart& part, std::uint32_t first, std::uint32_t s, float beyond) {
            part.indices.push_back(s);
            part.beyond.push_back(beyond);
            part.from.push_back(s == first ? prefixEnd : part.segments->hitEntity[s - 1]);
        };
        const std::uint32_t oldFirst = o, newFirst = n;
        // Not counted (hybrid mode, first segment of a light the renderer draws): skipped on
        // both sides.
        if (o < oldEnd && !counted(before, o, light)) ++o;
        if (n < newEnd && !counted(after, n, light)) ++n;
        // The two heads are one ray stopped at different lengths: the crossings of the shorter
        // one are also the longer one's and cancel exactly, so only the longer one's crossings
        // beyond the shorter one's end are applied.
        if (o < oldEnd && n < newEnd && before.origin[o] == after.origin[n] &&
            before.direction[o] == after.direction[n] && before.power[o] == after.power[n] &&
            before.bounce[o] == after.bounce[n]) {
            if (after.length[n] < before.length[o])
                list(subtract, oldFirst, o, after.length[n]);
            else if (before.length[o] < after.length[n])
                list(add, newFirst, n, before.length[o]);
            ++o;
            ++n;
        }
        for (; o < oldEnd; ++o)
            list(subtract, oldFirst, o, kWhole);
        for (; n < newEnd; ++n)
            list(add, newFirst, n, kWhole);
    }
}

void DetpIrradianceSystem::updateDetp(Registry& registry, const PhotonStore& store,
                                      const PhotonDelta& delta, bool full) {
    const double toIrradiance = 1.0 / (glm::pi<double>() * double(mRadius) * double(mRadius));
    const auto receivers = mReceivers.receivers();
    if (full) {
        std::fill(mPowerSum.begin(), mPowerSum.end(), CompensatedSum{});
        std::fill(mUpdateCount.begin(), mUpdateCount.end(), 0u);
        for (NearSegments& near : mNear)
            near.clear(); // copies of a ray set that is no more
        listCountedSegments(store, mSegmentList);
        accumulateDiscs(*mStaticDiscs, 0, store.segments, store.segments.power.data(), mSegmentList,
                        {}, 1.0, false);
        for (std::uint32_t v = 0; v < mReceivers.staticVertexCount(); ++v)
            mIrradiance[v] = published(mPowerSum[v].value() * toIrradiance);
        mAllMobiles.clear();
        for (std::uint32_t r = 0; r < receivers.size(); ++r)
            if (receivers[r].mobile) mAllMobiles.push_back(r);
        estimateMobiles(registry, store, mAllMobiles, true);
        publishAll(registry);
        return;
    }

    FrameProfiler* profiler = registry.ctx().find<FrameProfiler>();
    std::optional<StageTimer> timer(std::in_place, profiler, "delta", mStats.deltaMs);
    mTouched.clear();
    if (!delta.paths.empty()) {
        mStats.deltaSegments = delta.oldSegments.size() + delta.newSegments.size();
        splitDelta(store, delta);
        for (const DeltaPart& part : mDeltaParts)
            accumulateDiscs(*mStaticDiscs, 0, *part.segments, part.segments->power.data(),
                            part.indices, part.beyond, part.sign, true);
        // Mobiles that kept their pose take the same update, from the delta segments near them.
        const float tail = crossingTail();
        for (std::uint32_t r = 0; r < receivers.size(); ++r) {
            if (!receivers[r].mobile || mIsMoved[r] || !mActive[r]) continue;
            const Aabb box = discBounds(r);
            const Entity skipped = leavingSkippedFrom(r);
            for (const DeltaPart& part : mDeltaParts) {
                mSegmentList.clear();
                mBeyondList.clear();
                for (std::size_t k = 0; k < part.indices.size(); ++k) {
                    const std::uint32_t i = part.indices[k];
                    if (skipsLeaving(part.from[k], skipped) ||
                        !segmentMeetsBox(part.segments->origin[i], part.segments->direction[i],
                                         part.segments->length[i] + tail, box))
                        continue;
                    mSegmentList.push_back(part.indices[k]);
                    mBeyondList.push_back(part.beyond[k]);
                }
                accumulateDiscs(*mMobileDiscs[r], receivers[r].firstVertex, *part.segments,
                                part.segments->power.data(), mSegmentList, mBeyondList, part.sign,
                                true);
            }
        }
    }
    for (const std::uint32_t v : mTouched) {
        mIsTouched[v] = 0;
        mIrradiance[v] = published(mPowerSum[v].value() * toIrradiance);
    }
    std::sort(mTouched.begin(), mTouched.end());
    mReceivers.publish(registry, mIrradiance, mTouched);
    mStats.verticesWritten = mTouched.size();
    timer.emplace(profiler, "mobiles", mStats.mobileMs);

    updateNear(delta);
    estimateMobiles(registry, store, mMoved, false);
    for (const std::uint32_t r : mMoved) {
        mReceivers.publishReceiver(registry, mIrradiance, r);
        mStats.verticesWritten += receivers[r].vertexCount;
    }
    mStats.movedMobiles = mMoved.size();
}

// ---- impact count -------------------------------------------------------------------------

void DetpIrradianceSystem::updateImpacts(Registry& registry, const PhotonStore& store,
                                         const PhotonDelta& delta, bool full) {
    if (full) {
        mImpacts.reset(mReceivers);
        listCountedSegments(store, mSegmentList);
        mImpacts.accumulate(mReceivers, store.segments, mSegmentList, 1.0);
        mImpacts.takeTouchedVertices(mTouched); // forgotten: every vertex is published below
        for (std::uint32_t v = 0; v < mReceivers.vertexCount(); ++v)
            mIrradiance[v] = mImpacts.irradiance(v);
        publishAll(registry);
        return;
    }
    // Rigid mobiles keep their triangles' areas: only changed impacts count.
    if (delta.paths.empty() && delta.relabels.empty() && mMoved.empty()) return;
    mStats.deltaSegments = delta.oldSegments.size() + delta.newSegments.size();
    // Kept landings that slid onto another triangle of the same face.
    for (const PhotonRelabel& r : delta.relabels) {
        const std::size_t s = store.segmentIndex(r.path, r.k);
        if (!counted(store.segments, s, store.paths[r.path].light)) continue;
        mImpacts.moveImpact(mReceivers, store.segments.hitEntity[s], r.oldPrimitive, r.newPrimitive,
                            store.segments.power[s]);
    }
    for (const bool before : {true, false}) {
        const PhotonSegments& segments = before ? delta.oldSegments : delta.newSegments;
        const std::vector<std::uint32_t>& first = before ? delta.oldFirst : delta.newFirst;
        mSegmentList.clear();
        for (std::size_t i = 0; i < delta.paths.size(); ++i)
            for (std::uint32_t s = first[i]; s < first[i + 1]; ++s)
                if (counted(segments, s, store.paths[delta.paths[i]].light))
                    mSegmentList.push_back(s);
        mImpacts.accumulate(mReceivers, segments, mSegmentList, before ? -1.0 : 1.0);
    }
    // A mobile taken out lost every impact above; clearing its sums drops the rounding left.
    for (const std::uint32_t r : mMoved)
        if (!mActive[r]) mImpacts.clearTriangles(mReceivers.receivers()[r]);
    if (mImpacts.maxUpdates() >= mSettings.maxIncrementalUpdates) mNeedsFull = true;
    mImpacts.takeTouchedVertices(mTouched);
    for (const std::uint32_t v : mTouched)
        mIrradiance[v] = mImpacts.irradiance(v);
    mReceivers.publish(registry, mIrradiance, mTouched);
    mStats.verticesWritten = mTouched.size();
}

// ---- photon map ---------------------------------------------------------------------------

void DetpIrradianceSystem::estimatePhotonMap(std::uint32_t firstVertex, std::uint32_t count) {
    const auto positions = mReceivers.positions();
    const auto normals = mReceivers.normals();
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(firstVertex, firstVertex + count,
                                                        std::uint32_t(kVertexGrain)),
                      [&](const tbb::blocked_range<std::uint32_t>& range) {
                          std::vector<PhotonKdTree::Neighbour> scratch;
                          scratch.reserve(mSettings.photonMapNeighbours);
                          for (std::uint32_t v = range.begin(); v != range.end(); ++v)
                              mIrradiance[v] = mPhotonMap.estimateIrradiance(
                                  positions[v], normals[v], mSettings.photonMapNeighbours,
                                  mPhotonMapRadius, scratch);
                      });
}

void DetpIrradianceSystem::updatePhotonMap(Registry& registry, const PhotonStore& store,
                                           const PhotonDelta& delta, bool full) {
    if (full || !delta.paths.empty()) {
        // Not additive: rebuild from every stored hit and re-estimate everything.
        std::vector<PhotonKdTree::Photon> photons;
        photons.reserve(store.segments.size());
        for (const PhotonPath& path : store.paths) {
            for (std::uint32_t k = 0; k < path.count; ++k) {
                const std::uint32_t s = path.first + k;
                const PhotonSegments& segments = store.segments;
                if (segments.hitEntity[s].isNull() || !std::isfinite(segments.length[s]) ||
                    !counted(segments, s, path.light))
                    continue;
                photons.push_back({segments.origin[s] + segments.length[s] * segments.direction[s],
                                   segments.power[s], segments.direction[s]});
            }
        }
        mPhotonMap.build(std::move(photons));
        estimatePhotonMap(0, std::uint32_t(mReceivers.vertexCount()));
        for (std::uint32_t r = 0; r < mActive.size(); ++r)
            if (!mActive[r]) clearReceiver(r);
        mStats.deltaSegments = delta.oldSegments.size() + delta.newSegments.size();
        publishAll(registry);
        return;
    }
    for (const std::uint32_t r : mMoved) {
        const auto& receiver = mReceivers.receivers()[r];
        if (mActive[r])
            estimatePhotonMap(receiver.firstVertex, receiver.vertexCount);
        else
            clearReceiver(r);
        mReceivers.publishReceiver(registry, mIrradiance, r);
        mStats.verticesWritten += receiver.vertexCount;
    }
    mStats.movedMobiles = mMoved.size();
}

void DetpIrradianceSystem::publishAll(Registry& registry) {
    for (std::uint32_t r = 0; r < mReceivers.receivers().size(); ++r)
        mReceivers.publishReceiver(registry, mIrradiance, r);
    mStats.verticesWritten = mReceivers.vertexCount();
}

} // namespace qgi
