#include "runtime/scene/MeshProcessing.h"

#include "runtime/core/Error.h"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <queue>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

namespace qgi {
namespace {

using OmMesh = OpenMesh::TriMesh_ArrayKernelT<>;
using Triangle = std::array<std::uint32_t, 3>;

// Texture coordinates closer than this are the same (no seam between the two vertices).
constexpr float kUvWeldTolerance = 1e-6f;
// A triangle whose height is below this fraction of its longest edge is collinear within
// float precision: its normal would be rounding noise.
constexpr double kMinHeightRatio = 1e-6;
// Weld grid cell when welding only exact duplicates (weldDistance 0).
constexpr float kMinWeldCell = 1e-6f;

constexpr std::uint32_t kNone = 0xffffffffu;

bool finite(const glm::vec3& p) {
    return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

void checkOptions(const MeshProcessingOptions& o) {
    if (!(o.weldDistance >= 0.f) || !std::isfinite(o.weldDistance))
        fail("mesh processing: weldDistance ", o.weldDistance, " must be finite and >= 0");
    if (!(o.creaseAngle >= 0.f && o.creaseAngle <= glm::pi<float>()))
        fail("mesh processing: creaseAngle ", o.creaseAngle, " must lie in [0, pi] radians");
    if (!std::isfinite(o.maxEdgeLength))
        fail("mesh processing: maxEdgeLength ", o.maxEdgeLength, " must be finite");
    if (!(o.minTriangleArea >= 0.f) || !std::isfinite(o.minTriangleArea))
        fail("mesh processing: minTriangleArea ", o.minTriangleArea, " must be finite and >= 0");
}

void checkInput(const Mesh& raw) {
    if (raw.indices.size() % 3 != 0)
        fail("mesh: index count ", raw.indices.size(), " is not a multiple of 3");
    if (!raw.uvs.empty() && raw.uvs.size() != raw.positions.size())
        fail("mesh: ", raw.uvs.size(), " uvs for ", raw.positions.size(), " positions");
    for (std::size_t i = 0; i < raw.positions.size(); ++i) {
        const glm::vec3& p = raw.positions[i];
        if (!finite(p))
            fail("mesh: position ", i, " is not finite (", p.x, ", ", p.y, ", ", p.z, ")");
    }
    for (std::size_t i = 0; i < raw.uvs.size(); ++i)
        if (!std::isfinite(raw.uvs[i].x) || !std::isfinite(raw.uvs[i].y))
            fail("mesh: uv ", i, " is not finite");
    for (std::size_t k = 0; k < raw.indices.size(); ++k)
        if (raw.indices[k] >= raw.positions.size())
            fail("mesh: index ", k, " refers to vertex ", raw.indices[k], " of ",
                 raw.positions.size());
}

/// Vertices after welding: `remap[raw index]` is the welded index.
struct WeldedVertices {
    std::vector<glm::vec3> positions;
    std::vector<glm::vec2> uvs; // empty when the mesh has none
    std::vector<std::uint32_t> remap;
};

// Greedy weld on a hash grid with cells as large as the weld distance, so a partner lies in
// one of the 27 cells around a vertex. Each vertex joins the first earlier kept vertex it
// matches, which makes the result independent of hash order.
WeldedVertices weldVertices(const Mesh& raw, float distance) {
    const bool hasUvs = !raw.uvs.empty();
    const double inverseCell = 1.0 / double(std::max(distance, kMinWeldCell));
    const float distance2 = distance * distance;
    const auto cellOf = [&](const glm::vec3& p) {
        // Clamped so absurd but finite coordinates cannot overflow; they only share cells.
        const auto axis = [&](float x) {
            return std::int64_t(std::clamp(std::floor(double(x) * inverseCell), -4e18, 4e18));
        };
        return std::array<std::int64_t, 3>{axis(p.x), axis(p.y), axis(p.z)};
    };
    const auto key = [](std::int64_t x, std::int64_t y, std::int64_t z) {
        return std::uint64_t(x) * 0x9E3779B97F4A7C15ull ^ std::uint64_t(y) * 0xC2B2AE3D27D4EB4Full ^
               std::uint64_t(z) * 0x165667B19E3779F9ull;
    };

    WeldedVertices out;
    out.remap.resize(raw.positions.size());
    std::unordered_map<std::uint64_t, std::uint32_t> cellHead; // cell -> first kept vertex
    std::vector<std::uint32_t> nextInCell;                     // per kept vertex
    cellHead.reserve(raw.positions.size());
    for (std::size_t i = 0; i < raw.positions.size(); ++i) {
        const glm::vec3& p = raw.positions[i];
        const auto cell = cellOf(p);
        std::uint32_t match = kNone;
        for (int dz = -1; dz <= 1 && match == kNone; ++dz)
            for (int dy = -1; dy <= 1 && match == kNone; ++dy)
                for (int dx = -1; dx <= 1 && match == kNone; ++dx) {
                    const auto it = cellHead.find(key(cell[0] + dx, cell[1] + dy, cell[2] + dz));
                    if (it == cellHead.end()) continue;
                    for (std::uint32_t k = it->second; k != kNone; k = nextInCell[k]) {
                        const glm::vec3 d = out.positions[k] - p;
                        if (glm::dot(d, d) > distance2) continue;
                        if (hasUvs && glm::any(glm::greaterThan(glm::abs(out.uvs[k] - raw.uvs[i]),
                                                                glm::vec2(kUvWeldTolerance))))
                            continue;
                        match = k;
                        break;
                    }
                }
        if (match == kNone) {
            match = std::uint32_t(out.positions.size());
            out.positions.push_back(p);
            if (hasUvs) out.uvs.push_back(raw.uvs[i]);
            std::uint32_t& head =
                cellHead.try_emplace(key(cell[0], cell[1], cell[2]), kNone).first->second;
            nextInCell.push_back(head);
            head = match;
        }
        out.remap[i] = match;
    }
    return out;
}

struct TriangleHash {
    std::size_t operator()(const Triangle& t) const {
        return std::size_t(t[0]) * 0x9E3779B97F4A7C15ull ^
               std::size_t(t[1]) * 0xC2B2AE3D27D4EB4Full ^ std::size_t(t[2]);
    }
};

// How many triangles longest-edge bisection makes of triangle abc, until no edge is longer
// than sqrt(max2); counting stops once past `limit`. It runs the arithmetic refine() runs
// (float midpoints and squared lengths), and refine() splits every triangle at its longest
// edge too, since it takes the longest edges of the whole mesh first; only ties between equal
// edges may go another way, which refine()'s own check of the limit covers. A long thin
// triangle takes far more pieces than its area suggests: each split leaves a piece with two
// long sides, so a 100 m by 1 cm strip at a 1 m bound becomes 2187 pieces, not about 100.
using Corners = std::array<glm::vec3, 3>;
double bisectionCount(const Corners& abc, float max2, double limit, std::vector<Corners>& pending) {
    pending.assign(1, abc); // `pending` is the caller's, so its memory is reused
    double count = 0.0;
    while (!pending.empty() && count <= limit) {
        const auto [p, q, r] = pending.back();
        pending.pop_back();
        const float pq = glm::dot(q - p, q - p), qr = glm::dot(r - q, r - q),
                    rp = glm::dot(p - r, p - r);
        if (std::max({pq, qr, rp}) <= max2) {
            count += 1.0;
        } else if (pq >= qr && pq >= rp) {
            const glm::vec3 m = 0.5f * (p + q);
            pending.push_back({p, m, r});
            pending.push_back({m, q, r});
        } else if (qr >= rp) {
            const glm::vec3 m = 0.5f * (q + r);
            pending.push_back({q, m, p});
            pending.push_back({m, r, p});
        } else {
            const glm::vec3 m = 0.5f * (r + p);
            pending.push_back({r, m, q});
            pending.push_back({m, p, q});
        }
    }
    return count;
}

// Welded triangles without repeated vertices, slivers, tiny ones or exact duplicates (the
// same corners in the same orientation; a reversed copy is a legitimate back side). Also
// counts how many triangles refinement will make (bisectionCount, up to just past the
// limit), to refuse edge bounds the mesh cannot take before any memory goes to them.
std::vector<Triangle> cleanTriangles(const Mesh& raw, const WeldedVertices& welded,
                                     const MeshProcessingOptions& options,
                                     double& refinedEstimate) {
    const float max2 = options.maxEdgeLength * options.maxEdgeLength; // as refine() squares it
    // Counting stops past the limit; a shared budget may leave less than that.
    const double limit = options.budget ? std::min(options.maxTriangles, options.budget->left())
                                        : options.maxTriangles;
    std::vector<Corners> pending;
    std::vector<Triangle> triangles;
    triangles.reserve(raw.indices.size() / 3);
    std::unordered_set<Triangle, TriangleHash> seen;
    seen.reserve(raw.indices.size() / 3);
    refinedEstimate = 0.0;
    for (std::size_t k = 0; k < raw.indices.size(); k += 3) {
        Triangle t{welded.remap[raw.indices[k]], welded.remap[raw.indices[k + 1]],
                   welded.remap[raw.indices[k + 2]]};
        if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) continue;
        const glm::dvec3 a(welded.positions[t[0]]);
        const glm::dvec3 b(welded.positions[t[1]]);
        const glm::dvec3 c(welded.positions[t[2]]);
        if (!hasArea(a, b, c, double(options.minTriangleArea))) continue;
        // Rotate the smallest index first: the key of a triangle regardless of start corner.
        std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
        if (!seen.insert(t).second) continue;
        triangles.push_back(t);
    }
    if (options.maxEdgeLength <= 0.f) return triangles;
    // No piece with every side within the bound is larger than the equilateral one: a bound
    // the mesh's area alone rules out is refused without counting.
    double atLeast = 0.0;
    for (const Triangle& t : triangles) {
        const glm::dvec3 a(welded.positions[t[0]]), b(welded.positions[t[1]]),
            c(welded.positions[t[2]]);
        atLeast +=
            0.5 * glm::length(glm::cross(b - a, c - a)) / (0.25 * std::sqrt(3.0) * double(max2));
    }
    if (atLeast > limit) {
        refinedEstimate = atLeast;
        return triangles;
    }
    for (const Triangle& t : triangles) {
        if (refinedEstimate > limit) break;
        refinedEstimate +=
            bisectionCount({welded.positions[t[0]], welded.positions[t[1]], welded.positions[t[2]]},
                           max2, limit - refinedEstimate, pending);
    }
    return triangles;
}

} // namespace

bool hasArea(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c, double minArea) {
    const double doubleArea = glm::length(glm::cross(b - a, c - a));
    const double longest2 =
        std::max({glm::dot(b - a, b - a), glm::dot(c - b, c - b), glm::dot(a - c, a - c)});
    return 0.5 * doubleArea >= minArea && doubleArea > kMinHeightRatio * longest2;
}

namespace {

OmMesh::Point toOm(const glm::vec3& p) {
    return OmMesh::Point(p.x, p.y, p.z);
}
glm::vec3 toGlm(const OmMesh::Point& p) {
    return glm::vec3(p[0], p[1], p[2]);
}

// True when OpenMesh's add_face would accept the triangle: each corner is new or on a
// boundary, and no directed edge already carries a face. Checked up front because a refused
// add_face prints to OpenMesh's error stream (see buildHalfedgeMesh).
bool fitsManifold(const OmMesh& mesh, const std::array<OmMesh::VertexHandle, 3>& v) {
    for (int i = 0; i < 3; ++i) {
        if (!mesh.is_boundary(v[std::size_t(i)])) return false;
        const auto h = mesh.find_halfedge(v[std::size_t(i)], v[std::size_t((i + 1) % 3)]);
        if (h.is_valid() && !mesh.is_boundary(h)) return false;
    }
    return true;
}

/// The cleaned triangles as an OpenMesh half-edge mesh; `uvs` gets one entry per vertex.
/// A triangle that would make an edge or vertex non-manifold gets its own copies of its
/// corners: it stays in the mesh, only unconnected to its neighbours.
OmMesh buildHalfedgeMesh(const WeldedVertices& welded, const std::vector<Triangle>& triangles,
                         std::vector<glm::vec2>& uvs) {
    // A face add_face refuses is handled here (it gets its own corners), but OpenMesh also
    // reports it on its error stream, past the log's level and prefix: fitsManifold() spares
    // most refusals, and the stream is silenced for the rest (a corner whose boundary gaps
    // cannot be re-linked, which fitsManifold() does not model). qgi uses no other part of
    // OpenMesh that reports there.
    static const bool silenced = [] {
        omerr().disable();
        return true;
    }();
    (void)silenced;
    const bool hasUvs = !welded.uvs.empty();
    OmMesh mesh;
    mesh.reserve(welded.positions.size(), triangles.size() * 3 / 2 + 3, triangles.size());
    std::vector<OmMesh::VertexHandle> handles(welded.positions.size());
    const auto addVertex = [&](std::uint32_t w) {
        if (hasUvs) uvs.push_back(welded.uvs[w]);
        return mesh.add_vertex(toOm(welded.positions[w]));
    };
    const auto shared = [&](std::uint32_t w) {
        if (!handles[w].is_valid()) handles[w] = addVertex(w);
        return handles[w];
    };
    for (const Triangle& t : triangles) {
        const std::array<OmMesh::VertexHandle, 3> v{shared(t[0]), shared(t[1]), shared(t[2])};
        if (fitsManifold(mesh, v) && mesh.add_face(v[0], v[1], v[2]).is_valid()) continue;
        mesh.add_face(addVertex(t[0]), addVertex(t[1]), addVertex(t[2]));
    }
    return mesh;
}

// Longest-edge bisection: always split the longest edge left, at its midpoint, until none
// exceeds the bound. Splitting the longest edge first keeps triangle angles bounded away from
// zero; midpoints make both copies of an edge on a uv seam split at the same points.
void refine(OmMesh& mesh, std::vector<glm::vec2>& uvs, float maxEdgeLength, double maxTriangles,
            const TriangleBudget* budget) {
    const float max2 = maxEdgeLength * maxEdgeLength;
    const auto length2 = [&](OmMesh::HalfedgeHandle h) {
        const glm::vec3 d = toGlm(mesh.point(mesh.to_vertex_handle(h))) -
                            toGlm(mesh.point(mesh.from_vertex_handle(h)));
        return glm::dot(d, d);
    };
    // (squared length, edge index): the heap's top is the longest edge, ties by index.
    std::priority_queue<std::pair<float, int>> queue;
    for (const auto e : mesh.edges()) {
        const float l2 = length2(mesh.halfedge_handle(e, 0));
        if (l2 > max2) queue.emplace(l2, e.idx());
    }
    std::size_t splits = 0;
    while (!queue.empty()) {
        const OmMesh::EdgeHandle e(queue.top().second);
        queue.pop();
        const auto h = mesh.halfedge_handle(e, 0);
        const auto a = mesh.from_vertex_handle(h);
        const auto b = mesh.to_vertex_handle(h);
        const glm::vec3 mid = 0.5f * (toGlm(mesh.point(a)) + toGlm(mesh.point(b)));
        if (!uvs.empty())
            uvs.push_back(0.5f * (uvs[std::size_t(a.idx())] + uvs[std::size_t(b.idx())]));
        const auto m = mesh.add_vertex(toOm(mid));
        mesh.split(e, m);
        if (double(mesh.n_faces()) > maxTriangles)
            fail("mesh processing: maxEdgeLength ", maxEdgeLength, " m refines past the limit of ",
                 maxTriangles, " triangles");
        if (budget && (++splits & 4095) == 0 && budget->refused())
            fail("mesh processing: stopped, another mesh of the scene was refused");
        // The split edge's halves and the new edges to the opposite corners all meet at m;
        // no other edge changed, so the queue holds no stale entries.
        for (const auto out : mesh.voh_range(m)) {
            const float l2 = length2(out);
            if (l2 > max2) queue.emplace(l2, mesh.edge_handle(out).idx());
        }
    }
}

// Area-weighted vertex normals that keep creases. Around each vertex, faces joined across a
// smooth edge (dihedral angle at most creaseAngle) form one smooth group; each group becomes
// its own output vertex with the normalized sum of its faces' area-weighted normals.
Mesh extractWithNormals(const OmMesh& mesh, const std::vector<glm::vec2>& uvs, float creaseAngle) {
    std::vector<glm::vec3> weighted(mesh.n_faces()); // cross product: length is twice the area
    std::vector<glm::vec3> unit(mesh.n_faces());
    for (const auto f : mesh.faces()) {
        const auto h0 = mesh.halfedge_handle(f);
        const auto h1 = mesh.next_halfedge_handle(h0);
        const glm::vec3 a = toGlm(mesh.point(mesh.to_vertex_handle(h0)));
        const glm::vec3 b = toGlm(mesh.point(mesh.to_vertex_handle(h1)));
        const glm::vec3 c = toGlm(mesh.point(mesh.to_vertex_handle(mesh.next_halfedge_handle(h1))));
        const glm::vec3 n = glm::cross(b - a, c - a);
        const float length = glm::length(n);
        weighted[std::size_t(f.idx())] = n;
        unit[std::size_t(f.idx())] = length > 0.f ? n / length : glm::vec3(0.f);
    }
    const float cosCrease = std::cos(creaseAngle);
    std::vector<std::uint8_t> smooth(mesh.n_edges(), 0);
    for (const auto e : mesh.edges()) {
        if (mesh.is_boundary(e)) continue;
        const auto f0 = mesh.face_handle(mesh.halfedge_handle(e, 0)).idx();
        const auto f1 = mesh.face_handle(mesh.halfedge_handle(e, 1)).idx();
        smooth[std::size_t(e.idx())] =
            glm::dot(unit[std::size_t(f0)], unit[std::size_t(f1)]) >= cosCrease;
    }

    Mesh out;
    out.positions.reserve(mesh.n_vertices() * 11 / 10);
    out.normals.reserve(mesh.n_vertices() * 11 / 10);
    std::vector<std::uint32_t> corner(mesh.n_halfedges(), kNone); // incoming halfedge -> vertex
    std::vector<OmMesh::HalfedgeHandle> fan; // incoming halfedges that carry a face
    std::vector<std::size_t> parent;         // union-find over fan slots
    std::vector<glm::vec3> sums;
    const auto root = [&](std::size_t i) {
        while (parent[i] != i)
            i = parent[i] = parent[parent[i]];
        return i;
    };
    for (const auto v : mesh.vertices()) {
        fan.clear();
        for (const auto h : mesh.vih_range(v))
            if (!mesh.is_boundary(h)) fan.push_back(h);
        if (fan.empty()) continue; // a corner copy left unused by buildHalfedgeMesh
        parent.resize(fan.size());
        std::iota(parent.begin(), parent.end(), std::size_t(0));
        for (std::size_t i = 0; i < fan.size(); ++i) {
            if (!smooth[std::size_t(mesh.edge_handle(fan[i]).idx())]) continue;
            // The face across this edge holds v too; its incoming halfedge precedes the
            // opposite one.
            const auto across = mesh.prev_halfedge_handle(mesh.opposite_halfedge_handle(fan[i]));
            const auto j = std::size_t(std::find(fan.begin(), fan.end(), across) - fan.begin());
            QGI_ASSERT(j < fan.size(), "a face around a vertex is missing from its fan");
            const std::size_t ri = root(i), rj = root(j);
            parent[std::max(ri, rj)] = std::min(ri, rj);
        }
        sums.assign(fan.size(), glm::vec3(0.f));
        for (std::size_t i = 0; i < fan.size(); ++i)
            sums[root(i)] += weighted[std::size_t(mesh.face_handle(fan[i]).idx())];
        const glm::vec3 position = toGlm(mesh.point(v));
        for (std::size_t i = 0; i < fan.size(); ++i) {
            const std::size_t r = root(i);
            if (r == i) {
                const float length = glm::length(sums[r]);
                // Only faces folded back onto each other cancel; fall back to one face's normal.
                const glm::vec3& faceUnit = unit[std::size_t(mesh.face_handle(fan[i]).idx())];
                const glm::vec3 normal = length > 0.f                 ? sums[r] / length
                                         : faceUnit != glm::vec3(0.f) ? faceUnit
                                                                      : glm::vec3(0.f, 1.f, 0.f);
                corner[std::size_t(fan[i].idx())] = std::uint32_t(out.positions.size());
                out.positions.push_back(position);
                out.normals.push_back(normal);
                if (!uvs.empty()) out.uvs.push_back(uvs[std::size_t(v.idx())]);
            } else {
                corner[std::size_t(fan[i].idx())] = corner[std::size_t(fan[r].idx())];
            }
        }
    }
    out.indices.reserve(mesh.n_faces() * 3);
    for (const auto f : mesh.faces())
        for (const auto h : mesh.fh_range(f))
            out.indices.push_back(corner[std::size_t(h.idx())]);
    return out;
}

} // namespace

Mesh processMesh(const Mesh& raw, const MeshProcessingOptions& options) {
    checkOptions(options);
    checkInput(raw);
    const WeldedVertices welded = weldVertices(raw, options.weldDistance);
    double refinedEstimate = 0.0;
    const std::vector<Triangle> triangles = cleanTriangles(raw, welded, options, refinedEstimate);
    if (refinedEstimate > options.maxTriangles) {
        if (options.budget) options.budget->refuse();
        fail("mesh processing: maxEdgeLength ", options.maxEdgeLength, " m would refine ",
             triangles.size(), " triangles into more than the limit of ", options.maxTriangles,
             " (the bound is too small for the mesh, or its triangles are far thinner than it)");
    }
    const double made = options.maxEdgeLength > 0.f ? refinedEstimate : double(triangles.size());
    if (options.budget && !options.budget->take(made))
        fail("mesh processing: ",
             options.maxEdgeLength > 0.f ? str("refinement to ", options.maxEdgeLength, " m makes")
                                         : std::string("the mesh has"),
             " more triangles than the ", options.budget->left(),
             " the scene's other meshes left of its limit");
    std::vector<glm::vec2> uvs;
    OmMesh mesh = buildHalfedgeMesh(welded, triangles, uvs);
    if (options.maxEdgeLength > 0.f)
        refine(mesh, uvs, options.maxEdgeLength, options.maxTriangles, options.budget);
    return extractWithNormals(mesh, uvs, options.creaseAngle);
}

double meshArea(const Mesh& mesh) {
    QGI_ASSERT(mesh.indices.size() % 3 == 0, "index count is not a multiple of 3");
    double area = 0.0;
    for (std::size_t k = 0; k < mesh.indices.size(); k += 3) {
        QGI_ASSERT(std::max({mesh.indices[k], mesh.indices[k + 1], mesh.indices[k + 2]}) <
                       mesh.positions.size(),
                   "index out of range");
        const glm::dvec3 a(mesh.positions[mesh.indices[k]]);
        const glm::dvec3 b(mesh.positions[mesh.indices[k + 1]]);
        const glm::dvec3 c(mesh.positions[mesh.indices[k + 2]]);
        area += 0.5 * glm::length(glm::cross(b - a, c - a));
    }
    return area;
}

} // namespace qgi
