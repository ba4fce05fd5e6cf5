#include "systems/detp/DiscIndex.h"

#include "runtime/core/Error.h"
#include "runtime/raytrace/EmbreeDevice.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonStore.h"

#include <glm/common.hpp>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <tuple>

namespace qgi {
namespace {

/// Embree's discs are this much wider than the real ones (see the class comment).
constexpr float kEmbreeWiden = 1.01f;
/// Segments ahead whose fields traceChunk requests before it needs them.
constexpr std::size_t kPrefetchAhead = 8;
/// A plane's rectangles overlap their neighbours by this fraction of a cell, so that a
/// crossing on a shared edge meets at least one of them whatever Embree's rounding.
constexpr float kRectangleOverlap = 0.05f;
/// The two triangles of a rectangle are this fraction larger than its halves (see
/// splitIntoPlanes), so that they overlap across its diagonal.
constexpr float kDiagonalOverlap = 0.02f;
/// A plane becomes a patch only while its grid has at most this many cells per disc (plus
/// kGridCellsSpare): discs strewn thinly over a large plane stay points.
constexpr std::size_t kGridCellsPerDisc = 64;
constexpr std::size_t kGridCellsSpare = 1024;
/// Grid sides and cell totals stay far inside what float cell indices and uint32 offsets hold.
constexpr double kMaxGridSide = double(1 << 22);
constexpr double kMaxCells = double(std::uint32_t(1) << 31);
bool isFinite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

/// The axis a normal lies along exactly (one component is +-1, the others zero), or -1.
int exactAxis(const glm::vec3& n) {
    for (int a = 0; a < 3; ++a)
        if ((n[a] == 1.f || n[a] == -1.f) && n[(a + 1) % 3] == 0.f && n[(a + 2) % 3] == 0.f)
            return a;
    return -1;
}

std::uint32_t bitsOf(float f) {
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    return bits;
}

} // namespace

void DiscIndex::updateBox() {
    // Every disc with its widening, and the slack of Embree's segments, well inside; rounding
    // of the box itself (a few ulps of the largest coordinate) far inside the pad.
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
    for (const glm::vec3& c : mCenters) {
        lo = glm::min(lo, glm::dvec3(c));
        hi = glm::max(hi, glm::dvec3(c));
    }
    const glm::dvec3 pad = glm::dvec3(2.0 * mRadius) + 1e-5 * (glm::abs(lo) + glm::abs(hi));
    mBoxMin = lo - pad;
    mBoxMax = hi + pad;
}

struct DiscIndex::QueryContext {
    RTCIntersectContext embree; // first: Embree hands the filter a pointer to it
    const DiscIndex* index = nullptr;
    const PhotonSegments* segments = nullptr;
    const std::uint32_t* indices = nullptr;
    const float* beyond = nullptr; ///< per index, or null: whole segments
    std::size_t count = 0;
    std::vector<std::uint64_t>* pairs = nullptr; // the chunk's output
};

struct DiscIndex::Layout {
    std::vector<std::uint32_t> pointIds;
    std::vector<Plane> planes;
    std::vector<std::uint32_t> cellStart{0};
    std::vector<std::uint32_t> cellDiscs;
    std::vector<glm::vec3> cellCenters;
    std::vector<Rectangle> rectangles;
    std::vector<glm::vec4> patchVertices;
    std::vector<glm::uvec3> patchTriangles;
};

DiscIndex::DiscIndex(EmbreeDevice& device, Motion motion) : mDevice(device), mMotion(motion) {}

void DiscIndex::splitIntoPlanes(std::span<const glm::vec3> centers,
                                std::span<const glm::vec3> normals, float radius, Layout& out) {
    // Group the discs of exactly axis-aligned normal by (normal, coordinate along the axis),
    // bit for bit; the sort keeps the groups, and the discs in them, in a fixed order.
    struct Keyed {
        std::array<std::uint32_t, 4> key; // normal's bits, coordinate's bits
        std::uint32_t disc;
        bool operator<(const Keyed& o) const {
            return std::tie(key, disc) < std::tie(o.key, o.disc);
        }
    };
    std::vector<Keyed> keyed;
    std::vector<std::uint8_t> planar(centers.size(), 0);
    for (std::uint32_t i = 0; i < centers.size(); ++i) {
        const int axis = exactAxis(normals[i]);
        if (axis < 0) continue;
        // + 0.f: a negative zero joins the positive one (the rule gives the same answers).
        keyed.push_back({{bitsOf(normals[i].x + 0.f), bitsOf(normals[i].y + 0.f),
                          bitsOf(normals[i].z + 0.f), bitsOf(centers[i][axis] + 0.f)},
                         i});
    }
    std::sort(keyed.begin(), keyed.end());

    const float cell = kPlaneCellRadii * radius;
    const float overlap = kRectangleOverlap * cell;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> cellOf; // (cell, disc)
    std::vector<std::uint8_t> active;
    for (std::size_t first = 0; first < keyed.size();) {
        std::size_t last = first;
        while (last < keyed.size() && keyed[last].key == keyed[first].key)
            ++last;
        const std::span<const Keyed> group(keyed.data() + first, last - first);
        first = last;
        if (group.size() < kMinPlaneDiscs) continue;

        Plane plane;
        const glm::vec3 normal = normals[group[0].disc];
        plane.axis = std::uint8_t(exactAxis(normal));
        plane.u = std::uint8_t((plane.axis + 1) % 3);
        plane.v = std::uint8_t((plane.axis + 2) % 3);
        plane.normal = normal;
        plane.coordinate = centers[group[0].disc][plane.axis];
        glm::vec2 lo(std::numeric_limits<float>::max()), hi(std::numeric_limits<float>::lowest());
        for (const Keyed& k : group) {
            const glm::vec2 uv(centers[k.disc][plane.u], centers[k.disc][plane.v]);
            lo = glm::min(lo, uv);
            hi = glm::max(hi, uv);
        }
        // One empty cell all around: the 3 x 3 neighbourhood of a disc's cell is in the grid.
        const double columns = std::floor(double(hi.x - lo.x) / cell) + 3.0;
        const double rows = std::floor(double(hi.y - lo.y) / cell) + 3.0;
        if (!(columns * rows <= double(kGridCellsPerDisc * group.size() + kGridCellsSpare)) ||
            columns > kMaxGridSide || rows > kMaxGridSide ||
            double(out.cellStart.size()) + columns * rows > kMaxCells)
            continue;
        plane.columns = std::uint32_t(columns);
        plane.rows = std::uint32_t(rows);
        plane.corner = lo - glm::vec2(cell);
        plane.firstCell = std::uint32_t(out.cellStart.size() - 1);

        const auto cellIndex = [&](const glm::vec3& c) {
            const auto column = std::uint32_t(std::clamp(
                std::floor((c[plane.u] - plane.corner.x) / cell), 1.f, float(plane.columns - 2)));
            const auto row = std::uint32_t(std::clamp(
                std::floor((c[plane.v] - plane.corner.y) / cell), 1.f, float(plane.rows - 2)));
            return row * plane.columns + column;
        };
        cellOf.clear();
        for (const Keyed& k : group)
            cellOf.emplace_back(cellIndex(centers[k.disc]), k.disc);
        std::sort(cellOf.begin(), cellOf.end());
        const std::size_t cells = std::size_t(plane.columns) * plane.rows;
        std::size_t next = 0;
        active.assign(cells, 0);
        for (std::uint32_t c = 0; c < cells; ++c) {
            for (; next < cellOf.size() && cellOf[next].first == c; ++next) {
                out.cellDiscs.push_back(cellOf[next].second);
                out.cellCenters.push_back(centers[cellOf[next].second]);
                planar[cellOf[next].second] = 1;
            }
            out.cellStart.push_back(std::uint32_t(out.cellDiscs.size()));
        }
        // Cells within one of a non-empty cell: wherever a segment can cross within a radius
        // of one of the plane's discs.
        for (std::uint32_t row = 1; row + 1 < plane.rows; ++row)
            for (std::uint32_t column = 1; column + 1 < plane.columns; ++column) {
                const std::size_t c = std::size_t(row) * plane.columns + column;
                if (out.cellStart[plane.firstCell + c] == out.cellStart[plane.firstCell + c + 1])
                    continue;
                for (std::uint32_t r = row - 1; r <= row + 1; ++r)
                    for (std::uint32_t q = column - 1; q <= column + 1; ++q)
                        active[std::size_t(r) * plane.columns + q] = 1;
            }
        // Rectangles: runs of active cells along each row, merged with the run of the same
        // columns in the row below.
        struct Run {
            std::uint32_t first, last, rectangle;
        };
        std::vector<Run> above, here;
        const auto planeIndex = std::uint32_t(out.planes.size());
        for (std::uint32_t row = 0; row < plane.rows; ++row) {
            here.clear();
            for (std::uint32_t column = 0; column < plane.columns;) {
                if (!active[std::size_t(row) * plane.columns + column]) {
                    ++column;
                    continue;
                }
                Run run{column, column, 0};
                while (run.last + 1 < plane.columns &&
                       active[std::size_t(row) * plane.columns + run.last + 1])
                    ++run.last;
                column = run.last + 1;
                const float v1 = plane.corner.y + float(row + 1) * cell + overlap;
                const auto same = std::find_if(above.begin(), above.end(), [&](const Run& a) {
                    return a.first == run.first && a.last == run.last;
                });
                if (same != above.end()) { // extend the rectangle one row down
                    run.rectangle = same->rectangle;
                    out.rectangles[run.rectangle].hi.y = v1;
                } else {
                    run.rectangle = std::uint32_t(out.rectangles.size());
                    out.rectangles.push_back(
                        {planeIndex,
                         {plane.corner.x + float(run.first) * cell - overlap,
                          plane.corner.y + float(row) * cell - overlap},
                         {plane.corner.x + float(run.last + 1) * cell + overlap, v1}});
                }
                here.push_back(run);
            }
            std::swap(above, here);
        }
        out.planes.push_back(plane);
    }
    for (std::uint32_t i = 0; i < centers.size(); ++i)
        if (!planar[i]) out.pointIds.push_back(i);

    // Each rectangle as two right triangles, each stretched about its right-angle corner so
    // that they overlap across the diagonal: a crossing on the diagonal meets at least one of
    // them whatever Embree's rounding (its triangle test is not watertight). Triangle 2i and
    // 2i + 1 are rectangle i's.
    for (const Rectangle& r : out.rectangles) {
        const Plane& plane = out.planes[r.plane];
        const auto vertex = [&](glm::vec2 uv) {
            glm::vec4 p(0.f);
            p[plane.axis] = plane.coordinate;
            p[plane.u] = uv.x;
            p[plane.v] = uv.y;
            return p;
        };
        const glm::vec2 size = (r.hi - r.lo) * (1.f + kDiagonalOverlap);
        const auto base = std::uint32_t(out.patchVertices.size());
        // Right angle at (hi.x, lo.y), then at (lo.x, hi.y).
        out.patchVertices.push_back(vertex({r.hi.x - size.x, r.lo.y}));
        out.patchVertices.push_back(vertex({r.hi.x, r.lo.y}));
        out.patchVertices.push_back(vertex({r.hi.x, r.lo.y + size.y}));
        out.patchVertices.push_back(vertex({r.lo.x + size.x, r.hi.y}));
        out.patchVertices.push_back(vertex({r.lo.x, r.hi.y}));
        out.patchVertices.push_back(vertex({r.lo.x, r.hi.y - size.y}));
        out.patchTriangles.emplace_back(base, base + 1, base + 2);
        out.patchTriangles.emplace_back(base + 3, base + 4, base + 5);
    }
}

void DiscIndex::build(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
                      float radius) {
    QGI_ASSERT(centers.size() == normals.size(), "one normal per disc centre");
    if (!(radius > 0.f) || !std::isfinite(radius))
        fail("DiscIndex: radius ", radius, " must be a positive finite number of metres");
    for (std::size_t i = 0; i < centers.size(); ++i)
        if (!isFinite(centers[i]) || !isFinite(normals[i]))
            fail("DiscIndex: disc ", i, " has a non-finite centre or normal");

    Layout layout;
    if (mMotion == Motion::Static) {
        splitIntoPlanes(centers, normals, radius, layout);
    } else {
        layout.pointIds.resize(centers.size());
        std::iota(layout.pointIds.begin(), layout.pointIds.end(), 0u);
    }

    mDevice.takeError(); // earlier errors were logged; this build reports only its own
    const RTCDevice device = mDevice.handle();
    if (rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) != 0)
        fail("DiscIndex: this Embree was built with backface culling; the disc index needs "
             "two-sided triangles");
    SceneHandle scene(rtcNewScene(device));
    rtcSetSceneBuildQuality(scene.get(), mMotion == Motion::Static ? RTC_BUILD_QUALITY_HIGH
                                                                   : RTC_BUILD_QUALITY_LOW);
    if (mMotion == Motion::Moving) rtcSetSceneFlags(scene.get(), RTC_SCENE_FLAG_DYNAMIC);

    // Embree shares these buffers; they are moved into the members only once the build has
    // succeeded (moving a vector keeps its storage), so a failure leaves the old index intact.
    const std::size_t points = layout.pointIds.size();
    std::vector<glm::vec4> discs(points);
    std::vector<glm::vec3> padded(points + 1, glm::vec3(0.f));
    for (std::size_t i = 0; i < points; ++i) {
        discs[i] = glm::vec4(centers[layout.pointIds[i]], radius * kEmbreeWiden);
        padded[i] = normals[layout.pointIds[i]];
    }
    GeometryHandle geometry;
    if (points > 0) {
        geometry = GeometryHandle(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_ORIENTED_DISC_POINT));
        rtcSetSharedGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4,
                                   discs.data(), 0, sizeof(glm::vec4), points);
        rtcSetSharedGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_NORMAL, 0, RTC_FORMAT_FLOAT3,
                                   padded.data(), 0, sizeof(glm::vec3), points);
        rtcSetGeometryOccludedFilterFunction(geometry.get(), &DiscIndex::recordCrossings);
        rtcCommitGeometry(geometry.get());
        rtcAttachGeometry(scene.get(), geometry.get());
    }
    GeometryHandle planeGeometry;
    if (!layout.rectangles.empty()) {
        planeGeometry = GeometryHandle(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE));
        rtcSetSharedGeometryBuffer(planeGeometry.get(), RTC_BUFFER_TYPE_VERTEX, 0,
                                   RTC_FORMAT_FLOAT3, layout.patchVertices.data(), 0,
                                   sizeof(glm::vec4), layout.patchVertices.size());
        rtcSetSharedGeometryBuffer(planeGeometry.get(), RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                   layout.patchTriangles.data(), 0, sizeof(glm::uvec3),
                                   layout.patchTriangles.size());
        rtcSetGeometryOccludedFilterFunction(planeGeometry.get(), &DiscIndex::recordPlaneCrossings);
        rtcCommitGeometry(planeGeometry.get());
        rtcAttachGeometry(scene.get(), planeGeometry.get());
    }
    rtcCommitScene(scene.get());
    if (const auto error = mDevice.takeError())
        fail("DiscIndex: Embree failed to build ", centers.size(), " discs: ", error->message);
    mScene = std::move(scene);
    mGeometry = std::move(geometry);
    mPlaneGeometry = std::move(planeGeometry);
    mCenters.assign(centers.begin(), centers.end());
    mNormals.assign(normals.begin(), normals.end());
    mPointDiscs = std::move(discs);
    mPointNormals = std::move(padded);
    mPointIds = std::move(layout.pointIds);
    mPlanes = std::move(layout.planes);
    mCellStart = std::move(layout.cellStart);
    mCellDiscs = std::move(layout.cellDiscs);
    mCellCenters = std::move(layout.cellCenters);
    mRectangles = std::move(layout.rectangles);
    mPatchVertices = std::move(layout.patchVertices);
    mPatchTriangles = std::move(layout.patchTriangles);
    mRadius = radius;
    updateBox();
}

void DiscIndex::move(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals) {
    QGI_ASSERT(mMotion == Motion::Moving, "DiscIndex::move needs Motion::Moving");
    QGI_ASSERT(centers.size() == size() && normals.size() == size(),
               "DiscIndex::move keeps the disc count");
    if (size() == 0) return;
    for (std::size_t i = 0; i < size(); ++i) {
        QGI_ASSERT(isFinite(centers[i]) && isFinite(normals[i]), "non-finite disc ", i);
        mCenters[i] = centers[i];
        mNormals[i] = normals[i];
        mPointDiscs[i] = glm::vec4(centers[i], mRadius * kEmbreeWiden);
        mPointNormals[i] = normals[i];
    }
    updateBox();
    rtcUpdateGeometryBuffer(mGeometry.get(), RTC_BUFFER_TYPE_VERTEX, 0);
    rtcUpdateGeometryBuffer(mGeometry.get(), RTC_BUFFER_TYPE_NORMAL, 0);
    rtcCommitGeometry(mGeometry.get());
    rtcCommitScene(mScene.get());
}

void DiscIndex::consider(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                         std::uint32_t disc, const glm::vec3& center, const glm::vec3& normal) {
    const DiscIndex& index = *query.index;
    const PhotonSegments& segments = *query.segments;
    const float t = discCrossing(segments.origin[s], segments.direction[s], segments.length[s],
                                 center, normal, index.mRadius);
    if (t < 0.f) return;
    // The cut copy counts t <= beyond + tolerance (the same float expression): skip those.
    if (query.beyond && !(t > query.beyond[position] + kDiscEndTolerance * index.mRadius)) return;
    query.pairs->push_back(std::uint64_t(position) << 32 | disc);
}

void DiscIndex::recordCrossings(const RTCFilterFunctionNArguments* args) {
    const auto* query = reinterpret_cast<const QueryContext*>(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        args->valid[i] = 0; // rejected: traversal goes on to the next disc
        const std::uint32_t position = RTCRayN_id(args->ray, args->N, i);
        const DiscIndex& index = *query->index;
        const std::uint32_t disc = index.mPointIds[RTCHitN_primID(args->hit, args->N, i)];
        consider(*query, position, query->indices[position], disc, index.mCenters[disc],
                 index.mNormals[disc]);
    }
}

void DiscIndex::recordPlaneCrossings(const RTCFilterFunctionNArguments* args) {
    const auto* query = reinterpret_cast<const QueryContext*>(args->context);
    const DiscIndex& index = *query->index;
    const PhotonSegments& segments = *query->segments;
    const float cell = kPlaneCellRadii * index.mRadius;
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        args->valid[i] = 0; // rejected: traversal goes on
        const std::uint32_t position = RTCRayN_id(args->ray, args->N, i);
        const std::uint32_t s = query->indices[position];
        const std::uint32_t rectangle = RTCHitN_primID(args->hit, args->N, i) / 2;
        const Plane& plane = index.mPlanes[index.mRectangles[rectangle].plane];
        const glm::vec3& o = segments.origin[s];
        const glm::vec3& d = segments.direction[s];
        // From behind or parallel: crossesDisc() turns down every disc of the plane.
        if (!(d[plane.axis] * plane.normal[plane.axis] < 0.f)) continue;
        const float t = (plane.coordinate - o[plane.axis]) / d[plane.axis];
        const float u = o[plane.u] + t * d[plane.u], v = o[plane.v] + t * d[plane.v];
        // A crossing point that is not finite is no disc's: crossesDisc() would say so too.
        if (!std::isfinite(u) || !std::isfinite(v)) continue;
        const auto column = std::uint32_t(
            std::clamp(std::floor((u - plane.corner.x) / cell), 0.f, float(plane.columns - 1)));
        const auto row = std::uint32_t(
            std::clamp(std::floor((v - plane.corner.y) / cell), 0.f, float(plane.rows - 1)));
        const std::uint32_t c0 = column > 0 ? column - 1 : 0;
        const std::uint32_t c1 = std::min(column + 1, plane.columns - 1);
        const std::uint32_t r0 = row > 0 ? row - 1 : 0;
        const std::uint32_t r1 = std::min(row + 1, plane.rows - 1);
        for (std::uint32_t r = r0; r <= r1; ++r) {
            const std::size_t rowCells = plane.firstCell + std::size_t(r) * plane.columns;
            const std::uint32_t end = index.mCellStart[rowCells + c1 + 1];
            for (std::uint32_t j = index.mCellStart[rowCells + c0]; j < end; ++j)
                consider(*query, position, s, index.mCellDiscs[j], index.mCellCenters[j],
                         plane.normal);
        }
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
    const double slack = double(kEmbreeSlack) * mRadius;
    const double endTolerance = double(kDiscEndTolerance) * mRadius;

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
        const glm::vec3& o = segments.origin[s];
        const glm::vec3& d = segments.direction[s];
        // The part of the segment Embree sees, in the segment's t: from the counted part's
        // start to the end past the landing tolerance, kEmbreeSlack radii wider at each end,
        // then clipped to the box around the discs. In double: Embree's ray starts where the
        // clipped part does, so that a segment from far away (a distant light) is traced from
        // near the discs and Embree's rounding stays that of the scene's scale.
        const auto [start, stop] = clipToBox(
            o, d,
            (query.beyond ? std::max(0.0, double(query.beyond[k]) + endTolerance) : 0.0) - slack,
            double(segments.length[s]) + endTolerance + slack, // +inf stays +inf
            mBoxMin, mBoxMax);
        if (!(start <= stop)) continue; // misses the box: no disc to cross
        RTCRay ray;
        ray.org_x = float(o.x + start * d.x);
        ray.org_y = float(o.y + start * d.y);
        ray.org_z = float(o.z + start * d.z);
        ray.tnear = 0.f;
        ray.dir_x = d.x;
        ray.dir_y = d.y;
        ray.dir_z = d.z;
        ray.time = 0.f;
        ray.tfar = float(stop - start);
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
    if (size() == 0 || indices.empty()) return;
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
