#include "systems/photon_update/PhotonUpdateSystem.h"

#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/PathFollower.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/Transform.h"
#include "components/WorldTransform.h"
#include "runtime/core/Hash.h"
#include "runtime/core/Log.h"
#include "runtime/profile/StageTimer.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneQueries.h"
#include "systems/photon_update/PhotonPathGrid.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/transform/TransformSystem.h"

#include <glm/common.hpp>
#include <glm/matrix.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace qgi {
namespace {

constexpr std::size_t kMaxLights = std::numeric_limits<std::uint16_t>::max(); // PhotonPath::light
constexpr std::size_t kTestGrain = 256;       // candidate paths per task
/// A moving mobile keeps its near paths while they are at most this share of the paths the
/// grid hands out for the same box (PhotonSettings::nearPathMargin).
constexpr double kNearPathsPerGridPath = 0.5;
/// A mobile whose near paths were not worth keeping tries them again after this many moves.
constexpr std::uint32_t kNearRetryMoves = 64;
constexpr std::size_t kCopyGrain = 512;       // paths per task when moving segments
// A shot where more of the lit photons than this leave the scene at once is warned about.
constexpr double kMostlyEscaped = 0.99;
// The grid refreshes when more paths are changed than 1/64 of all, or than twice the paths
// re-traced this frame, whichever is more: scanning that many boxes per query costs far less
// than the frame's re-tracing, and a big mobile re-traces much the same paths every frame.
constexpr std::size_t kIdleChangedRatio = 64;
constexpr std::size_t kIdleRetracedMultiple = 2;
// The grid is rebuilt at once when more than 1/16 of the paths are changed and more than 8
// times this frame's re-traced paths that may change again (all but those re-traced for an
// albedo edit alone): cornell's moving block keeps about 1/8 changed with 55k re-traced a frame.
constexpr std::size_t kRebuildChangedRatio = 16;
constexpr std::size_t kRebuildRecurringMultiple = 8;
// How far a light's photon count may drift from its share before it is dealt new photons
// (redealDrifted): each deal re-shoots its photons, so only a drift that costs visibly in
// noise. Once a deal is due, lights this far off are dealt anew along with it.
constexpr double kShareDrift = 4.0;
constexpr double kRedealAlong = 2.0;
// reuseLandedPaths: a segment tested again lands where it did within this fraction of the
// scene box's diagonal (the rounding of a ray mapped into a translated instance is far below
// it).
constexpr float kLandingTolerance = 1e-6f;
// A segment whose plane slid along it by more than this many tolerances cannot land: it is
// not tested again (the margin covers the rounding of the slide itself).
constexpr float kLandingMargin = 4.f;
// Two triangles of a mobile are one plane when their unit normals differ by less than this.
constexpr float kFacetTolerance = 1e-5f;

glm::vec3 albedoOf(const Material* material) {
    const glm::vec3 albedo = material ? material->baseColor : Material{}.baseColor;
    glm::vec3 out;
    for (int c = 0; c < 3; ++c) // NaN fails every comparison: it becomes 0, black
        out[c] = albedo[c] > 0.f ? std::min(albedo[c], 1.f) : 0.f;
    return out;
}

/// The albedo photons reflect off `e`, with a warning when its baseColor is not one.
glm::vec3 tracedAlbedo(const Registry& registry, Entity e) {
    const Material* material = registry.tryGet<Material>(e);
    const glm::vec3 albedo = albedoOf(material);
    if (material && albedo != material->baseColor) // NaN never compares equal
        logWarning("photons: Material.baseColor of ", entityName(registry, e), " is (",
                   material->baseColor.x, ", ", material->baseColor.y, ", ", material->baseColor.z,
                   "), not an albedo in [0, 1]; photons reflect (", albedo.x, ", ", albedo.y, ", ",
                   albedo.z, ")");
    return albedo;
}

bool isTraced(const Registry& registry, Entity e) {
    return registry.has<StaticMesh>(e) || registry.has<MobileMesh>(e);
}

Aabb transformBox(const Aabb& box, const glm::mat4& m) {
    Aabb out;
    for (int i = 0; i < 8; ++i)
        out.extend(
            glm::vec3(m * glm::vec4(i & 1 ? box.max.x : box.min.x, i & 2 ? box.max.y : box.min.y,
                                    i & 4 ? box.max.z : box.min.z, 1.f)));
    return out;
}

/// The box `box` (in the local frame of a node with `scale`) sweeps as the node follows `path`,
/// in the node's parent frame. Positions between keys are linear: where two keys share a
/// rotation the box between them lies within the boxes at the two keys; where the rotation
/// turns, within a sphere about each key's position that holds the box turned any way.
Aabb sweepAlong(const PathFollower& path, const glm::vec3& scale, const Aabb& box) {
    const glm::vec3 s = glm::abs(scale);
    const float reach =
        std::max({s.x, s.y, s.z}) * (glm::length(box.center()) + 0.5f * glm::length(box.extent()));
    Aabb sweep;
    const auto extend = [&](const Aabb& b) {
        sweep.extend(b.min);
        sweep.extend(b.max);
    };
    const std::vector<PathKey>& keys = path.keys;
    for (std::size_t k = 0; k < keys.size(); ++k) {
        extend(
            transformBox(box, localMatrix(Transform{keys[k].position, keys[k].rotation, scale})));
        // (A looping path jumps from its last key back to its first: nothing lies between.)
        if (k + 1 == keys.size() || keys[k + 1].rotation == keys[k].rotation) continue;
        for (const PathKey* key : {&keys[k], &keys[k + 1]})
            extend({key->position - glm::vec3(reach), key->position + glm::vec3(reach)});
    }
    return sweep;
}

/// World bounds of everywhere a mobile goes while it, or a node above it (a glTF mesh's
/// primitives hang below the animated node), follows a scripted path; empty when none does.
/// Walking up from the mobile, each node carries the box into its parent's frame: along its
/// path when it has one, else at its present local pose. Nodes without a Transform, or a
/// chain deeper than any real scene's, end the walk at the world transform they have.
Aabb scriptedSweep(const Registry& registry, Entity e, const Aabb& objectBounds) {
    if (objectBounds.empty()) return {};
    Aabb box = objectBounds;
    bool scripted = false;
    for (int depth = 0; depth < kMaxTransformDepth && !e.isNull(); ++depth) {
        const Transform* local = registry.tryGet<Transform>(e);
        const PathFollower* path = registry.tryGet<PathFollower>(e);
        if (!local) {
            const WorldTransform* world = registry.tryGet<WorldTransform>(e);
            return scripted && world ? transformBox(box, world->matrix) : Aabb{};
        }
        if (path && !path->keys.empty()) {
            box = sweepAlong(*path, local->scale, box);
            scripted = true;
        } else {
            box = transformBox(box, localMatrix(*local));
        }
        e = local->parent;
    }
    return scripted && e.isNull() ? box : Aabb{};
}

/// Whether a segment of path p meets `box`.
bool pathMeetsBox(const PhotonStore& store, std::uint32_t p, const Aabb& box) {
    const PhotonPath& path = store.paths[p];
    const PhotonSegments& segments = store.segments;
    for (std::uint32_t s = path.first; s < path.first + path.count; ++s)
        if (segmentMeetsBox(segments.origin[s], segments.direction[s], segments.length[s], box))
            return true;
    return false;
}

/// The box widened past rounding (of transformed corners, of rays mapped to object space),
/// so that testing segments against it never rejects one that touches what it bounds.
Aabb widened(const Aabb& box) {
    const glm::vec3 pad = 1e-4f * (glm::abs(box.min) + glm::abs(box.max) + box.extent()) + 1e-6f;
    return {box.min - pad, box.max + pad};
}

double wattsOf(const glm::vec3& power) {
    return double(power.x) + power.y + power.z;
}

/// Photon counts in proportion to each light's power (the sum of its RGB watts), summing to
/// `photons`: largest remainders, so every count is within one of its exact share.
void allocatePhotons(std::vector<PhotonEmitter>& emitters, std::uint32_t photons) {
    double total = 0.0;
    for (const PhotonEmitter& e : emitters)
        total += wattsOf(e.power);
    std::vector<std::pair<double, std::size_t>> remainders;
    std::uint64_t given = 0;
    for (std::size_t i = 0; i < emitters.size(); ++i) {
        const double share = total > 0.0 ? photons * (wattsOf(emitters[i].power) / total) : 0.0;
        emitters[i].photonCount = std::uint32_t(std::floor(share));
        given += emitters[i].photonCount;
        if (share > 0.0) remainders.emplace_back(share - std::floor(share), i);
    }
    // Ties go to the earlier light: the order is fixed, so the allocation is deterministic.
    std::stable_sort(remainders.begin(), remainders.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    for (std::size_t r = 0; given < photons && r < remainders.size(); ++r, ++given)
        ++emitters[remainders[r].second].photonCount;
    std::uint32_t first = 0;
    for (PhotonEmitter& e : emitters) {
        e.firstPhoton = first;
        first += e.photonCount;
    }
}

void setBit(std::vector<std::uint64_t>& bits, std::uint32_t i, bool value) {
    const std::uint64_t mask = std::uint64_t(1) << (i & 63);
    bits[i >> 6] = value ? bits[i >> 6] | mask : bits[i >> 6] & ~mask;
}

bool testBit(const std::vector<std::uint64_t>& bits, std::uint32_t i) {
    return (bits[i >> 6] >> (i & 63)) & 1;
}

} // namespace

bool PhotonUpdateSystem::Mobile::sameFacet(std::uint32_t a, std::uint32_t b) const {
    if (a == b) return true;
    if (a >= facetNormals.size() || b >= facetNormals.size()) return false;
    const glm::vec3 d = facetNormals[a] - facetNormals[b];
    return glm::dot(facetNormals[a], facetNormals[a]) > 0.f &&
           glm::dot(d, d) < kFacetTolerance * kFacetTolerance;
}

PhotonUpdateSystem::PhotonUpdateSystem(const PhotonSettings& settings) : mSettings(settings) {
    validatePhotonSettings(settings);
}

std::vector<PhotonUpdateSystem::LightPhotons> PhotonUpdateSystem::lightPhotons() const {
    std::vector<LightPhotons> out;
    out.reserve(mEmitters.size());
    for (std::size_t l = 0; l < mEmitters.size(); ++l)
        out.push_back({mEmitters[l].firstPhoton, mEmitters[l].photonCount, mSweeps[l].remaining,
                       mEmitters[l].absent, mEmitters[l].ghost});
    return out;
}

PhotonTracer::Surfaces PhotonUpdateSystem::surfaces() const {
    return {mSettings.seed, mSettings.maxBounces, mAlbedo};
}

void PhotonUpdateSystem::update(Registry& registry, const FrameContext& /*frame*/) {
    Context& ctx = registry.ctx();
    const RayScene* scene = ctx.find<RayScene>();
    QGI_ASSERT(scene, "PhotonUpdateSystem needs the RayScene world resource");
    PhotonStore& store =
        ctx.contains<PhotonStore>() ? ctx.get<PhotonStore>() : ctx.emplace<PhotonStore>();
    PhotonDelta& delta =
        ctx.contains<PhotonDelta>() ? ctx.get<PhotonDelta>() : ctx.emplace<PhotonDelta>();
    PhotonPathGrid& grid =
        ctx.contains<PhotonPathGrid>() ? ctx.get<PhotonPathGrid>() : ctx.emplace<PhotonPathGrid>();
    delta.clear(); // keeps the sequence number, which this update advances
    ++delta.sequence;
    mStats = {};

    mSources.clear();
    findEmitterSources(registry, mSettings, mSources);
    if (mShot) {
        findMovedMobiles(registry, *scene, delta);
        findAlbedoEdits(registry); // a full shot below reads every albedo anew anyway
    }
    if (!mShot || mSettings.fullRecompute || detectLightChanges(registry, store, grid)) {
        shootAll(registry, *scene, store, grid);
        delta.full = true;
        return;
    }

    FrameProfiler* profiler = ctx.find<FrameProfiler>();
    {
        const StageTimer timer(profiler, "find", mStats.findMs);
        scheduleReshoots();
        mRelabels.clear();
        findAffectedPaths(*scene, store, grid);
        for (const Relabel& r : mRelabels) {
            delta.relabels.push_back(
                {r.path, r.k, store.segments.hitPrimitive[r.segment], r.primitive});
            store.segments.hitPrimitive[r.segment] = r.primitive;
        }
    }
    if (!mJobs.empty()) {
        const StageTimer timer(profiler, "trace", mStats.traceMs);
        retrace(*scene, store, delta);
    }
    const StageTimer timer(profiler, "grid", mStats.gridMs);
    updateNearPaths(delta); // an index too
    // A frame that leaves a large share of the paths changed for good (a repainted floor: its
    // paths will not change again next frame, as a moving mobile's do) rebuilds the grid:
    // re-indexed a budget at a time, they would leave every query testing their boxes for
    // hundreds of frames.
    const std::size_t recurring = delta.paths.size() - mStats.repaintedPaths;
    const bool rebuild =
        grid.changedPathCount() + delta.paths.size() >
        std::max(store.pathCount() / kRebuildChangedRatio, kRebuildRecurringMultiple * recurring);
    if (!mJobs.empty() && !rebuild) grid.markChanged(store, delta.paths);
    // A little of the garbage re-traced paths left, every frame (PhotonStoreSpace).
    const PhotonStoreSpace::Reclaimed reclaimed =
        mSpace.reclaim(store, double(mSettings.compactionFraction));
    mStats.compacted = reclaimed.laidOut;
    mStats.compactedRegions = reclaimed.regions;
    if (rebuild) {
        grid.build(store, mSceneBox, mSettings.gridResolution);
        mStats.reindexedPaths = store.pathCount();
        return;
    }
    // Also on still frames: the index catches up with earlier changes. While few paths are
    // changed it idles: queries scan their boxes cheaply, and paths near a moving mobile
    // would change again anyway. A light's re-shot photons do not change again next frame
    // (a sweep takes each once, and they lie in consecutive chunks): the budget grows by them,
    // so a long sweep (a light added with a million photons) never leaves enough changed to
    // force a rebuild.
    const std::size_t idleUpTo =
        std::max(store.pathCount() / kIdleChangedRatio, kIdleRetracedMultiple * delta.paths.size());
    mStats.reindexedPaths =
        grid.refresh(store, mSettings.gridRefreshBudget + mStats.reshotPaths, idleUpTo);
}

/// Where the light stand-ins are (a stand-in added, removed, moved or retagged changes which
/// emissive surfaces hybrid mode's renderer draws itself).
std::uint64_t standInSignature(const Registry& registry) {
    Fnv1aHasher h;
    registry.view<const LightStandIn, const WorldTransform>().each(
        [&](Entity e, const LightStandIn&, const WorldTransform& at) {
            h.add(e.index);
            h.add(glm::vec3(at.matrix[3]));
            h.add(registry.has<PointLight>(e) || registry.has<SpotLight>(e));
        });
    return h.value();
}

std::int64_t PhotonUpdateSystem::emitterOf(const PhotonEmitter& source) const {
    const auto it = mEmitterIndex.find({source.kind, source.entity});
    return it == mEmitterIndex.end() ? -1 : std::int64_t(it->second);
}

void PhotonUpdateSystem::indexEmitters() {
    mEmitterIndex.clear();
    for (std::size_t i = 0; i < mEmitters.size(); ++i)
        mEmitterIndex.emplace(std::pair(mEmitters[i].kind, mEmitters[i].entity), std::uint32_t(i));
}

bool PhotonUpdateSystem::detectLightChanges(const Registry& registry, PhotonStore& store,
                                            PhotonPathGrid& grid) {
    if (const std::uint64_t standIns = standInSignature(registry); standIns != mStandIns) {
        mStandIns = standIns;
        // A surface drawn by the shader (or no longer) counts its first segments otherwise:
        // the stored lights' flags change, and DETP must start over.
        for (const PhotonEmitter& e : mEmitters)
            if (e.kind == EmitterKind::Surface && !e.absent &&
                hasLightStandIn(registry, e.entity) != e.directDrawn)
                return true;
    }
    mSourceOf.assign(mEmitters.size(), -1);
    mAdded.clear();
    for (std::size_t s = 0; s < mSources.size(); ++s) {
        const std::int64_t e = emitterOf(mSources[s]);
        if (e < 0)
            mAdded.push_back(s);
        else
            mSourceOf[std::size_t(e)] = std::int64_t(s);
    }
    bool changed = false;
    for (std::size_t i = 0; i < mEmitters.size(); ++i) {
        PhotonEmitter& shot = mEmitters[i];
        PhotonEmitter edited;
        if (mSourceOf[i] < 0) {
            if (shot.absent) continue;
            // Removed: dark from now on, its photons re-shot empty, until it is listed again.
            edited = shot;
            edited.absent = true;
            edited.radiant = glm::vec3(0.f);
            edited.power = glm::vec3(0.f);
        } else {
            const PhotonEmitter& source = mSources[std::size_t(mSourceOf[i])];
            if (!shot.absent && source.sameSource(shot)) continue;
            edited = source; // a source only: nothing derived to copy yet
            edited.firstPhoton = shot.firstPhoton;
            edited.photonCount = shot.photonCount;
            prepareEmitter(registry, mDirectionalBox, edited);
            // A surface moving to or from a stand-in changes what hybrid mode counts: shoot
            // everything anew. A light switched off keeps its photons, re-shot empty (they
            // carry nothing), for when it shines again; one that lights up without photons
            // of its own gets some (addPhotons).
            if (edited.directDrawn != shot.directDrawn) return true;
        }
        shot = std::move(edited);
        mSweeps[i].remaining = shot.photonCount;
        store.lights[i].power = shot.power;
        changed = true;
    }
    for (const std::size_t s : mAdded) {
        if (mEmitters.size() >= kMaxLights) {
            // A full shot drops the removed lights; without any, the lights past the limit
            // stay dark (the full shot named them).
            if (std::any_of(mEmitters.begin(), mEmitters.end(),
                            [](const PhotonEmitter& e) { return e.absent; }))
                return true;
            break;
        }
        PhotonEmitter light = mSources[s];
        prepareEmitter(registry, mDirectionalBox, light);
        light.firstPhoton = std::uint32_t(store.paths.size());
        mEmitterIndex.emplace(std::pair(light.kind, light.entity), std::uint32_t(mEmitters.size()));
        store.lights.push_back({light.entity, light.power, 0, light.directDrawn});
        mEmitters.push_back(std::move(light));
        mSweeps.emplace_back();
        changed = true;
    }
    if (!changed) return false;
    store.emittedPower = glm::vec3(0.f);
    for (const PhotonLight& light : store.lights)
        store.emittedPower += light.power;
    const std::size_t before = store.paths.size();
    mergeFreeRanges(store);
    if (!addPhotons(store) || !redealDrifted(store)) return true;
    mStats.addedPaths = store.paths.size() - before;
    if (mStats.addedPaths > 0) {
        mReshooting.resize((store.paths.size() + 63) / 64, 0);
        mSpace.addEmptyPaths(store);
        grid.addEmptyPaths(store);
    }
    return false;
}

void PhotonUpdateSystem::setRange(PhotonStore& store, std::size_t l, std::uint32_t first,
                                  std::uint32_t count) {
    mEmitters[l].firstPhoton = first;
    mEmitters[l].photonCount = count;
    store.lights[l].photonCount = count;
}

void PhotonUpdateSystem::handOver(PhotonStore& store, std::uint32_t first, std::uint32_t count,
                                  std::size_t owner) {
    for (std::uint32_t p = first; p < first + count; ++p)
        store.paths[p].light = std::uint16_t(owner);
}

void PhotonUpdateSystem::mergeFreeRanges(PhotonStore& store) {
    mFree.clear();
    for (std::size_t l = 0; l < mEmitters.size(); ++l)
        if (mEmitters[l].absent && mSweeps[l].remaining == 0 && mEmitters[l].photonCount > 0)
            mFree.push_back(l);
    std::sort(mFree.begin(), mFree.end(), [&](std::size_t a, std::size_t b) {
        return mEmitters[a].firstPhoton < mEmitters[b].firstPhoton;
    });
    std::size_t kept = 0;
    for (const std::size_t l : mFree) {
        if (kept > 0) {
            const std::size_t a = mFree[kept - 1];
            const PhotonEmitter& left = mEmitters[a];
            if (left.firstPhoton + left.photonCount == mEmitters[l].firstPhoton) {
                handOver(store, mEmitters[l].firstPhoton, mEmitters[l].photonCount, a);
                setRange(store, a, left.firstPhoton, left.photonCount + mEmitters[l].photonCount);
                setRange(store, l, 0, 0);
                continue;
            }
        }
        mFree[kept++] = l;
    }
    mFree.resize(kept);
}

std::uint32_t PhotonUpdateSystem::roomFor(const PhotonStore& store, std::uint32_t count) const {
    const std::size_t limit = std::size_t(kMaxPhotonGrowth) * mSettings.photonCount;
    std::size_t room = limit > store.paths.size() ? limit - store.paths.size() : 0;
    for (const std::size_t l : mFree)
        room = std::max<std::size_t>(room, mEmitters[l].photonCount);
    return std::uint32_t(std::min<std::size_t>(room, count));
}

void PhotonUpdateSystem::takeRange(PhotonStore& store, std::size_t owner, std::uint32_t count) {
    QGI_ASSERT(count > 0 && roomFor(store, count) == count, "no room for ", count, " photons");
    // The smallest free range that holds them, else the store's end.
    std::size_t best = mFree.size();
    for (std::size_t i = 0; i < mFree.size(); ++i) {
        const std::uint32_t size = mEmitters[mFree[i]].photonCount;
        if (size >= count && (best == mFree.size() || size < mEmitters[mFree[best]].photonCount))
            best = i;
    }
    std::uint32_t first = 0;
    if (best < mFree.size()) {
        const std::size_t donor = mFree[best];
        first = mEmitters[donor].firstPhoton;
        setRange(store, donor, first + count, mEmitters[donor].photonCount - count);
        if (mEmitters[donor].photonCount == 0) mFree.erase(mFree.begin() + std::ptrdiff_t(best));
        handOver(store, first, count, owner);
    } else {
        first = std::uint32_t(store.paths.size());
        store.paths.resize(store.paths.size() + count, PhotonPath{0, 0, std::uint16_t(owner)});
    }
    setRange(store, owner, first, count);
    mSweeps[owner] = Sweep{count, 0};
}

bool PhotonUpdateSystem::takeShare(PhotonStore& store, std::size_t l, std::uint32_t share) {
    const std::uint32_t count = roomFor(store, share);
    if (double(count) * kShareDrift < double(share)) return false;
    takeRange(store, l, count);
    return true;
}

bool PhotonUpdateSystem::retire(PhotonStore& store, std::size_t l) {
    const std::uint32_t first = mEmitters[l].firstPhoton, count = mEmitters[l].photonCount;
    if (count == 0) return true;
    // A ghost with nothing left to do takes them, else a new one.
    std::size_t g = 0;
    while (g < mEmitters.size() &&
           !(mEmitters[g].ghost && mEmitters[g].photonCount == 0 && mSweeps[g].remaining == 0))
        ++g;
    if (g == mEmitters.size()) {
        if (g >= kMaxLights) return false;
        mEmitters.emplace_back();
        mSweeps.emplace_back();
        store.lights.emplace_back();
    }
    PhotonEmitter ghost;
    ghost.kind = mEmitters[l].kind;
    ghost.absent = ghost.ghost = true;
    ghost.directDrawn = mEmitters[l].directDrawn; // its photons are counted as they were
    mEmitters[g] = std::move(ghost);
    store.lights[g] = PhotonLight{Entity{}, glm::vec3(0.f), 0, mEmitters[g].directDrawn};
    handOver(store, first, count, g);
    setRange(store, g, first, count);
    mSweeps[g] = Sweep{count, 0};
    setRange(store, l, 0, 0);
    mSweeps[l] = Sweep{};
    return true;
}

bool PhotonUpdateSystem::addPhotons(PhotonStore& store) {
    double litPower = 0.0, litPhotons = 0.0, waiting = 0.0;
    for (const PhotonEmitter& e : mEmitters) {
        if (!carriesPower(e.power)) continue;
        if (e.photonCount > 0) {
            litPower += wattsOf(e.power);
            litPhotons += e.photonCount;
        } else {
            waiting += wattsOf(e.power);
        }
    }
    if (!(waiting > 0.0)) return true;
    // Photons per watt: the lit lights', so every photon carries the same power, but never
    // fewer than photonCount over all the lights that shine (when the lights with photons
    // have few, a big one removed, the new ones restore the count). Short of room, takeShare.
    const double rate = std::max(litPhotons > 0.0 ? litPhotons / litPower : 0.0,
                                 mSettings.photonCount / (litPower + waiting));
    for (std::size_t l = 0; l < mEmitters.size(); ++l) {
        const PhotonEmitter& e = mEmitters[l];
        if (!carriesPower(e.power) || e.photonCount > 0) continue;
        const auto wanted =
            std::uint32_t(std::min(std::floor(rate * wattsOf(e.power) + 0.5),
                                   double(kMaxPhotonGrowth) * mSettings.photonCount));
        if (wanted == 0) continue; // a share under half a photon
        if (!takeShare(store, l, wanted)) return false;
    }
    return true;
}

bool PhotonUpdateSystem::redealDrifted(PhotonStore& store) {
    // Photons carry equal power only as dealt: a light that has since brightened carries more
    // per photon than the rest (noisier, not biased), one dimmed holds photons the others
    // could use. Each lit light's count is compared with its exact share of the lit lights'
    // photons, or of photonCount when they hold fewer (a big light removed or switched off
    // leaves the rest too few); a share under one photon is no share to keep. Lights
    // switched off are left out: their photons wait for them.
    double total = 0.0, photons = 0.0;
    for (const PhotonEmitter& e : mEmitters) {
        if (!carriesPower(e.power)) continue;
        total += wattsOf(e.power);
        photons += e.photonCount;
    }
    if (!(total > 0.0)) return true;
    photons = std::max(photons, double(mSettings.photonCount));
    const auto shareOf = [&](const PhotonEmitter& e) { return photons * wattsOf(e.power) / total; };
    const auto off = [&](const PhotonEmitter& e, double factor) {
        const double share = shareOf(e), count = e.photonCount;
        return share >= 1.0 && (count * factor < share || count > factor * share);
    };
    const bool any = std::any_of(mEmitters.begin(), mEmitters.end(), [&](const PhotonEmitter& e) {
        return carriesPower(e.power) && off(e, kShareDrift);
    });
    if (!any) return true;
    // Once a deal is due, lights 2x off their shares are dealt anew with it: then every lit
    // light is within 2x of its share, and the lit photons within 2x of their total.
    mDrifted.clear();
    for (std::size_t l = 0; l < mEmitters.size(); ++l)
        if (carriesPower(mEmitters[l].power) && off(mEmitters[l], kRedealAlong))
            mDrifted.emplace_back(l, std::uint32_t(std::floor(shareOf(mEmitters[l]) + 0.5)));
    // Each light's photons go dark (a ghost re-shoots them empty) while its share is shot
    // from a range of its own: its light fades from the old photons to the new.
    for (const auto& [l, share] : mDrifted)
        if (!retire(store, l)) return false;
    for (const auto& [l, share] : mDrifted)
        if (!takeShare(store, l, share)) return false;
    mStats.redealtLights = mDrifted.size();
    return true;
}

bool PhotonUpdateSystem::litByDirectionalLight() const {
    return std::any_of(mEmitters.begin(), mEmitters.end(), [](const PhotonEmitter& e) {
        return e.kind == EmitterKind::Directional && !e.absent && e.photonCount > 0;
    });
}

void PhotonUpdateSystem::findAlbedoEdits(const Registry& registry) {
    for (const AlbedoEdit& edit : mEdits)
        mEditedByIndex[edit.entity.index] = Entity{};
    mEdits.clear();
    for (const Entity e : registry.changed<Material>()) {
        if (e.index >= mAlbedo.size() || !registry.alive(e) || !isTraced(registry, e)) continue;
        if (edited(e) || albedoOf(registry.tryGet<Material>(e)) == mAlbedo[e.index]) continue;
        mAlbedo[e.index] = tracedAlbedo(registry, e);
        // Where the hits recorded on it lie: where the ray scene holds it (not where its
        // components say, which the ray scene may have refused), at its pose as traced. A
        // mobile that moved this frame has its old box queried as a moved mobile; one out of
        // the world has no hits.
        Aabb box;
        if (const auto mobile = mMobileIndex.find(e); mobile != mMobileIndex.end()) {
            const Mobile& m = mMobiles[mobile->second];
            if (m.active) box = widened(transformBox(m.objectBounds, m.pose));
        } else if (const auto still = mStaticBoxes.find(e); still != mStaticBoxes.end()) {
            box = still->second;
        }
        mEdits.push_back({e, box});
        if (mEditedByIndex.size() <= e.index) mEditedByIndex.resize(e.index + 1);
        mEditedByIndex[e.index] = e;
    }
    mStats.editedSurfaces = mEdits.size();
}

void PhotonUpdateSystem::captureScene(const Registry& registry, const RayScene& scene) {
    mSceneBox = {};
    mStaticBoxes.clear();
    registry.view<const StaticMesh, const Mesh, const WorldTransform>().each(
        [&](Entity e, const StaticMesh&, const Mesh& mesh, const WorldTransform& world) {
            Aabb box;
            for (const glm::vec3& p : mesh.positions)
                box.extend(glm::vec3(world.matrix * glm::vec4(p, 1.f)));
            mSceneBox.extend(box);
            if (!box.empty()) mStaticBoxes.emplace(e, widened(box));
        });
    mMobiles.clear();
    mMobileIndex.clear();
    registry.view<const MobileMesh, const Mesh>().each(
        [&](Entity e, const MobileMesh&, const Mesh& mesh) {
            if (!scene.isMobile(e)) return;
            Mobile mobile{e, {}, scene.mobilePose(e), scene.mobileActive(e), {}};
            for (const glm::vec3& p : mesh.positions)
                mobile.objectBounds.extend(p);
            mobile.facetNormals.reserve(mesh.indices.size() / 3);
            for (std::size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
                const glm::vec3& a = mesh.positions[mesh.indices[t]];
                const glm::vec3 n = glm::cross(mesh.positions[mesh.indices[t + 1]] - a,
                                               mesh.positions[mesh.indices[t + 2]] - a);
                const float length = glm::length(n);
                mobile.facetNormals.push_back(length > 0.f ? n / length : glm::vec3(0.f));
            }
            // A pooled mobile out of the world may wait anywhere: not part of the scene's box.
            if (mobile.active) mSceneBox.extend(transformBox(mobile.objectBounds, mobile.pose));
            mMobileIndex.emplace(e, mMobiles.size());
            mMobiles.push_back(mobile);
        });
    if (mSceneBox.empty()) mSceneBox = {glm::vec3(-1.f), glm::vec3(1.f)};

    if (directionalBoundsSet(mSettings)) {
        mDirectionalBox = mSettings.directionalBounds;
        return;
    }
    mDirectionalBox = mSceneBox;
    // Photons spread over a box twice as wide are a quarter as dense: a path that reaches past
    // the scene box grown to twice its size is named.
    const Aabb roomy{mSceneBox.center() - mSceneBox.extent(),
                     mSceneBox.center() + mSceneBox.extent()};
    const bool sun = std::any_of(mSources.begin(), mSources.end(), [](const PhotonEmitter& e) {
        return e.kind == EmitterKind::Directional;
    });
    std::string far;
    for (const Mobile& mobile : mMobiles) {
        const Aabb sweep = scriptedSweep(registry, mobile.entity, mobile.objectBounds);
        if (sweep.empty()) continue;
        mDirectionalBox.extend(sweep.min);
        mDirectionalBox.extend(sweep.max);
        if (!contains(roomy, sweep))
            far += str(far.empty() ? "" : ", ", entityName(registry, mobile.entity));
    }
    if (sun && !far.empty())
        logWarning("photons: the scripted paths of ", far,
                   " reach far beyond the scene; "
                   "directional lights spread their photons over them too (set "
                   "PhotonSettings::directionalBounds to the area that matters)");
}

void PhotonUpdateSystem::shootAll(const Registry& registry, const RayScene& scene,
                                  PhotonStore& store, PhotonPathGrid& grid) {
    if (!mShot) captureScene(registry, scene);
    mShot = true;
    mNearPaths.clear(); // paths of a ray set that is no more
    mStats.full = true;

    // Lights: an unchanged light keeps what was derived from it (no work, no repeated warning).
    if (mSources.size() > kMaxLights) {
        logWarning("photons: ", mSources.size(), " lights; only the first ", kMaxLights, " shoot");
        mSources.resize(kMaxLights);
    }
    for (std::size_t i = 0; i < mSources.size(); ++i) {
        const std::int64_t shot = emitterOf(mSources[i]);
        if (shot >= 0 && !mEmitters[std::size_t(shot)].absent &&
            mSources[i].sameSource(mEmitters[std::size_t(shot)])) {
            mSources[i] = std::move(mEmitters[std::size_t(shot)]);
            // A kept surface may have gained or lost its stand-in since it was prepared.
            if (mSources[i].kind == EmitterKind::Surface)
                mSources[i].directDrawn = hasLightStandIn(registry, mSources[i].entity);
        } else {
            prepareEmitter(registry, mDirectionalBox, mSources[i]);
        }
    }
    std::swap(mEmitters, mSources);
    indexEmitters();
    allocatePhotons(mEmitters, mSettings.photonCount);
    mStandIns = standInSignature(registry);
    mSweeps.assign(mEmitters.size(), Sweep{});

    mAlbedo.clear();
    registry.view<const Mesh>().each([&](Entity e, const Mesh&) {
        if (!isTraced(registry, e)) return;
        if (e.index >= mAlbedo.size()) mAlbedo.resize(e.index + 1, glm::vec3(0.f));
        mAlbedo[e.index] = tracedAlbedo(registry, e);
    });

    store.lights.clear();
    store.emittedPower = glm::vec3(0.f);
    store.paths.clear();
    for (std::size_t l = 0; l < mEmitters.size(); ++l) {
        const PhotonEmitter& e = mEmitters[l];
        store.lights.push_back({e.entity, e.power, e.photonCount, e.directDrawn});
        store.emittedPower += e.power;
        store.paths.resize(store.paths.size() + e.photonCount, PhotonPath{0, 0, std::uint16_t(l)});
    }
    ++store.generation;

    store.segments.clear();
    mEnds.assign(1, 0);
    mTracer.trace(
        scene, surfaces(), store.paths.size(),
        [&](std::size_t i) {
            return emitPhoton(mEmitters[store.paths[i].light], std::uint32_t(i), mSettings.seed);
        },
        store.segments, mEnds);
    for (std::size_t i = 0; i < store.paths.size(); ++i) {
        store.paths[i].first = mEnds[i];
        store.paths[i].count = std::uint16_t(mEnds[i + 1] - mEnds[i]);
    }
    const std::size_t traced = store.segments.size();
    mReshooting.assign((store.paths.size() + 63) / 64, 0);
    if (mSettings.fullRecompute) {
        // Re-shot every frame: no room for re-traced paths, and no index of paths to find
        // them by (building it would cost 0.4 to 1.3 times the frame's tracing, for a few per
        // cent of DETP's full estimate).
        mSpace.clear();
        grid.clear();
    } else {
        mSpace.layOut(store, double(mSettings.compactionFraction));
        grid.build(store, mSceneBox, mSettings.gridResolution);
    }
    mStats.tracedSegments = traced;
    mStats.reindexedPaths = store.paths.size();
    if (!mLoggedShot) { // --full-recompute shoots every frame: once is enough
        mLoggedShot = true;
        constexpr double kMiB = 1024.0 * 1024.0;
        logInfo("photons: ", store.paths.size(), " from ", mEmitters.size(), " lights, ", traced,
                " segments: store ",
                double(store.segments.size() * PhotonSegments::kBytesPerSegment) / kMiB,
                " MiB (with room for re-traced paths), path grid ",
                double(grid.memoryBytes()) / kMiB, " MiB");
        // Lights that light nothing give a dark export and image: say why.
        std::size_t lit = 0, escaped = 0;
        for (const PhotonPath& path : store.paths) {
            if (path.count == 0) continue; // a dark light's photon
            ++lit;
            escaped += !store.segments.hitEntity[path.first];
        }
        if (mSettings.photonCount > 0 && !mEmitters.empty() && lit == 0)
            logWarning("photons: every light is off or has no power, so no photon carries light "
                       "(global illumination stays dark until one lights up)");
        else if (lit > 0 && double(escaped) > kMostlyEscaped * double(lit))
            logWarning("photons: ", escaped, " of ", lit,
                       " photons leave the scene without meeting a surface: are the lights "
                       "inside the scene, and turned towards it?");
    }
}

void PhotonUpdateSystem::findMovedMobiles(const Registry& registry, const RayScene& scene,
                                          PhotonDelta& delta) {
    mMoved.clear();
    const auto follow = [&](Entity e) {
        const auto it = mMobileIndex.find(e);
        if (it == mMobileIndex.end() || !scene.isMobile(e)) return;
        Mobile& mobile = mMobiles[it->second];
        const glm::mat4& pose = scene.mobilePose(e);
        const bool active = scene.mobileActive(e);
        // Also skips an entity listed twice, or in both change lists.
        if (pose == mobile.pose && active == mobile.active) return;
        delta.movedMobiles.push_back(e);
        if (mobile.active || active) {
            const glm::mat4 toObject = glm::inverse(pose);
            const bool turned = glm::mat3(pose) != glm::mat3(mobile.pose);
            mMoved.push_back(
                {e, pose, toObject, glm::transpose(glm::mat3(toObject)),
                 glm::vec3(pose[3] - mobile.pose[3]), widened(mobile.objectBounds),
                 mobile.active ? widened(transformBox(mobile.objectBounds, mobile.pose)) : Aabb{},
                 active ? widened(transformBox(mobile.objectBounds, pose)) : Aabb{},
                 mobile.active && active && !turned ? &mobile : nullptr, active});
        }
        mobile.pose = pose;
        mobile.active = active;
        if (active && !mobile.warnedOutside && litByDirectionalLight() &&
            !contains(widened(mDirectionalBox), transformBox(mobile.objectBounds, pose))) {
            mobile.warnedOutside = true;
            logWarning("photons: mobile ", entityName(registry, e),
                       " left the box the directional lights cover; beyond it no directional "
                       "photons reach it (set PhotonSettings::directionalBounds to the area it "
                       "moves in)");
        }
    };
    forEachMovedOrSwitched(registry, follow);
    mStats.movedMobiles = mMoved.size();
}

void PhotonUpdateSystem::scheduleReshoots() {
    mJobs.clear();
    std::uint32_t budget = mSettings.reshootBudget;
    std::size_t pending = 0;
    for (const Sweep& sweep : mSweeps)
        pending += sweep.remaining > 0 ? 1 : 0;
    // Shares of what is left, evenly among the lights still sweeping; each pass hands out at
    // least one photon per pending light, so the loop ends.
    while (budget > 0 && pending > 0) {
        const std::uint32_t share = std::max<std::uint32_t>(1, budget / std::uint32_t(pending));
        pending = 0;
        for (std::size_t l = 0; l < mSweeps.size() && budget > 0; ++l) {
            Sweep& sweep = mSweeps[l];
            if (sweep.remaining == 0) continue;
            const PhotonEmitter& emitter = mEmitters[l];
            const std::uint32_t take = std::min({share, sweep.remaining, budget});
            for (std::uint32_t t = 0; t < take; ++t) {
                const std::uint32_t photon =
                    emitter.firstPhoton + (sweep.cursor + t) % emitter.photonCount;
                mJobs.push_back({photon, 0, true});
                setBit(mReshooting, photon, true);
            }
            sweep.cursor = (sweep.cursor + take) % emitter.photonCount;
            sweep.remaining -= take;
            budget -= take;
            pending += sweep.remaining > 0 ? 1 : 0;
        }
    }
    mStats.reshotPaths = mJobs.size();
}

void PhotonUpdateSystem::findAffectedPaths(const RayScene& scene, const PhotonStore& store,
                                           const PhotonPathGrid& grid) {
    if (mMoved.empty() && mEdits.empty()) {
        for (const Job& job : mJobs)
            setBit(mReshooting, job.path, false);
        return;
    }
    mQueryBoxes.clear();
    for (const MovedMobile& m : mMoved)
        for (const Aabb& box : {m.oldBox, m.newBox})
            if (!box.empty()) mQueryBoxes.push_back(box);
    for (const AlbedoEdit& edit : mEdits)
        if (!edit.box.empty()) mQueryBoxes.push_back(edit.box);
    if (mEdits.empty() && mSettings.nearPathMargin > 0.f)
        candidatesNearMobiles(store, grid);
    else
        grid.pathsOverlapping(mQueryBoxes, mCandidates);
    mFirstAffected.resize(mCandidates.size());

    // Paths being re-shot anyway are skipped (-1).
    const float tolerance = kLandingTolerance * glm::length(mSceneBox.extent());
    for (LandingScratch& scratch : mLandingScratch) {
        scratch.relabels.clear();
        scratch.kept = scratch.checked = 0;
    }
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, mCandidates.size(), kTestGrain),
        [&](const tbb::blocked_range<std::size_t>& range) {
            LandingScratch& scratch = mLandingScratch.local();
            walkPathsPrefetched(store, mCandidates, range.begin(), range.end(), [&](std::size_t i) {
                mFirstAffected[i] =
                    testBit(mReshooting, mCandidates[i])
                        ? -1
                        : firstToRetrace(scene, store, mCandidates[i], tolerance, scratch);
            });
        });
    for (const LandingScratch& scratch : mLandingScratch) {
        mRelabels.insert(mRelabels.end(), scratch.relabels.begin(), scratch.relabels.end());
        mStats.landedPaths += scratch.kept;
        mStats.retestedSegments += scratch.checked;
    }
    for (const Job& job : mJobs)
        setBit(mReshooting, job.path, false);
    for (std::size_t i = 0; i < mCandidates.size(); ++i) {
        if (mFirstAffected[i] < 0) continue;
        const std::uint32_t k = std::uint32_t(mFirstAffected[i]);
        mJobs.push_back({mCandidates[i], k, false});
        if (!mEdits.empty() &&
            edited(store.segments.hitEntity[store.segmentIndex(mCandidates[i], k)]))
            ++mStats.repaintedPaths;
    }
    mStats.candidatePaths = mCandidates.size();
    mStats.retracedPaths = mJobs.size() - mStats.reshotPaths;
}

void PhotonUpdateSystem::candidatesNearMobiles(const PhotonStore& store,
                                               const PhotonPathGrid& grid) {
    mCandidates.clear();
    mQueryBoxes.clear(); // of the mobiles that keep no near paths
    for (const MovedMobile& m : mMoved) {
        Aabb need = m.oldBox;
        need.extend(m.newBox);
        if (need.empty()) continue; // out of the world before and after
        NearPaths& near = mNearPaths[m.entity];
        near.idle = 0;
        if (!near.worth && --near.retryIn > 0) {
            for (const Aabb& box : {m.oldBox, m.newBox})
                if (!box.empty()) mQueryBoxes.push_back(box);
            continue;
        }
        // Made anew when the mobile left its box, or when re-traced paths that no longer come
        // near it have grown it by half.
        if (near.worth && !near.box.empty() && contains(near.box, need) &&
            2 * near.paths.size() <= 3 * near.made + kTestGrain) {
            mCandidates.insert(mCandidates.end(), near.paths.begin(), near.paths.end());
            continue;
        }
        near.box = neighbourhoodBox(need, mSettings.nearPathMargin, m.shift);
        grid.pathsOverlapping(near.box, mNearScratch);
        mNearMeets.resize(mNearScratch.size());
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mNearScratch.size(), kTestGrain),
                          [&](const tbb::blocked_range<std::size_t>& range) {
                              walkPathsPrefetched(store, mNearScratch, range.begin(), range.end(),
                                                  [&](std::size_t i) {
                                                      mNearMeets[i] = pathMeetsBox(
                                                          store, mNearScratch[i], near.box);
                                                  });
                          });
        near.paths.clear();
        for (std::size_t i = 0; i < mNearScratch.size(); ++i)
            if (mNearMeets[i]) near.paths.push_back(mNearScratch[i]);
        near.made = near.paths.size();
        ++mStats.nearPathsMade;
        mStats.nearPathsWalked += mNearScratch.size();
        mCandidates.insert(mCandidates.end(), near.paths.begin(), near.paths.end());
        // Worth keeping only where the grid's cells hand out many paths that do not come near
        // (a mobile small against the cells); a big mobile's near paths churn as fast as it
        // re-traces them, and would cost more to keep up than the grid's query.
        near.worth = double(near.made) <= kNearPathsPerGridPath * double(mNearScratch.size());
        if (!near.worth) { // the grid for a while; then another look, since the mobile moves
            near.paths = {};
            near.retryIn = kNearRetryMoves;
        }
    }
    if (!mQueryBoxes.empty()) {
        grid.pathsOverlapping(mQueryBoxes, mNearScratch);
        mCandidates.insert(mCandidates.end(), mNearScratch.begin(), mNearScratch.end());
    }
    if (mMoved.size() > 1) { // increasing, each once, as the grid hands them out
        std::sort(mCandidates.begin(), mCandidates.end());
        mCandidates.erase(std::unique(mCandidates.begin(), mCandidates.end()), mCandidates.end());
    }
}

void PhotonUpdateSystem::updateNearPaths(const PhotonDelta& delta) {
    for (auto it = mNearPaths.begin(); it != mNearPaths.end();) {
        NearPaths& near = it->second;
        if (++near.idle > kNearIdleFrames) {
            it = mNearPaths.erase(it);
            continue;
        }
        mNearAdded.clear();
        for (std::size_t i = 0; near.worth && i < delta.paths.size(); ++i)
            for (std::uint32_t s = delta.newFirst[i]; s < delta.newFirst[i + 1]; ++s)
                if (segmentMeetsBox(delta.newSegments.origin[s], delta.newSegments.direction[s],
                                    delta.newSegments.length[s], near.box)) {
                    mNearAdded.push_back(delta.paths[i]);
                    break;
                }
        if (!mNearAdded.empty()) {
            std::sort(mNearAdded.begin(), mNearAdded.end());
            mNearScratch.clear();
            std::set_union(near.paths.begin(), near.paths.end(), mNearAdded.begin(),
                           mNearAdded.end(), std::back_inserter(mNearScratch));
            std::swap(near.paths, mNearScratch);
        }
        ++it;
    }
}

std::int32_t PhotonUpdateSystem::nextAffected(const RayScene& scene, const PhotonStore& store,
                                              std::uint32_t p, std::uint32_t from) const {
    const PhotonSegments& segments = store.segments;
    const PhotonPath& path = store.paths[p];
    for (std::uint32_t k = from; k < path.count; ++k) {
        const std::size_t s = std::size_t(path.first) + k;
        for (const MovedMobile& m : mMoved)
            if (segments.hitEntity[s] == m.entity) return std::int32_t(k);
        // Same ray, same hit; what changed is how the photon leaves the surface.
        if (!mEdits.empty() && edited(segments.hitEntity[s])) return std::int32_t(k);
        const glm::vec3& o = segments.origin[s];
        const glm::vec3& d = segments.direction[s];
        const glm::vec3 inverse = 1.f / d; // once for every mobile's box
        const float length = segments.length[s];
        // World box, then the tight object-space box (an affine map keeps t), then the
        // mobile's triangles.
        for (const MovedMobile& m : mMoved) {
            if (!m.active || !segmentMeetsBox(o, d, inverse, length, m.newBox)) continue;
            const Ray local = m.toLocal(o, d, length);
            if (segmentMeetsBox(local.origin, local.direction, length, m.objectBox) &&
                scene.occludedByMobile(m.entity, local))
                return std::int32_t(k);
        }
    }
    return -1;
}

const PhotonUpdateSystem::MovedMobile*
PhotonUpdateSystem::mayLand(const PhotonSegments& segments, std::size_t s, float tolerance) const {
    // A translation by `shift` moves the plane with world normal n along a ray of direction d
    // by (n . shift) / (n . d), so the segment would meet it that much further or nearer.
    const Entity hit = segments.hitEntity[s];
    for (const MovedMobile& m : mMoved) {
        if (hit != m.entity) continue;
        const std::uint32_t primitive = segments.hitPrimitive[s];
        if (!m.translated || primitive >= m.translated->facetNormals.size()) return nullptr;
        const glm::vec3 n = m.normalMatrix * m.translated->facetNormals[primitive];
        const float slide = glm::dot(n, m.shift), along = glm::dot(n, segments.direction[s]);
        return std::abs(slide) <= kLandingMargin * tolerance * std::abs(along) ? &m : nullptr;
    }
    return nullptr;
}

bool PhotonUpdateSystem::lands(const RayScene& scene, const PhotonSegments& segments, std::size_t s,
                               const MovedMobile& mobile, float tolerance,
                               std::uint32_t& primitive) const {
    // The mobile at its new pose must meet the ray first on the same plane at the same
    // distance (within the tolerance), and no other moved mobile may cross the segment first.
    // Static geometry and mobiles that did not move cannot be in the way: they were not
    // before. The triangle now hit may be a neighbour in the same plane.
    const glm::vec3& o = segments.origin[s];
    const glm::vec3& d = segments.direction[s];
    const float length = segments.length[s];
    const std::optional<Hit> hit =
        scene.intersectMobileLocal(mobile.entity, mobile.toObject,
                                   mobile.toLocal(o, d, std::numeric_limits<float>::infinity()));
    if (!hit || !(std::abs(hit->t - length) <= tolerance) ||
        !mobile.translated->sameFacet(hit->primitive, segments.hitPrimitive[s]))
        return false;
    for (const MovedMobile& other : mMoved) {
        if (&other == &mobile || !other.active || !segmentMeetsBox(o, d, hit->t, other.newBox))
            continue;
        if (scene.occludedByMobile(other.entity, other.toLocal(o, d, hit->t))) return false;
    }
    primitive = hit->primitive;
    return true;
}

std::int32_t PhotonUpdateSystem::firstToRetrace(const RayScene& scene, const PhotonStore& store,
                                                std::uint32_t p, float tolerance,
                                                LandingScratch& scratch) const {
    const PhotonSegments& segments = store.segments;
    std::int32_t k = nextAffected(scene, store, p, 0);
    if (!mSettings.reuseLandedPaths) return k;
    // One affected segment after another, while each lands where it did.
    while (k >= 0) {
        const std::size_t s = store.segmentIndex(p, std::uint32_t(k));
        if (!mEdits.empty() && edited(segments.hitEntity[s])) break; // it reflects differently
        const MovedMobile* mobile = mayLand(segments, s, tolerance);
        if (!mobile) break;
        ++scratch.checked;
        std::uint32_t primitive = 0;
        if (!lands(scene, segments, s, *mobile, tolerance, primitive)) break; // re-traced from k
        if (primitive != segments.hitPrimitive[s])
            scratch.relabels.push_back({s, primitive, p, std::uint32_t(k)});
        k = nextAffected(scene, store, p, std::uint32_t(k) + 1);
        scratch.kept += k < 0 ? 1 : 0;
    }
    return k;
}

void PhotonUpdateSystem::retrace(const RayScene& scene, PhotonStore& store, PhotonDelta& delta) {
    const std::size_t n = mJobs.size();
    delta.paths.resize(n);
    delta.oldFirst.resize(n + 1);
    for (std::size_t i = 0; i < n; ++i) {
        const Job& job = mJobs[i];
        delta.paths[i] = job.path;
        delta.oldFirst[i + 1] = delta.oldFirst[i] + store.paths[job.path].count - job.k;
    }
    delta.oldSegments.resize(delta.oldFirst[n]);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kCopyGrain),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t i = range.begin(); i < range.end(); ++i) {
                              const PhotonPath& path = store.paths[mJobs[i].path];
                              delta.oldSegments.copyFrom(delta.oldFirst[i], store.segments,
                                                         path.first + mJobs[i].k,
                                                         path.count - mJobs[i].k);
                          }
                      });

    // A re-traced suffix starts with the ray its old one did: the first old segment, just
    // copied next to the others (read from the store, it would be a cache miss per path).
    const PhotonSegments& before = delta.oldSegments;
    mTracer.trace(
        scene, surfaces(), n,
        [&](std::size_t i) {
            const Job& job = mJobs[i];
            if (job.emit)
                return emitPhoton(mEmitters[store.paths[job.path].light], job.path, mSettings.seed);
            const std::size_t s = delta.oldFirst[i];
            return PhotonHead{before.origin[s], before.direction[s], before.power[s], job.path,
                              before.bounce[s]};
        },
        delta.newSegments, delta.newFirst);
    mStats.tracedSegments = delta.newSegments.size();

    // A path that still fits its range is rewritten in place (its tail, if shorter, becomes
    // garbage); a longer one moves to its region's free room or the overflow (PhotonStoreSpace).
    mWrite.resize(n);
    std::size_t end = store.segments.size();
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t count = mJobs[i].k + delta.newFirst[i + 1] - delta.newFirst[i];
        mWrite[i] = mSpace.place(store, mJobs[i].path, count, end);
    }
    store.segments.resize(end);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kCopyGrain),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t i = range.begin(); i < range.end(); ++i) {
                              PhotonPath& path = store.paths[mJobs[i].path];
                              const std::size_t k = mJobs[i].k;
                              const std::size_t suffix = delta.newFirst[i + 1] - delta.newFirst[i];
                              if (mWrite[i] != path.first)
                                  store.segments.copyFrom(mWrite[i], store.segments, path.first, k);
                              store.segments.copyFrom(mWrite[i] + k, delta.newSegments,
                                                      delta.newFirst[i], suffix);
                              path.first = std::uint32_t(mWrite[i]);
                              path.count = std::uint16_t(k + suffix);
                          }
                      });
}

} // namespace qgi
