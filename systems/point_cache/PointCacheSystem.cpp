#include "systems/point_cache/PointCacheSystem.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/profile/StageTimer.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneQueries.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/point_cache/PointCacheFile.h"
#include "systems/point_cache/ShadowCandidates.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <numeric>

namespace qgi {

float PointCacheSystem::MobileBound::radius(const glm::mat4& m) const {
    // Each axis of the transformed box offset d (|d_i| <= e_i) is sum_i M_ji d_i, at most
    // (|M| e)_j: a rotation, a scale or a shear (a turned child of a stretched parent).
    const glm::mat3 linear(m);
    glm::vec3 reach(0.f);
    for (int i = 0; i < 3; ++i)
        reach += glm::abs(linear[i]) * halfExtent[i];
    return glm::length(reach);
}

PointCacheSystem::PointCacheSystem(const PointCacheSettings& settings) : mSettings(settings) {
    validate(settings);
}

PointCacheSystem::~PointCacheSystem() = default;

void PointCacheSystem::build(Registry& registry) {
    RayScene* scene = registry.ctx().find<RayScene>();
    if (!scene) fail("PointCacheSystem::build: the registry has no RayScene");
    const Aabb bounds = staticBounds(registry);
    PointCache& cache = registry.ctx().contains<PointCache>()
                            ? registry.ctx().get<PointCache>()
                            : registry.ctx().emplace<PointCache>();
    const std::uint64_t setVersion = cache.pointSetVersion;
    cache = PointCache{};
    cache.pointSetVersion = setVersion + 1;
    cache.settings = resolvePointCacheSettings(mSettings, bounds);
    const PointCacheSettings& s = cache.settings;
    mLights = findAreaLights(registry, bounds);
    if (mLights.size() > 0xffffu) fail("point cache: more than 65535 area lights");

    const std::uint64_t key = pointCacheKey(registry, s);
    mLoaded = false;
    if (!s.cacheFile.empty() && std::filesystem::exists(s.cacheFile)) {
        try {
            readPointCacheFile(s.cacheFile, key, cache);
            if (cache.lightCount != mLights.size())
                fail("point cache file '", s.cacheFile, "' holds ", cache.lightCount,
                     " lights, the scene has ", mLights.size(), " (stale)");
            if (cache.sampleWords != recordedShadowWords(s.shadowSamples))
                fail("point cache file '", s.cacheFile, "' records ", cache.sampleWords,
                     " words of samples per light, this build ",
                     recordedShadowWords(s.shadowSamples), " (stale)");
            mLoaded = true;
            logInfo("point cache: loaded ", cache.size(), " points from '", s.cacheFile, "'");
        } catch (const Error& error) {
            logWarning(error.what(), "; rebuilding it");
            cache.position.clear();
        }
    }
    if (!mLoaded) {
        mBuildStats = buildPointSet(registry, *scene, s, bounds, cache);
        cache.lightCount = std::uint32_t(mLights.size());
        cache.direct.assign(cache.size(), glm::vec3(0.f));
        cache.visibility.assign(cache.size() * mLights.size(), 1.f);
        cache.sampleWords = recordedShadowWords(s.shadowSamples);
        cache.reached.assign(cache.visibility.size() * cache.sampleWords, 0u);
    }
    mLightStale.assign(cache.sampleWords > 0 ? cache.size() * mLights.size() : 0, 0);
    // A shadow ray runs between points offset from the surface and from the light by
    // photon::offsetFromSurface: at most 1e-4 of the largest coordinate (or 1e-4 m).
    float magnitude = 1.f;
    for (int a = 0; a < 3; ++a)
        magnitude = std::max({magnitude, std::abs(bounds.min[a]), std::abs(bounds.max[a])});
    for (const AreaLight& light : mLights)
        for (int a = 0; a < 3; ++a)
            magnitude = std::max(magnitude, std::abs(light.centre[a]) + light.boundRadius);
    mRaySlack = 2e-4f * magnitude;
    if (!mLoaded) {
        std::vector<std::uint32_t> all(cache.size());
        std::iota(all.begin(), all.end(), 0u);
        shadePoints(*scene, cache, all, /*everyLight=*/true);
        if (!s.cacheFile.empty()) {
            // A file that cannot be written costs the next start a bake, not this one its cache.
            try {
                writePointCacheFile(s.cacheFile, key, cache);
                logInfo("point cache: wrote ", cache.size(), " points to '", s.cacheFile, "'");
            } catch (const Error& e) {
                logWarning(e.what(), "; the point cache is used without a file");
            }
        }
    }
    cache.indirect.assign(cache.size(), glm::vec3(0.f));
    cache.buildGrid();

    mDiscs = std::make_unique<DiscIndex>(scene->device(), DiscIndex::Motion::Static);
    if (cache.size() > 0) mDiscs->build(cache.position, cache.normal, s.detpRadius);
    mPowerSum.assign(cache.size(), glm::dvec3(0.0));
    mIsTouched.assign(cache.size(), 0);
    mQueuedFlag.assign(cache.size(), 0);
    mQueueKey.assign(cache.size(), 0.f);
    mQueue.clear();

    // Where the ray scene has each mobile (it refuses poses it cannot use, keeping the last
    // good one): the shadows the cache holds are of those poses.
    mMobiles.clear();
    registry.view<const MobileMesh, const Mesh>().each(
        [&](Entity e, const MobileMesh&, const Mesh& mesh) {
            if (!scene->isMobile(e)) return;
            Aabb box;
            for (const glm::vec3& p : mesh.positions)
                box.extend(p);
            if (box.empty()) return;
            mMobiles[e] = MobileBound{box.center(), 0.5f * box.extent(), scene->mobilePose(e),
                                      scene->mobileActive(e)};
        });
    mNeedsFull = true;
    mBuilt = true;
}

void PointCacheSystem::shadePoints(const RayScene& scene, PointCache& cache,
                                   std::span<const std::uint32_t> points, bool everyLight) {
    const PointCacheSettings& s = cache.settings;
    const std::size_t lights = mLights.size();
    std::atomic<std::size_t> traced{0}, replayed{0};
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, points.size(), 16),
        [&](const tbb::blocked_range<std::size_t>& range) {
            std::size_t tracedHere = 0, replayedHere = 0;
            for (std::size_t k = range.begin(); k != range.end(); ++k) {
                const std::uint32_t p = points[k];
                const glm::vec3 x = cache.position[p], n = cache.normal[p];
                glm::vec3 sum(0.f);
                for (std::size_t l = 0; l < lights; ++l) {
                    const std::size_t pl = std::size_t(p) * lights + l;
                    const auto light = std::uint32_t(l);
                    LightSample ls;
                    if (cache.sampleWords == 0) {
                        ls = shadeAreaLight(scene, mLights[l], light, x, n, s.shadowSamples, s.seed,
                                            cache.dart[p]);
                        ++tracedHere;
                    } else {
                        const std::span<std::uint32_t> reached(
                            &cache.reached[pl * cache.sampleWords], cache.sampleWords);
                        if (everyLight || mLightStale[pl]) {
                            ls = shadeAreaLight(scene, mLights[l], light, x, n, s.shadowSamples,
                                                s.seed, cache.dart[p], reached);
                            ++tracedHere;
                        } else {
                            ls = replayAreaLight(mLights[l], light, x, n, s.shadowSamples, s.seed,
                                                 cache.dart[p], reached);
                            ++replayedHere;
                        }
                        mLightStale[pl] = 0;
                    }
                    sum += ls.irradiance;
                    cache.visibility[pl] = ls.visibility;
                }
                cache.direct[p] = sum;
            }
            traced += tracedHere;
            replayed += replayedHere;
        });
    mStats.lightsTraced += traced;
    mStats.lightsReplayed += replayed;
}

void PointCacheSystem::estimateIndirect(PointCache& cache, const PhotonSegments& segments,
                                        std::span<const std::uint32_t> indices, double sign) {
    if (indices.empty() || cache.size() == 0) return;
    // Indirect light only: segments that leave a light (bounce 0) are the direct light, which
    // the stored visibility covers.
    mIndirect.clear();
    for (const std::uint32_t s : indices)
        if (segments.bounce[s] != 0) mIndirect.push_back(s);
    mDiscs->collectCrossings(segments, mIndirect, mCrossings);
    mStats.discCrossings += mCrossings.size();
    for (const DiscCrossing& c : mCrossings) {
        mPowerSum[c.disc] += sign * glm::dvec3(segments.power[c.segment]);
        if (!mIsTouched[c.disc]) {
            mIsTouched[c.disc] = 1;
            mTouched.push_back(c.disc);
        }
    }
}

void PointCacheSystem::queueShadowed(const Registry& registry, const RayScene& scene,
                                     const PointCache& cache) {
    std::vector<MobileMove> moves;
    // Moved, taken out or put back (MobileMesh::active): both places, whether it is there
    // now or not, which is conservative. The poses are the ray scene's, which the shadow rays
    // meet: a pose it refused (not finite, not invertible, past kMaxPoseReach) moved nothing.
    const auto follow = [&](Entity e) {
        const auto it = mMobiles.find(e);
        if (it == mMobiles.end() || !scene.isMobile(e)) return;
        MobileBound& m = it->second;
        const glm::mat4& pose = scene.mobilePose(e);
        const bool active = scene.mobileActive(e);
        if (m.pose == pose && m.active == active) return; // nothing changed
        if (!m.active && !active) { // moved while out of the world: shadows nothing
            m.pose = pose;
            return;
        }
        m.active = active;
        moves.push_back(
            MobileMove::make(glm::vec3(m.pose * glm::vec4(m.centre, 1.f)), m.radius(m.pose),
                             glm::vec3(pose * glm::vec4(m.centre, 1.f)), m.radius(pose)));
        m.pose = pose;
    };
    forEachMovedOrSwitched(registry, follow);
    if (moves.empty() || cache.size() == 0) return;
    // Per point: the distance to the nearest moved mobile that may stand between it and a
    // light (old or new pose; +inf where none may). Each such light is marked stale for the
    // point: its recorded samples no longer hold.
    const std::size_t lights = mLights.size();
    std::vector<float> key(cache.size(), std::numeric_limits<float>::infinity());
    mStats.shadowCandidates =
        forEachShadowedPair(cache.grid, cache.position, cache.normal, mLights, moves, mRaySlack,
                            [&](std::uint32_t p, std::uint32_t m, std::uint32_t l) {
                                const glm::vec3 x = cache.position[p];
                                if (cache.sampleWords > 0)
                                    mLightStale[std::size_t(p) * lights + l] = 1;
                                key[p] = std::min({key[p], glm::length(moves[m].after - x),
                                                   glm::length(moves[m].before - x)});
                            });
    for (std::size_t p = 0; p < cache.size(); ++p) {
        if (!std::isfinite(key[p])) continue;
        if (!mQueuedFlag[p]) {
            mQueuedFlag[p] = 1;
            mQueueKey[p] = key[p];
            mQueue.push_back(std::uint32_t(p));
            ++mStats.queued;
        } else {
            mQueueKey[p] = std::min(mQueueKey[p], key[p]);
        }
    }
}

void PointCacheSystem::update(Registry& registry, const FrameContext&) {
    mStats = FrameStats{};
    if (!mBuilt) return;
    PointCache* cache = registry.ctx().find<PointCache>();
    RayScene* scene = registry.ctx().find<RayScene>();
    if (!cache || !scene || cache->size() == 0) return;

    FrameProfiler* profiler = registry.ctx().find<FrameProfiler>();
    // ---- indirect: DETP on the points' discs --------------------------------------------------
    const PhotonStore* store = registry.ctx().find<PhotonStore>();
    const PhotonDelta* delta = registry.ctx().find<PhotonDelta>();
    mTouched.clear();
    if (store) {
        const StageTimer timer(profiler, "indirect", mStats.indirectMs);
        // Each delta is applied once (PhotonDeltaReader); after one missed, in full.
        const PhotonDeltaReader::News news =
            delta ? mDeltaReader.read(*delta) : PhotonDeltaReader::News::Fresh;
        if (news == PhotonDeltaReader::News::Repeated) delta = nullptr;
        const bool full =
            mNeedsFull || news == PhotonDeltaReader::News::AfterGap || (delta && delta->full);
        if (full) {
            mStats.fullIndirect = true;
            std::fill(mPowerSum.begin(), mPowerSum.end(), glm::dvec3(0.0));
            mSegments.clear();
            for (const PhotonPath& path : store->paths)
                for (std::uint32_t k = 0; k < path.count; ++k)
                    mSegments.push_back(path.first + k);
            mStats.deltaSegments = mSegments.size();
            estimateIndirect(*cache, store->segments, mSegments, 1.0);
            mNeedsFull = false;
        } else if (delta && !delta->empty()) {
            mSegments.resize(delta->oldSegments.size());
            std::iota(mSegments.begin(), mSegments.end(), 0u);
            estimateIndirect(*cache, delta->oldSegments, mSegments, -1.0);
            mSegments.resize(delta->newSegments.size());
            std::iota(mSegments.begin(), mSegments.end(), 0u);
            estimateIndirect(*cache, delta->newSegments, mSegments, 1.0);
            mStats.deltaSegments = delta->oldSegments.size() + delta->newSegments.size();
        }
        const double toIrradiance = 1.0 / (glm::pi<double>() * double(cache->settings.detpRadius) *
                                           double(cache->settings.detpRadius));
        if (full) {
            for (std::size_t p = 0; p < cache->size(); ++p)
                cache->indirect[p] = glm::vec3(glm::max(mPowerSum[p] * toIrradiance, 0.0));
            mStats.indirectWritten = cache->size();
        } else {
            for (const std::uint32_t p : mTouched)
                cache->indirect[p] = glm::vec3(glm::max(mPowerSum[p] * toIrradiance, 0.0));
            mStats.indirectWritten = mTouched.size();
        }
        for (const std::uint32_t p : mTouched)
            mIsTouched[p] = 0;
    }

    // ---- soft shadows around moved mobiles, within the budget ---------------------------------
    {
        const StageTimer timer(profiler, "queue", mStats.queueMs);
        queueShadowed(registry, *scene, *cache);
    }
    if (!mQueue.empty()) {
        const StageTimer timer(profiler, "refresh", mStats.refreshMs);
        const std::size_t take = std::min<std::size_t>(mQueue.size(), cache->settings.updateBudget);
        const auto nearer = [&](std::uint32_t a, std::uint32_t b) {
            return mQueueKey[a] < mQueueKey[b] || (mQueueKey[a] == mQueueKey[b] && a < b);
        };
        std::partial_sort(mQueue.begin(), mQueue.begin() + std::ptrdiff_t(take), mQueue.end(),
                          nearer);
        shadePoints(*scene, *cache, std::span<const std::uint32_t>(mQueue).first(take),
                    /*everyLight=*/false);
        for (std::size_t k = 0; k < take; ++k)
            mQueuedFlag[mQueue[k]] = 0;
        mQueue.erase(mQueue.begin(), mQueue.begin() + std::ptrdiff_t(take));
        mStats.refreshed = take;
    }
    mStats.pending = mQueue.size();
    if (mStats.indirectWritten > 0 || mStats.refreshed > 0) ++cache->shadingVersion;
}

} // namespace qgi
