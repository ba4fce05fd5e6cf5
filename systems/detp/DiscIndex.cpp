#include "systems/detp/DiscIndex.h"

#include "runtime/core/Error.h"
#include "runtime/raytrace/EmbreeDevice.h"
#include "systems/photon_update/PhotonStore.h"

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace qgi {
namespace {

/// Embree's discs are this much wider than the real ones (see the class comment).
constexpr float kEmbreeWiden = 1.01f;
/// Segments ahead whose fields traceChunk requests before it needs them.
constexpr std::size_t kPrefetchAhead = 8;

bool isFinite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

} // namespace

struct DiscIndex::QueryContext {
    RTCIntersectContext embree; // first: Embree hands the filter a pointer to it
    const DiscIndex* index = nullptr;
    const PhotonSegments* segments = nullptr;
    const std::uint32_t* indices = nullptr;
    const float* beyond = nullptr; ///< per index, or null: whole segments
    std::size_t count = 0;
    std::vector<std::uint64_t>* pairs = nullptr; // the chunk's output
};

DiscIndex::DiscIndex(EmbreeDevice& device, Motion motion) : mDevice(device), mMotion(motion) {}

void DiscIndex::build(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
                      float radius) {
    QGI_ASSERT(centers.size() == normals.size(), "one normal per disc centre");
    if (!(radius > 0.f) || !std::isfinite(radius))
        fail("DiscIndex: radius ", radius, " must be a positive finite number of metres");
    for (std::size_t i = 0; i < centers.size(); ++i)
        if (!isFinite(centers[i]) || !isFinite(normals[i]))
            fail("DiscIndex: disc ", i, " has a non-finite centre or normal");

    mDevice.takeError(); // earlier errors were logged; this build reports only its own
    const RTCDevice device = mDevice.handle();
    SceneHandle scene(rtcNewScene(device));
    rtcSetSceneBuildQuality(scene.get(), mMotion == Motion::Static ? RTC_BUILD_QUALITY_HIGH
                                                                   : RTC_BUILD_QUALITY_LOW);
    if (mMotion == Motion::Moving) rtcSetSceneFlags(scene.get(), RTC_SCENE_FLAG_DYNAMIC);

    // Embree shares these buffers; they are moved into the members only once the build has
    // succeeded (moving a vector keeps its storage), so a failure leaves the old index intact.
    const std::size_t count = centers.size();
    std::vector<glm::vec4> discs(count);
    std::vector<glm::vec3> padded(count + 1, glm::vec3(0.f));
    for (std::size_t i = 0; i < count; ++i) {
        discs[i] = glm::vec4(centers[i], radius * kEmbreeWiden);
        padded[i] = normals[i];
    }
    GeometryHandle geometry;
    if (count > 0) {
        geometry = GeometryHandle(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_ORIENTED_DISC_POINT));
        rtcSetSharedGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4,
                                   discs.data(), 0, sizeof(glm::vec4), count);
        rtcSetSharedGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_NORMAL, 0, RTC_FORMAT_FLOAT3,
                                   padded.data(), 0, sizeof(glm::vec3), count);
        rtcSetGeometryOccludedFilterFunction(geometry.get(), &DiscIndex::recordCrossings);
        rtcCommitGeometry(geometry.get());
        rtcAttachGeometry(scene.get(), geometry.get());
    }
    rtcCommitScene(scene.get());
    if (const auto error = mDevice.takeError())
        fail("DiscIndex: Embree failed to build ", count, " discs: ", error->message);
    mScene = std::move(scene);
    mGeometry = std::move(geometry);
    mDiscs = std::move(discs);
    mNormals = std::move(padded);
    mRadius = radius;
    mCount = count;
}

void DiscIndex::move(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals) {
    QGI_ASSERT(centers.size() == mCount && normals.size() == mCount,
               "DiscIndex::move keeps the disc count");
    if (mCount == 0) return;
    for (std::size_t i = 0; i < mCount; ++i) {
        QGI_ASSERT(isFinite(centers[i]) && isFinite(normals[i]), "non-finite disc ", i);
        mDiscs[i] = glm::vec4(centers[i], mRadius * kEmbreeWiden);
        mNormals[i] = normals[i];
    }
    rtcUpdateGeometryBuffer(mGeometry.get(), RTC_BUFFER_TYPE_VERTEX, 0);
    rtcUpdateGeometryBuffer(mGeometry.get(), RTC_BUFFER_TYPE_NORMAL, 0);
    rtcCommitGeometry(mGeometry.get());
    rtcCommitScene(mScene.get());
}

void DiscIndex::recordCrossings(const RTCFilterFunctionNArguments* args) {
    const auto* query = reinterpret_cast<const QueryContext*>(args->context);
    const DiscIndex& index = *query->index;
    const PhotonSegments& segments = *query->segments;
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        args->valid[i] = 0; // rejected: traversal goes on to the next disc
        const std::uint32_t position = RTCRayN_id(args->ray, args->N, i);
        const std::uint32_t disc = RTCHitN_primID(args->hit, args->N, i);
        const std::uint32_t s = query->indices[position];
        const float t = discCrossing(segments.origin[s], segments.direction[s], segments.length[s],
                                     index.center(disc), index.mNormals[disc], index.mRadius);
        if (t < 0.f) continue;
        // The cut copy counts t <= beyond + tolerance (the same float expression): skip those.
        if (query->beyond && !(t > query->beyond[position] + kDiscEndTolerance * index.mRadius))
            continue;
        query->pairs->push_back(std::uint64_t(position) << 32 | disc);
    }
}

void DiscIndex::traceChunk(const QueryContext& query, std::size_t chunk) {
    std::vector<std::uint64_t>& pairs = mChunkPairs[chunk];
    pairs.clear();
    QueryContext context = query;
    context.pairs = &pairs;

    const PhotonSegments& segments = *query.segments;
    const std::size_t begin = chunk * kChunkSize;
    const std::size_t end = std::min(query.count, begin + kChunkSize);
    const float slack = kEmbreeSlack * mRadius;
    const float tail = kDiscEndTolerance * mRadius + 2.f * slack;

    for (std::size_t k = begin; k < end; ++k) {
        // The indices may point anywhere in a large store (a moved mobile's segments): ask
        // for a later segment's fields ahead of use.
        if (k + kPrefetchAhead < end) {
            const std::uint32_t ahead = query.indices[k + kPrefetchAhead];
            __builtin_prefetch(&segments.origin[ahead]);
            __builtin_prefetch(&segments.direction[ahead]);
            __builtin_prefetch(&segments.length[ahead]);
        }
        const std::uint32_t s = query.indices[k];
        const glm::vec3& d = segments.direction[s];
        const glm::vec3 origin = segments.origin[s] - slack * d;
        RTCRay ray;
        ray.org_x = origin.x;
        ray.org_y = origin.y;
        ray.org_z = origin.z;
        // Embree's t is the segment's t + slack: start where the counted part starts.
        ray.tnear =
            query.beyond ? std::max(0.f, query.beyond[k] + kDiscEndTolerance * mRadius) : 0.f;
        ray.dir_x = d.x;
        ray.dir_y = d.y;
        ray.dir_z = d.z;
        ray.time = 0.f;
        ray.tfar = segments.length[s] + tail; // +inf stays +inf
        ray.mask = ~0u;
        ray.id = std::uint32_t(k);
        ray.flags = 0;
        rtcOccluded1(mScene.get(), &context.embree, &ray);
    }
    // Canonical order; a disc Embree reports twice for one segment is counted once.
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
}

void DiscIndex::collectCrossings(const PhotonSegments& segments,
                                 std::span<const std::uint32_t> indices,
                                 std::vector<DiscCrossing>& out, std::span<const float> beyond) {
    QGI_ASSERT(beyond.empty() || beyond.size() == indices.size(), "one length per index");
    out.clear();
    if (mCount == 0 || indices.empty()) return;
    const std::size_t chunks = (indices.size() + kChunkSize - 1) / kChunkSize;
    if (mChunkPairs.size() < chunks) mChunkPairs.resize(chunks);

    QueryContext query;
    rtcInitIntersectContext(&query.embree);
    query.index = this;
    query.segments = &segments;
    query.indices = indices.data();
    query.beyond = beyond.empty() ? nullptr : beyond.data();
    query.count = indices.size();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t c = range.begin(); c != range.end(); ++c)
                              traceChunk(query, c);
                      });

    std::size_t total = 0;
    for (std::size_t c = 0; c < chunks; ++c)
        total += mChunkPairs[c].size();
    out.resize(total);
    std::size_t j = 0;
    for (std::size_t c = 0; c < chunks; ++c)
        for (const std::uint64_t pair : mChunkPairs[c])
            out[j++] = {indices[pair >> 32], std::uint32_t(pair)};
}

} // namespace qgi
