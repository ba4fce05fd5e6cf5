#pragma once

#include "runtime/ecs/Entity.h"
#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"
#include "systems/detp/DiscCrossing.h"
#include "systems/detp/DiscIndex.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointCacheSettings.h"
#include "systems/point_cache/PointSetBuilder.h"
#include "systems/point_cache/PointShading.h"

#include <glm/mat4x4.hpp>

#include <memory>
#include <unordered_map>
#include <vector>

namespace qgi {

struct PhotonSegments;

/** The point cache (seed 003): an AO-steered Poisson point set on the static surfaces, built
 *  once (or loaded from its cache file), holding soft shadows of the area lights, indirect
 *  irradiance from the photon ray set and ambient occlusion, blended at shaded positions.
 *
 *  build(): resolves the settings against the static world's bounds, loads the cache file
 *  when its key matches (a stale or corrupt file is reported, rebuilt and rewritten), or
 *  builds the point set (buildPointSet) and fills AO and the area lights' soft shadows
 *  (shadeAreaLight, parallel over points); builds the query grid and the DETP disc index of
 *  the points' own discs (radius detpRadius, seed 000 section 2.7); emplaces the PointCache
 *  world resource.
 *
 *  update(), the `point.cache` schedule entry:
 *   - indirect: when the photon set was (re)built (first frame, PhotonDelta::full) or a
 *     delta was missed (PhotonDeltaReader: each is applied once, by its sequence) every
 *     point's disc counts every stored segment after its first bounce (DETP, as the vertices'
 *     irradiance); otherwise the delta's old segments are subtracted and its new ones added
 *     (DETP is additive per segment): exact, cheap, and a point no delta segment crosses is
 *     not written;
 *   - soft shadows: for each mobile whose WorldTransform or MobileMesh::active changed, every
 *     point from which the mobile's bounding sphere (at the old or the new pose) may meet the
 *     cone of shadow rays to a light's bounding sphere (distanceBeyondCone; lights wholly
 *     below the point's horizon skipped) is queued, keyed by its distance to the mobile; then at
 *     most updateBudget queued points, nearest first (ties by index), are re-shaded; the
 *     rest wait for the next frames. A re-shaded point casts shadow rays only towards the
 *     lights that test passed for (marked stale since it was last shaded); its other lights
 *     are replayed from the samples it recorded (PointCache::reached), which no moved mobile
 *     can have blocked or unblocked, so the result is bit for bit a full re-shade.
 *  Shading uses random numbers keyed by the point, never by the frame: identical frames give
 *  bit-identical values, and a point that is not refreshed keeps its value exactly.
 *
 *  Reads:  ctx<RayScene>, ctx<const PhotonStore>, ctx<const PhotonDelta> (when present),
 *          const StaticMesh, const MobileMesh and const WorldTransform (and their change
 *          lists), const Mesh, const Material, lights (cache key, particles)
 *  Writes: ctx<PointCache> (emplaced by build(); shading arrays each frame), the cache file */
class PointCacheSystem {
public:
    struct FrameStats {
        bool fullIndirect = false;       ///< every point's indirect re-estimated
        std::size_t deltaSegments = 0;   ///< delta segments traced against the point discs
        std::size_t discCrossings = 0;   ///< (segment, point disc) crossings they made
        std::size_t indirectWritten = 0; ///< points whose indirect value changed
        std::size_t shadowCandidates = 0; ///< points tested against the moved mobiles
        std::size_t queued = 0;          ///< points newly queued for soft-shadow refresh
        std::size_t refreshed = 0;       ///< points re-shaded this frame (<= updateBudget)
        std::size_t lightsTraced = 0;    ///< of their (point, light) pairs: cast shadow rays
        std::size_t lightsReplayed = 0;  ///< ... and replayed from the recorded samples
        std::size_t pending = 0;         ///< queued points left for later frames
        // Wall-clock milliseconds of the stages (also nested under point.cache in the profile).
        double indirectMs = 0; ///< the photon delta through the points' discs
        double queueMs = 0;    ///< finding the points a moved mobile may shadow
        double refreshMs = 0;  ///< re-shading the budget's worth of them
    };

    /// Throws qgi::Error for settings out of range.
    explicit PointCacheSystem(const PointCacheSettings& settings);
    PointCacheSystem(const PointCacheSystem&) = delete;
    PointCacheSystem& operator=(const PointCacheSystem&) = delete;
    ~PointCacheSystem();

    /// Set-up once the scene, its WorldTransforms and the RayScene exist. Throws qgi::Error on
    /// bad settings for this scene or an unwritable cache file.
    void build(Registry& registry);
    /// The frame. Never throws.
    void update(Registry& registry, const FrameContext& frame);

    const PointCacheSettings& settings() const { return mSettings; }
    const PointSetStats& buildStats() const { return mBuildStats; }
    bool loadedFromFile() const { return mLoaded; }
    const FrameStats& lastFrame() const { return mStats; }
    const std::vector<AreaLight>& areaLights() const { return mLights; }

private:
    /// Shades `points`: every light with shadow rays when `everyLight` or nothing is recorded
    /// (PointCache::sampleWords 0), else only the lights marked stale, the others replayed.
    void shadePoints(const RayScene& scene, PointCache& cache,
                     std::span<const std::uint32_t> points, bool everyLight);
    void estimateIndirect(PointCache& cache, const PhotonSegments& segments,
                          std::span<const std::uint32_t> indices, double sign);
    void queueShadowed(const Registry& registry, const RayScene& scene, const PointCache& cache);

    /// A mobile's object-space box, and where the ray scene last had it.
    struct MobileBound {
        glm::vec3 centre{0.f};     ///< object space
        glm::vec3 halfExtent{0.f}; ///< object space
        glm::mat4 pose{1.f};       ///< the ray scene's pose when last seen
        bool active = true;        ///< the ray scene's MobileMesh::active when last seen
        /// Radius of a ball around pose x centre holding the box under `pose`, shear included:
        /// the half-diagonal of the transformed box, |M| e.
        float radius(const glm::mat4& pose) const;
    };

    PointCacheSettings mSettings; ///< as given; resolved ones live in the PointCache
    PointSetStats mBuildStats;
    bool mLoaded = false;
    bool mBuilt = false;
    bool mNeedsFull = true;
    PhotonDeltaReader mDeltaReader;
    FrameStats mStats;
    std::vector<AreaLight> mLights;
    std::unique_ptr<DiscIndex> mDiscs;
    std::vector<glm::dvec3> mPowerSum; ///< W crossing each point's disc
    std::unordered_map<Entity, MobileBound> mMobiles;

    std::vector<std::uint8_t> mQueuedFlag; ///< per point
    std::vector<float> mQueueKey;          ///< per point: distance to the mobile when queued
    std::vector<std::uint32_t> mQueue;

    // With the samples recorded (PointCache::reached), a refreshed point casts rays only
    // towards the lights a moved mobile may have come between.
    std::vector<std::uint8_t> mLightStale; ///< per (point, light): a move may have changed it
    float mRaySlack = 0.f; ///< how far a shadow ray's ends lie from the point and the light, m

    std::vector<std::uint32_t> mSegments;
    std::vector<std::uint32_t> mIndirect; ///< scratch: the segments estimateIndirect counts
    std::vector<DiscCrossing> mCrossings;
    std::vector<std::uint32_t> mTouched;
    std::vector<std::uint8_t> mIsTouched;
};

} // namespace qgi
