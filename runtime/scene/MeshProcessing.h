#pragma once

#include "components/Mesh.h"

#include <glm/vec3.hpp>

#include <atomic>

namespace qgi {

/// Most triangles a scene may hold after refinement, every instance counted (about 1.5 GB of
/// mesh data; the atrium has 0.3M).
inline constexpr double kSceneMaxTriangles = 2e7;

/// Triangles that several processMesh calls, on any threads, may make together: a scene's
/// limit when its meshes are processed in parallel. Each call takes its refined count before
/// it refines, so a scene past the limit is refused before the memory goes to it.
class TriangleBudget {
public:
    explicit TriangleBudget(double triangles) : mLeft(triangles) {}
    /// Takes `triangles` when that many are left; otherwise takes nothing, marks the budget
    /// refused (the other meshes' refinements then stop early) and returns false.
    bool take(double triangles) {
        double left = mLeft.load();
        do
            if (triangles > left) {
                refuse();
                return false;
            }
        while (!mLeft.compare_exchange_weak(left, left - triangles));
        return true;
    }
    double left() const { return mLeft.load(); }
    /// Marks the budget refused: a mesh failed, so the scene will not load.
    void refuse() { mRefused.store(true); }
    bool refused() const { return mRefused.load(std::memory_order_relaxed); }

private:
    std::atomic<double> mLeft;
    std::atomic<bool> mRefused{false};
};

struct MeshProcessingOptions {
    /// Vertices closer than this (metres) with matching uv are merged into one.
    float weldDistance = 1e-5f;
    /// Dihedral angle (radians) above which an edge is a hard crease: vertices along it keep one
    /// normal per side instead of an averaged one.
    float creaseAngle = 0.6981317f; // 40 degrees
    /// Split edges until none is longer than this (metres); 0 or less: no refinement.
    float maxEdgeLength = 0.f;
    /// Triangles with area below this (m^2), or with a degenerate (collinear) shape, are removed.
    float minTriangleArea = 1e-12f;
    /// Refuse (qgi::Error) an edge bound that would refine past this many triangles: a mistake,
    /// not a scene (20M triangles are about 1.5 GB of mesh data).
    double maxTriangles = kSceneMaxTriangles;
    /// When set, the mesh's refined triangle count is taken from it before refining (a
    /// qgi::Error when it cannot give them), so meshes processed together share one limit.
    TriangleBudget* budget = nullptr;
};

/// Cleans and refines a raw triangle mesh for per-vertex lighting (OpenMesh): welds duplicate
/// vertices, removes degenerate triangles, splits long edges, and computes area-weighted
/// normals that keep hard creases (a vertex on a crease is duplicated, one copy per smooth
/// group). `raw.normals` may be empty; `raw.uvs` is kept (interpolated through refinement).
/// Throws qgi::Error if a position is NaN or infinite, or an index is out of range.
Mesh processMesh(const Mesh& raw, const MeshProcessingOptions& options);

/// processMesh's test for a triangle it keeps, on the corners given (it applies it to welded
/// corners in the mesh's units): area at least `minArea` and not a sliver (its height at
/// least a millionth of its longest edge).
bool hasArea(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c, double minArea);

/// Total surface area of a mesh, m^2.
double meshArea(const Mesh& mesh);

} // namespace qgi
