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
#include <bit>
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
/// addRectangles), so that they overlap across its diagonal.
constexpr float kDiagonalOverlap = 0.02f;
/// A plane's lookup skips discs whose centre lies farther than this many radii from the
/// crossing point in the plane: the distance the 3 x 3 cells around it guarantee, so the
/// quarter radius the lookup has to spare for rounding stays (see the class comment).
constexpr double kLookupReach = 1.25;
/// A tilted plane whose lookup would need |cos| above this (its coordinates' rounding is large
/// for the radius) is not made: a twentieth of all segments would test each of its discs.
constexpr double kMaxTiltedMinCosine = 0.05;
/// Tilted discs are grouped by their unit normal rounded to this step.
constexpr double kNormalQuantum = 1.0 / 1024.0;
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
    SegmentRays segments{{}, {}, {}};
    const std::uint32_t* indices = nullptr;
    const float* beyond = nullptr; ///< per index, or null: whole segments
    std::size_t count = 0;
    std::vector<std::uint64_t>* pairs = nullptr; // the chunk's output
};

struct DiscIndex::Scratch {
    struct Keyed {
        std::array<std::uint32_t, 4> key; // exact: normal's bits, coordinate's bits
        std::uint32_t disc;
        bool operator<(const Keyed& o) const {
            return std::tie(key, disc) < std::tie(o.key, o.disc);
        }
    };
    struct Offset {
        double offset;
        std::uint32_t disc;
        bool operator<(const Offset& o) const {
            return std::tie(offset, disc) < std::tie(o.offset, o.disc);
        }
    };
    struct Run {
        std::uint32_t first, last, rectangle;
    };
    /// A group of tilted discs with one quantised normal: keyed[first, end).
    struct Group {
        std::size_t first, end;
    };
    std::vector<Keyed> keyed;
    std::vector<Group> groups;
    std::vector<Offset> offsets;
    std::vector<std::uint8_t> planar;
    std::vector<std::uint32_t> discs;
    std::vector<glm::dvec2> uv;
    std::vector<float> values;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> cellOf; // (cell, position in discs)
    std::vector<std::uint8_t> active;
    std::vector<Run> above, here;
};

void DiscIndex::Layout::clear() {
    pointIds.clear();
    pointDiscs.clear();
    pointNormals.clear();
    planes.clear();
    cellStart.assign(1, 0);
    cellDiscs.clear();
    cellCenters.clear();
    cellNormals.clear();
    cellPoints.clear();
    rectangles.clear();
    patchVertices.clear();
    patchTriangles.clear();
    direct = false;
    sieve = {};
}

DiscIndex::DiscIndex(EmbreeDevice& device, Motion motion)
    : mDevice(device), mMotion(motion), mScratch(std::make_unique<Scratch>()) {}

DiscIndex::~DiscIndex() = default;

std::size_t DiscIndex::tiltedPlaneCount() const {
    return std::size_t(std::count_if(mLayout.planes.begin(), mLayout.planes.end(),
                                     [](const Plane& p) { return p.tilted; }));
}

glm::dvec2 DiscIndex::planeCoordinates(const Plane& plane, const glm::dvec3& x) {
    if (plane.tilted) return {glm::dot(x, plane.uAxis), glm::dot(x, plane.vAxis)};
    return {x[plane.u], x[plane.v]};
}

bool DiscIndex::addPlane(Plane plane, std::span<const std::uint32_t> discs,
                         std::span<const glm::dvec2> uv, std::span<const glm::vec3> centers,
                         std::span<const glm::vec3> normals, float radius, Layout& out,
                         Scratch& scratch) {
    const double cell = double(kPlaneCellRadii) * radius;
    glm::dvec2 lo(std::numeric_limits<double>::max()), hi(std::numeric_limits<double>::lowest());
    for (const glm::dvec2& p : uv) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    // One empty cell all around: the 3 x 3 neighbourhood of a disc's cell is in the grid.
    const double columns = std::floor((hi.x - lo.x) / cell) + 3.0;
    const double rows = std::floor((hi.y - lo.y) / cell) + 3.0;
    if (!(columns * rows <= double(kGridCellsPerDisc * discs.size() + kGridCellsSpare)) ||
        columns > kMaxGridSide || rows > kMaxGridSide ||
        double(out.cellStart.size()) + columns * rows > kMaxCells)
        return false;
    plane.columns = std::uint32_t(columns);
    plane.rows = std::uint32_t(rows);
    plane.corner = lo - glm::dvec2(cell);
    // kLookupReach radii, and the rounding of the discs' float coordinates in the grid.
    const double extent = std::max(hi.x - lo.x, hi.y - lo.y) + 2.0 * cell;
    plane.reach2 = float(std::pow(kLookupReach * radius + std::ldexp(extent, -20), 2.0));
    plane.firstCell = std::uint32_t(out.cellStart.size() - 1);

    auto& cellOf = scratch.cellOf;
    cellOf.clear();
    for (std::uint32_t i = 0; i < discs.size(); ++i) {
        const auto column = std::uint32_t(std::clamp(std::floor((uv[i].x - plane.corner.x) / cell),
                                                     1.0, double(plane.columns - 2)));
        const auto row = std::uint32_t(
            std::clamp(std::floor((uv[i].y - plane.corner.y) / cell), 1.0, double(plane.rows - 2)));
        cellOf.emplace_back(row * plane.columns + column, i);
    }
    std::sort(cellOf.begin(), cellOf.end()); // by cell, then by disc within it
    const std::size_t cells = plane.cellCount();
    std::size_t next = 0;
    for (std::uint32_t c = 0; c < cells; ++c) {
        for (; next < cellOf.size() && cellOf[next].first == c; ++next) {
            const std::uint32_t disc = discs[cellOf[next].second];
            out.cellDiscs.push_back(disc);
            out.cellCenters.push_back(centers[disc]);
            out.cellNormals.push_back(normals[disc]);
            out.cellPoints.push_back(glm::vec2(uv[cellOf[next].second] - plane.corner));
        }
        out.cellStart.push_back(std::uint32_t(out.cellDiscs.size()));
    }
    out.planes.push_back(plane);
    return true;
}

void DiscIndex::addRectangles(std::uint32_t planeIndex, float radius, Layout& out,
                              Scratch& scratch) {
    const Plane& plane = out.planes[planeIndex];
    QGI_ASSERT(!plane.tilted, "tilted planes are queried directly, without rectangles");
    const double cell = double(kPlaneCellRadii) * radius;
    const double overlap = double(kRectangleOverlap) * cell;
    auto& active = scratch.active;
    active.assign(plane.cellCount(), 0);
    // Cells within one of a non-empty cell: wherever a segment can cross within a radius of
    // one of the plane's discs.
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
    auto& above = scratch.above;
    auto& here = scratch.here;
    above.clear();
    const std::size_t firstRectangle = out.rectangles.size();
    for (std::uint32_t row = 0; row < plane.rows; ++row) {
        here.clear();
        for (std::uint32_t column = 0; column < plane.columns;) {
            if (!active[std::size_t(row) * plane.columns + column]) {
                ++column;
                continue;
            }
            Scratch::Run run{column, column, 0};
            while (run.last + 1 < plane.columns &&
                   active[std::size_t(row) * plane.columns + run.last + 1])
                ++run.last;
            column = run.last + 1;
            const double v1 = plane.corner.y + double(row + 1) * cell + overlap;
            const auto same = std::find_if(above.begin(), above.end(), [&](const Scratch::Run& a) {
                return a.first == run.first && a.last == run.last;
            });
            if (same != above.end()) { // extend the rectangle one row down
                run.rectangle = same->rectangle;
                out.rectangles[run.rectangle].hi.y = v1;
            } else {
                run.rectangle = std::uint32_t(out.rectangles.size());
                out.rectangles.push_back(
                    {planeIndex,
                     {plane.corner.x + double(run.first) * cell - overlap,
                      plane.corner.y + double(row) * cell - overlap},
                     {plane.corner.x + double(run.last + 1) * cell + overlap, v1}});
            }
            here.push_back(run);
        }
        std::swap(above, here);
    }

    // Each rectangle as two right triangles, each stretched about its right-angle corner so
    // that they overlap across the diagonal: a crossing on the diagonal meets at least one of
    // them whatever Embree's rounding (its triangle test is not watertight). Triangle 2i and
    // 2i + 1 are rectangle i's.
    const auto vertex = [&](glm::dvec2 p) {
        glm::vec4 q(0.f);
        q[plane.axis] = plane.coordinate;
        q[plane.u] = float(p.x);
        q[plane.v] = float(p.y);
        return q;
    };
    for (std::size_t i = firstRectangle; i < out.rectangles.size(); ++i) {
        const Rectangle& r = out.rectangles[i];
        const glm::dvec2 size = (r.hi - r.lo) * (1.0 + double(kDiagonalOverlap));
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

void DiscIndex::makeLayout(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
                           float radius, Layout& out, Scratch& scratch) {
    groupDiscs(centers, normals, radius, out, scratch);
    out.direct = out.cellDiscs.size() == centers.size() && out.planes.size() <= kMaxDirectPlanes;
    if (!out.direct) {
        // Tilted planes pay only where they leave Embree out; elsewhere their discs stay
        // points. They come after the exact ones: drop them, their cells and their discs.
        const auto tilted = std::find_if(out.planes.begin(), out.planes.end(),
                                         [](const Plane& p) { return p.tilted; });
        if (tilted != out.planes.end()) {
            out.cellStart.resize(tilted->firstCell + 1);
            const std::size_t kept = out.cellStart.back();
            out.cellDiscs.resize(kept);
            out.cellCenters.resize(kept);
            out.cellNormals.resize(kept);
            out.cellPoints.resize(kept);
            out.planes.erase(tilted, out.planes.end());
        }
    }
    auto& planar = scratch.planar;
    planar.assign(centers.size(), 0);
    for (const std::uint32_t disc : out.cellDiscs)
        planar[disc] = 1;
    for (std::uint32_t i = 0; i < centers.size(); ++i) {
        if (planar[i]) continue;
        out.pointIds.push_back(i);
        out.pointDiscs.push_back(glm::vec4(centers[i], radius * kEmbreeWiden));
        out.pointNormals.push_back(normals[i]);
    }
    out.pointNormals.push_back(glm::vec3(0.f)); // the padding
    if (out.direct) {                           // no Embree: no rectangles
        makeSieve(radius, out);
        return;
    }
    for (std::uint32_t p = 0; p < out.planes.size(); ++p)
        addRectangles(p, radius, out, scratch);
}

void DiscIndex::makeSieve(float radius, Layout& layout) {
    PlaneSieve& sieve = layout.sieve;
    sieve = {};
    sieve.count = std::uint32_t(layout.planes.size());
    QGI_ASSERT(sieve.count <= PlaneSieve::kLanes, "a direct query has at most 16 planes");
    for (std::uint32_t p = 0; p < sieve.count; ++p) {
        const Plane& plane = layout.planes[p];
        glm::vec3 n;
        float offset;
        if (plane.tilted) {
            n = glm::vec3(plane.unitNormal);
            offset = float(plane.offset);
            // At or above minCosine crossPlane() either turns the segment down (from behind)
            // or tests every disc (grazing); the 1e-2 floor keeps the float crossing within
            // the margins below.
            sieve.grazing[p] = float(std::max(1e-2, 1.001 * plane.minCosine + 1e-6));
            sieve.facing[p] = sieve.grazing[p];
        } else {
            // d . n is d[axis] * normal[axis] exactly (the other terms are zeros), so the facing
            // test is crossPlane()'s own.
            n = plane.normal;
            offset = plane.normal[plane.axis] * plane.coordinate;
            sieve.grazing[p] = 1e-2f;
            sieve.facing[p] = 0.f;
        }
        sieve.nx[p] = n.x;
        sieve.ny[p] = n.y;
        sieve.nz[p] = n.z;
        sieve.offset[p] = offset;
        // A disc crossPlane() accepts has its centre within a radius of its own crossing
        // point, which lies within kTiltedReachRadii radii of the plane's (none for an exact
        // plane): well within kLookupReach radii of the centres' box.
        glm::vec3 low(std::numeric_limits<float>::max()), high(-low);
        const std::uint32_t end = layout.cellStart[plane.firstCell + plane.cellCount()];
        for (std::uint32_t j = layout.cellStart[plane.firstCell]; j < end; ++j) {
            low = glm::min(low, layout.cellCenters[j]);
            high = glm::max(high, layout.cellCenters[j]);
        }
        const float reach = float(kLookupReach) * radius;
        sieve.lowX[p] = low.x - reach;
        sieve.lowY[p] = low.y - reach;
        sieve.lowZ[p] = low.z - reach;
        sieve.highX[p] = high.x + reach;
        sieve.highY[p] = high.y + reach;
        sieve.highZ[p] = high.z + reach;
    }
}

// The sieve's margins and its handling of NaN assume IEEE arithmetic, as compiled without
// -ffast-math.
static_assert(std::numeric_limits<float>::is_iec559, "the plane sieve needs IEEE floats");
#if defined(__FAST_MATH__)
#error                                                                                             \
    "DiscIndex's plane sieve must not be compiled with -ffast-math (it needs NaN and exact rounding)"
#endif

std::uint32_t DiscIndex::PlaneSieve::candidates(const glm::vec3& o, const glm::vec3& d, float start,
                                                float stop) const {
    // Float rounding of the crossing (t and the point) stays below 2.5e-5 of
    // |offset| + |o|_1 + |t| where |cos| >= 1e-2 (about 400 float steps): the margin is four
    // times that. Comparisons are written so that NaN keeps a plane.
    const float size = std::abs(o.x) + std::abs(o.y) + std::abs(o.z);
    std::array<std::uint32_t, kLanes> keep;
    for (std::size_t p = 0; p < kLanes; ++p) {
        const float cosine = d.x * nx[p] + d.y * ny[p] + d.z * nz[p];
        const float t = (offset[p] - (o.x * nx[p] + o.y * ny[p] + o.z * nz[p])) / cosine;
        const float margin = 1e-4f * (std::abs(offset[p]) + size + std::abs(t));
        const float x = o.x + t * d.x, y = o.y + t * d.y, z = o.z + t * d.z;
        // Bitwise on 0/1 integers, not short-circuit: no branches, so the loop vectorises.
        const std::uint32_t away = cosine >= facing[p];
        const std::uint32_t grazes = std::abs(cosine) < grazing[p];
        const std::uint32_t outside =
            std::uint32_t(t < start - margin) | std::uint32_t(t > stop + margin) |
            std::uint32_t(x < lowX[p] - margin) | std::uint32_t(x > highX[p] + margin) |
            std::uint32_t(y < lowY[p] - margin) | std::uint32_t(y > highY[p] + margin) |
            std::uint32_t(z < lowZ[p] - margin) | std::uint32_t(z > highZ[p] + margin);
        keep[p] = (away ^ 1u) & (grazes | (outside ^ 1u));
    }
    std::uint32_t mask = 0;
    for (std::size_t p = 0; p < kLanes; ++p)
        mask |= keep[p] << p;
    return mask & ((std::uint32_t(1) << count) - 1u);
}

void DiscIndex::groupDiscs(std::span<const glm::vec3> centers, std::span<const glm::vec3> normals,
                           float radius, Layout& out, Scratch& scratch) {
    out.clear();
    auto& planar = scratch.planar;
    planar.assign(centers.size(), 0);
    auto& keyed = scratch.keyed;
    auto& discs = scratch.discs;
    auto& uv = scratch.uv;
    const auto takeDiscs = [&](std::size_t firstCell) {
        for (std::size_t j = out.cellStart[firstCell]; j < out.cellDiscs.size(); ++j)
            planar[out.cellDiscs[j]] = 1;
    };

    // Exact planes. Group the discs of exactly axis-aligned normal by (normal, coordinate along
    // the axis), bit for bit; the sort keeps the groups, and the discs in them, in a fixed order.
    keyed.clear();
    for (std::uint32_t i = 0; i < centers.size(); ++i) {
        const int axis = exactAxis(normals[i]);
        if (axis < 0) continue;
        // + 0.f: a negative zero joins the positive one (the rule gives the same answers).
        keyed.push_back({{bitsOf(normals[i].x + 0.f), bitsOf(normals[i].y + 0.f),
                          bitsOf(normals[i].z + 0.f), bitsOf(centers[i][axis] + 0.f)},
                         i});
    }
    std::sort(keyed.begin(), keyed.end());
    for (std::size_t first = 0; first < keyed.size();) {
        std::size_t last = first;
        while (last < keyed.size() && keyed[last].key == keyed[first].key)
            ++last;
        const std::span<const Scratch::Keyed> group(keyed.data() + first, last - first);
        first = last;
        if (group.size() < kMinPlaneDiscs) continue;
        Plane plane;
        plane.normal = normals[group[0].disc];
        plane.axis = std::uint8_t(exactAxis(plane.normal));
        plane.u = std::uint8_t((plane.axis + 1) % 3);
        plane.v = std::uint8_t((plane.axis + 2) % 3);
        plane.coordinate = centers[group[0].disc][plane.axis];
        discs.clear();
        uv.clear();
        for (const Scratch::Keyed& k : group) {
            discs.push_back(k.disc);
            uv.push_back(planeCoordinates(plane, glm::dvec3(centers[k.disc])));
        }
        const std::size_t firstCell = out.cellStart.size() - 1;
        if (addPlane(plane, discs, uv, centers, normals, radius, out, scratch))
            takeDiscs(firstCell);
    }

    // Tilted planes. Group the other discs by their normal quantised to kNormalQuantum (a
    // plane's discs, whose normals differ in their last bits, fall in one group unless it
    // straddles a step: then in two); within a group, a plane is a run of discs whose offsets
    // along the mean normal stay within the thickness allowed.
    keyed.clear();
    for (std::uint32_t i = 0; i < centers.size(); ++i) {
        if (planar[i] || exactAxis(normals[i]) >= 0) continue;
        std::array<std::uint32_t, 4> key{0, 0, 0, 0};
        for (int a = 0; a < 3; ++a)
            key[std::size_t(a)] =
                std::uint32_t(std::int32_t(std::lround(normals[i][a] / kNormalQuantum)));
        keyed.push_back({key, i});
    }
    std::sort(keyed.begin(), keyed.end());
    auto& groups = scratch.groups;
    groups.clear();
    for (std::size_t first = 0; first < keyed.size();) {
        std::size_t last = first;
        while (last < keyed.size() && keyed[last].key == keyed[first].key)
            ++last;
        if (last - first >= kMinPlaneDiscs) groups.push_back({first, last});
        first = last;
    }
    const double thickness = kTiltedThicknessRadii * radius;
    auto& offsets = scratch.offsets;
    for (const Scratch::Group& group : groups) {
        // The plane's normal: the mean of those near the group's median normal (discs of
        // another, rougher surface may share the group).
        glm::dvec3 median(0.0);
        for (int a = 0; a < 3; ++a) {
            auto& values = scratch.values;
            values.clear();
            for (std::size_t k = group.first; k < group.end; ++k)
                values.push_back(normals[keyed[k].disc][a]);
            std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
            median[a] = values[values.size() / 2];
        }
        glm::dvec3 sum(0.0);
        for (std::size_t k = group.first; k < group.end; ++k)
            if (glm::length(glm::dvec3(normals[keyed[k].disc]) - median) <= kTiltedNormalSpread)
                sum += glm::dvec3(normals[keyed[k].disc]);
        if (!(glm::dot(sum, sum) > 0.0)) continue;
        const glm::dvec3 n = glm::normalize(sum);
        offsets.clear();
        for (std::size_t k = group.first; k < group.end; ++k) {
            const std::uint32_t disc = keyed[k].disc;
            if (glm::length(glm::dvec3(normals[disc]) - n) <= kTiltedNormalSpread)
                offsets.push_back({glm::dot(n, glm::dvec3(centers[disc])), disc});
        }
        std::sort(offsets.begin(), offsets.end());
        // A basis of the plane: u across the axis n leans on least.
        glm::dvec3 across(0.0);
        const glm::dvec3 an = glm::abs(n);
        across[an.x <= an.y && an.x <= an.z ? 0 : an.y <= an.z ? 1 : 2] = 1.0;
        const glm::dvec3 uAxis = glm::normalize(glm::cross(n, across));
        const glm::dvec3 vAxis = glm::cross(n, uAxis);
        for (std::size_t first = 0; first < offsets.size();) {
            std::size_t last = first;
            while (last < offsets.size() &&
                   offsets[last].offset - offsets[first].offset <= thickness)
                ++last;
            const std::span<const Scratch::Offset> run(offsets.data() + first, last - first);
            first = last;
            if (run.size() < kMinPlaneDiscs) continue;
            Plane plane;
            plane.tilted = true;
            plane.unitNormal = n;
            plane.uAxis = uAxis;
            plane.vAxis = vAxis;
            plane.normal = glm::vec3(n);
            plane.offset = 0.5 * (run.front().offset + run.back().offset);
            // h: how far a disc's own plane lies from the patch's within a radius of its centre,
            // plus a few float steps of the coordinates (the rule's own rounding: it works in
            // float, the lookup in double).
            double separation = 0.0, reach = 0.0;
            glm::dvec3 lo(std::numeric_limits<double>::max()),
                hi(-std::numeric_limits<double>::max());
            discs.clear();
            uv.clear();
            for (const Scratch::Offset& o : run) {
                const glm::dvec3 c(centers[o.disc]);
                separation =
                    std::max(separation, std::abs(o.offset - plane.offset) +
                                             glm::length(glm::dvec3(normals[o.disc]) - n) * radius);
                reach = std::max(reach, glm::length(c));
                lo = glm::min(lo, c);
                hi = glm::max(hi, c);
                discs.push_back(o.disc);
                uv.push_back(planeCoordinates(plane, c));
            }
            separation += 4.0 * std::ldexp(reach + 2.0 * radius, -23);
            plane.minCosine = separation / (kTiltedReachRadii * radius);
            // Coordinates so large for the radius that many segments would test every disc:
            // the discs stay points.
            if (!(plane.minCosine <= kMaxTiltedMinCosine)) continue;
            const glm::dvec3 widen(double(radius) * (1.0 + double(kEmbreeSlack)) + separation);
            plane.boxMin = lo - widen;
            plane.boxMax = hi + widen;
            const std::size_t firstCell = out.cellStart.size() - 1;
            if (!addPlane(plane, discs, uv, centers, normals, radius, out, scratch)) continue;
            takeDiscs(firstCell);
        }
    }
}

void DiscIndex::attachGeometries(RTCDevice device, RTCScene scene, Layout& layout,
                                 GeometryHandle& points, GeometryHandle& patches) {
    // Embree shares the layout's buffers; a geometry already attached takes them anew (they
    // may have moved or changed size) and is committed again.
    const std::size_t pointCount = layout.pointIds.size();
    if (pointCount > 0) {
        const bool fresh = points.get() == nullptr;
        if (fresh) {
            points = GeometryHandle(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_ORIENTED_DISC_POINT));
            rtcSetGeometryOccludedFilterFunction(points.get(), &DiscIndex::recordCrossings);
        }
        rtcSetSharedGeometryBuffer(points.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4,
                                   layout.pointDiscs.data(), 0, sizeof(glm::vec4), pointCount);
        rtcSetSharedGeometryBuffer(points.get(), RTC_BUFFER_TYPE_NORMAL, 0, RTC_FORMAT_FLOAT3,
                                   layout.pointNormals.data(), 0, sizeof(glm::vec3), pointCount);
        rtcCommitGeometry(points.get());
        if (fresh) rtcAttachGeometry(scene, points.get());
    }
    if (!layout.rectangles.empty()) {
        const bool fresh = patches.get() == nullptr;
        if (fresh) {
            patches = GeometryHandle(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE));
            rtcSetGeometryOccludedFilterFunction(patches.get(), &DiscIndex::recordPlaneCrossings);
        }
        rtcSetSharedGeometryBuffer(patches.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                   layout.patchVertices.data(), 0, sizeof(glm::vec4),
                                   layout.patchVertices.size());
        rtcSetSharedGeometryBuffer(patches.get(), RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                   layout.patchTriangles.data(), 0, sizeof(glm::uvec3),
                                   layout.patchTriangles.size());
        rtcCommitGeometry(patches.get());
        if (fresh) rtcAttachGeometry(scene, patches.get());
    }
    rtcCommitScene(scene);
}

SceneHandle DiscIndex::newScene(RTCDevice device, Motion motion) {
    SceneHandle scene(rtcNewScene(device));
    rtcSetSceneBuildQuality(scene.get(), motion == Motion::Static ? RTC_BUILD_QUALITY_HIGH
                                                                  : RTC_BUILD_QUALITY_LOW);
    if (motion == Motion::Moving) rtcSetSceneFlags(scene.get(), RTC_SCENE_FLAG_DYNAMIC);
    return scene;
}

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
    if (rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) != 0)
        fail("DiscIndex: this Embree was built with backface culling; the disc index needs "
             "two-sided triangles");
    // Everything is made aside and moved into the members only once the build has succeeded
    // (moving a vector keeps its storage, which Embree shares), so a failure leaves the old
    // index intact.
    Layout layout;
    makeLayout(centers, normals, radius, layout, *mScratch);
    SceneHandle scene;
    GeometryHandle points, patches;
    if (!layout.direct) {
        scene = newScene(device, mMotion);
        attachGeometries(device, scene.get(), layout, points, patches);
    }
    if (const auto error = mDevice.takeError())
        fail("DiscIndex: Embree failed to build ", centers.size(), " discs: ", error->message);
    mScene = std::move(scene);
    mGeometry = std::move(points);
    mPlaneGeometry = std::move(patches);
    mLayout = std::move(layout);
    mCenters.assign(centers.begin(), centers.end());
    mNormals.assign(normals.begin(), normals.end());
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
    }
    makeLayout(mCenters, mNormals, mRadius, mLayout, *mScratch);
    updateBox();
    if (mLayout.direct) { // no Embree
        mGeometry = {};
        mPlaneGeometry = {};
        mScene = {};
        return;
    }
    // A scene whose kinds of geometry change (the discs turned into or out of planes) is made
    // anew; otherwise the geometries take the refilled buffers.
    const RTCDevice device = mDevice.handle();
    if (!mScene.get() || (mGeometry.get() != nullptr) != !mLayout.pointIds.empty() ||
        (mPlaneGeometry.get() != nullptr) != !mLayout.rectangles.empty()) {
        mGeometry = {};
        mPlaneGeometry = {};
        mScene = newScene(device, mMotion);
    }
    attachGeometries(device, mScene.get(), mLayout, mGeometry, mPlaneGeometry);
    QGI_ASSERT(!mDevice.takeError(), "Embree failed to refit a moved disc index");
}

void DiscIndex::consider(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                         std::uint32_t disc, const glm::vec3& center, const glm::vec3& normal) {
    const DiscIndex& index = *query.index;
    const SegmentRays& segments = query.segments;
    const float t = discCrossing(segments.origin[s], segments.direction[s], segments.length[s],
                                 center, normal, index.mRadius);
    if (t < 0.f) return;
    // The cut copy counts t <= beyond + tolerance (the same float expression): skip those.
    if (query.beyond && !(t > query.beyond[position] + kDiscEndTolerance * index.mRadius)) return;
    query.pairs->push_back(std::uint64_t(position) << 32 | disc);
}

void DiscIndex::considerCells(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                              const Plane& plane, std::uint32_t c0, std::uint32_t c1,
                              std::uint32_t r0, std::uint32_t r1, const glm::dvec2* point) {
    const Layout& layout = query.index->mLayout;
    const glm::vec2 p = point ? glm::vec2(*point - plane.corner) : glm::vec2(0.f);
    for (std::uint32_t r = r0; r <= r1; ++r) {
        const std::size_t rowCells = plane.firstCell + std::size_t(r) * plane.columns;
        const std::uint32_t end = layout.cellStart[rowCells + c1 + 1];
        for (std::uint32_t j = layout.cellStart[rowCells + c0]; j < end; ++j) {
            if (point) { // far from the crossing point: no need for the rule
                const glm::vec2 offset = layout.cellPoints[j] - p;
                if (offset.x * offset.x + offset.y * offset.y > plane.reach2) continue;
            }
            consider(query, position, s, layout.cellDiscs[j], layout.cellCenters[j],
                     layout.cellNormals[j]);
        }
    }
}

void DiscIndex::recordCrossings(const RTCFilterFunctionNArguments* args) {
    const auto* query = reinterpret_cast<const QueryContext*>(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        args->valid[i] = 0; // rejected: traversal goes on to the next disc
        const std::uint32_t position = RTCRayN_id(args->ray, args->N, i);
        const DiscIndex& index = *query->index;
        const std::uint32_t disc = index.mLayout.pointIds[RTCHitN_primID(args->hit, args->N, i)];
        consider(*query, position, query->indices[position], disc, index.mCenters[disc],
                 index.mNormals[disc]);
    }
}

void DiscIndex::crossPlane(const QueryContext& query, std::uint32_t position, std::uint32_t s,
                           const Plane& plane, const double* range) {
    const glm::vec3& o = query.segments.origin[s];
    const glm::vec3& d = query.segments.direction[s];
    glm::dvec2 uv;
    if (plane.tilted) {
        QGI_ASSERT(range, "tilted planes are queried directly");
        const double cosine = glm::dot(glm::dvec3(d), plane.unitNormal);
        if (!(cosine <= -plane.minCosine)) {
            // From behind: no disc of the plane faces the segment. Grazing: the crossing point
            // is no guide, so every disc, where the segment comes near the plane's discs.
            if (std::abs(cosine) < plane.minCosine) {
                const auto [near, far] =
                    clipToBox(o, d, range[0], range[1], plane.boxMin, plane.boxMax);
                if (near <= far)
                    considerCells(query, position, s, plane, 0, plane.columns - 1, 0,
                                  plane.rows - 1, nullptr);
            }
            return;
        }
        const double t = (plane.offset - glm::dot(glm::dvec3(o), plane.unitNormal)) / cosine;
        if (!(t >= range[0] && t <= range[1])) return;
        uv = planeCoordinates(plane, glm::dvec3(o) + t * glm::dvec3(d));
    } else {
        // From behind or parallel: crossesDisc() turns down every disc of the plane. The
        // crossing point as crossesDisc() computes it, in float.
        if (!(d[plane.axis] * plane.normal[plane.axis] < 0.f)) return;
        const float t = (plane.coordinate - o[plane.axis]) / d[plane.axis];
        if (range && !(double(t) >= range[0] && double(t) <= range[1])) return;
        uv = {o[plane.u] + t * d[plane.u], o[plane.v] + t * d[plane.v]};
    }
    // A crossing point that is not finite is no disc's: crossesDisc() would say so too. Nor is
    // one off the grid, which reaches a cell past every disc's.
    const double cell = double(kPlaneCellRadii) * query.index->mRadius;
    const double column = std::floor((uv.x - plane.corner.x) / cell);
    const double row = std::floor((uv.y - plane.corner.y) / cell);
    if (!(column >= 0.0 && column < double(plane.columns) && row >= 0.0 &&
          row < double(plane.rows)))
        return;
    const auto c = std::uint32_t(column), r = std::uint32_t(row);
    considerCells(query, position, s, plane, c > 0 ? c - 1 : 0, std::min(c + 1, plane.columns - 1),
                  r > 0 ? r - 1 : 0, std::min(r + 1, plane.rows - 1), &uv);
}

void DiscIndex::recordPlaneCrossings(const RTCFilterFunctionNArguments* args) {
    const auto* query = reinterpret_cast<const QueryContext*>(args->context);
    const Layout& layout = query->index->mLayout;
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        args->valid[i] = 0; // rejected: traversal goes on
        const std::uint32_t position = RTCRayN_id(args->ray, args->N, i);
        const std::uint32_t rectangle = RTCHitN_primID(args->hit, args->N, i) / 2;
        crossPlane(*query, position, query->indices[position],
                   layout.planes[layout.rectangles[rectangle].plane], nullptr);
    }
}

void DiscIndex::traceChunk(const QueryContext& query, std::size_t chunk) {
    std::vector<std::uint64_t>& pairs = mChunkPairs[chunk];
    pairs.clear();
    QueryContext context = query;
    context.pairs = &pairs;

    const SegmentRays& segments = query.segments;
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
        // The part of the segment Embree sees (or the planes, in a direct query), in the
        // segment's t: from the counted part's start to the end past the landing tolerance,
        // kEmbreeSlack radii wider at each end, then clipped to the box around the discs. In
        // double: Embree's ray starts where the clipped part does, so that a segment from far
        // away (a distant light) is traced from near the discs and Embree's rounding stays that
        // of the scene's scale.
        const auto [start, stop] = clipToBox(
            o, d,
            (query.beyond ? std::max(0.0, double(query.beyond[k]) + endTolerance) : 0.0) - slack,
            double(segments.length[s]) + endTolerance + slack, // +inf stays +inf
            mBoxMin, mBoxMax);
        if (!(start <= stop)) continue; // misses the box: no disc to cross
        if (mLayout.direct) {           // plane by plane: they are few
            const double range[2] = {start, stop};
            const std::size_t first = pairs.size();
            for (std::uint32_t planes = mLayout.sieve.candidates(o, d, float(start), float(stop));
                 planes != 0; planes &= planes - 1)
                crossPlane(context, std::uint32_t(k), s, mLayout.planes[std::countr_zero(planes)],
                           range);
            // The canonical order, segment by segment (a disc sits in one plane's grid once,
            // and each plane is looked up once: no pair comes twice).
            std::sort(pairs.begin() + std::ptrdiff_t(first), pairs.end());
            continue;
        }
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
    if (mLayout.direct) return; // in order already
    // Canonical order; a disc Embree reports twice for one segment is counted once.
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
}

SegmentRays::SegmentRays(const PhotonSegments& segments)
    : origin(segments.origin.data()), direction(segments.direction.data()),
      length(segments.length.data()) {}

void DiscIndex::collectCrossings(SegmentRays segments, std::span<const std::uint32_t> indices,
                                 std::vector<DiscCrossing>& out, std::span<const float> beyond) {
    QGI_ASSERT(beyond.empty() || beyond.size() == indices.size(), "one length per index");
    out.clear();
    if (size() == 0 || indices.empty()) return;
    const std::size_t chunks = (indices.size() + kChunkSize - 1) / kChunkSize;
    if (mChunkPairs.size() < chunks) mChunkPairs.resize(chunks);

    QueryContext query;
    rtcInitIntersectContext(&query.embree);
    query.index = this;
    query.segments = segments;
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
