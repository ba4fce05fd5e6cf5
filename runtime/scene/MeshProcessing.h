#pragma once

#include "components/Mesh.h"

#include <glm/vec3.hpp>

namespace qgi {

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
    double maxTriangles = 2e7;
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
