#include "runtime/scene/MeshProcessing.h"

#include "runtime/core/Error.h"
#include "runtime/scene/ProceduralMesh.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <tuple>
#include <vector>

namespace qgi {
namespace {

// Positions are floats: one rounding moves a coordinate of magnitude m by at most m * 2^-24.
constexpr double kFloatEpsilon = 1.0 / 16777216.0;

double angleBetween(const glm::dvec3& a, const glm::dvec3& b) {
    return std::atan2(glm::length(glm::cross(a, b)), glm::dot(a, b)); // stable near 0
}

glm::dvec3 corner(const Mesh& m, std::size_t t, int k) {
    return glm::dvec3(m.positions[m.indices[3 * t + std::size_t(k)]]);
}

glm::dvec3 faceNormal(const Mesh& m, std::size_t t) {
    const glm::dvec3 a = corner(m, t, 0), b = corner(m, t, 1), c = corner(m, t, 2);
    return glm::normalize(glm::cross(b - a, c - a));
}

std::size_t triangleCount(const Mesh& m) {
    return m.indices.size() / 3;
}

double longestEdge(const Mesh& m) {
    double longest = 0.0;
    for (std::size_t t = 0; t < triangleCount(m); ++t)
        for (int k = 0; k < 3; ++k)
            longest = std::max(longest, glm::length(corner(m, t, (k + 1) % 3) - corner(m, t, k)));
    return longest;
}

double totalEdgeLength(const Mesh& m) {
    double total = 0.0;
    for (std::size_t t = 0; t < triangleCount(m); ++t)
        for (int k = 0; k < 3; ++k)
            total += glm::length(corner(m, t, (k + 1) % 3) - corner(m, t, k));
    return total;
}

double smallestAngle(const Mesh& m) {
    double smallest = glm::pi<double>();
    for (std::size_t t = 0; t < triangleCount(m); ++t)
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 p = corner(m, t, k);
            smallest = std::min(smallest, angleBetween(corner(m, t, (k + 1) % 3) - p,
                                                       corner(m, t, (k + 2) % 3) - p));
        }
    return smallest;
}

std::size_t distinctPositions(const Mesh& m) {
    std::set<std::tuple<float, float, float>> distinct;
    for (const glm::vec3& p : m.positions)
        distinct.emplace(p.x, p.y, p.z);
    return distinct.size();
}

double shortestEdge(const Mesh& m) {
    double shortest = std::numeric_limits<double>::max();
    for (std::size_t t = 0; t < triangleCount(m); ++t)
        for (int k = 0; k < 3; ++k)
            shortest = std::min(shortest, glm::length(corner(m, t, (k + 1) % 3) - corner(m, t, k)));
    return shortest;
}

// How far refinement may move a vertex from its exact place: a vertex made by k levels of
// midpoint splits carries at most k roundings of sqrt(3) * maxCoordinate * 2^-24 each, and
// halving the longest edge twice at least halves every edge, so there are at most
// 2 * ceil(log2(inputEdge / maxEdge)) + 2 levels.
double refinementDisplacement(double maxCoordinate, double inputEdge, double maxEdge) {
    const double levels = 2.0 * std::ceil(std::log2(inputEdge / maxEdge)) + 2.0;
    return levels * std::sqrt(3.0) * maxCoordinate * kFloatEpsilon;
}

// Area error bound of refinement. Moving a vertex inside the plane of all its triangles only
// re-partitions the area, so the first-order change comes from vertices on rims and creases:
// at most their total length times the displacement.
double refinementAreaTolerance(double rimLength, double maxCoordinate, double inputEdge,
                               double maxEdge) {
    return rimLength * refinementDisplacement(maxCoordinate, inputEdge, maxEdge);
}

// Normal direction error bound (radians): displacing a triangle's corners by d tilts its
// normal by at most about 2 d / (its shortest edge).
double refinementNormalTolerance(const Mesh& out, double maxCoordinate, double inputEdge,
                                 double maxEdge) {
    return 2.0 * refinementDisplacement(maxCoordinate, inputEdge, maxEdge) / shortestEdge(out);
}

/// A unit cube centred on the origin as an unindexed soup: 12 triangles, 36 vertices.
Mesh soupCube() {
    ProceduralMesh cube;
    cube.addBox(glm::vec3(-0.5f), glm::vec3(0.5f));
    return std::move(cube).release();
}

MeshProcessingOptions noRefinement() {
    return MeshProcessingOptions{};
}

MeshProcessingOptions refinedTo(float maxEdge) {
    MeshProcessingOptions options;
    options.maxEdgeLength = maxEdge;
    return options;
}

void expectUnitNormals(const Mesh& m) {
    ASSERT_EQ(m.normals.size(), m.positions.size());
    for (const glm::vec3& n : m.normals)
        EXPECT_NEAR(glm::length(n), 1.f, 1e-6f);
}

TEST(MeshProcessing, EmptyMeshGivesEmptyMesh) {
    const Mesh out = processMesh(Mesh{}, refinedTo(0.1f));
    EXPECT_TRUE(out.positions.empty());
    EXPECT_TRUE(out.normals.empty());
    EXPECT_TRUE(out.indices.empty());
    EXPECT_EQ(meshArea(out), 0.0);
}

TEST(MeshProcessing, BadInputThrows) {
    Mesh nan = soupCube();
    nan.positions[7].y = std::numeric_limits<float>::quiet_NaN();
    EXPECT_THROW(processMesh(nan, noRefinement()), Error);

    Mesh inf = soupCube();
    inf.positions[0].x = std::numeric_limits<float>::infinity();
    EXPECT_THROW(processMesh(inf, noRefinement()), Error);

    Mesh outOfRange = soupCube();
    outOfRange.indices[5] = std::uint32_t(outOfRange.positions.size());
    EXPECT_THROW(processMesh(outOfRange, noRefinement()), Error);

    Mesh partial = soupCube();
    partial.indices.pop_back();
    EXPECT_THROW(processMesh(partial, noRefinement()), Error);

    Mesh fewUvs = soupCube();
    fewUvs.uvs.resize(3);
    EXPECT_THROW(processMesh(fewUvs, noRefinement()), Error);

    MeshProcessingOptions nanBound;
    nanBound.maxEdgeLength = std::numeric_limits<float>::quiet_NaN();
    EXPECT_THROW(processMesh(soupCube(), nanBound), Error);

    // 6 m^2 at a 10 um bound would be ~5e11 triangles: refused up front, not attempted.
    EXPECT_THROW(processMesh(soupCube(), refinedTo(1e-5f)), Error);
}

// Longest-edge bisection of a long thin triangle leaves a piece with two long sides at every
// split, so it makes far more triangles than area or length suggest: this 100 m x 1 cm sliver
// at a 1 m bound becomes 3^7 = 2187 pieces, where area and length alone said about 100. The
// triangle limit must hold against what refinement really makes (a fuzzed glTF with such a
// sliver refined without end while its estimate sat far below the limit).
TEST(MeshProcessing, TheTriangleLimitHoldsForSlivers) {
    Mesh sliver;
    sliver.positions = {{0.f, 0.f, 0.f}, {100.f, 0.f, 0.f}, {0.f, 0.01f, 0.f}};
    sliver.indices = {0, 1, 2};
    MeshProcessingOptions options = refinedTo(1.f);
    options.maxTriangles = 2187;
    const Mesh out = processMesh(sliver, options);
    EXPECT_EQ(out.indices.size() / 3, 2187u);
    double longest = 0.0;
    for (std::size_t k = 0; k < out.indices.size(); k += 3)
        for (int i = 0; i < 3; ++i)
            longest = std::max(longest,
                               double(glm::distance(out.positions[out.indices[k + i]],
                                                    out.positions[out.indices[k + (i + 1) % 3]])));
    EXPECT_LE(longest, 1.0);

    options.maxTriangles = 2186;
    try {
        processMesh(sliver, options);
        ADD_FAILURE() << "a refinement past the limit was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("more than the limit of 2186"), std::string::npos)
            << e.what();
    }
}

// The limit is checked before refining by counting what bisection will make, so the count
// must be exact: a fan of four triangles on integer corners (equal edges everywhere, where a
// tie could split a triangle another way) at four bounds, 400 times. Each refines at a limit
// of exactly its triangle count, and one fewer is refused by the count, before any splitting.
TEST(MeshProcessing, TheTriangleCountBeforeRefiningIsExact) {
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> coord(0, 6);
    const float bounds[] = {1.f, 0.7f, 0.45f, 1.5f};
    int refined = 0;
    for (int trial = 0; trial < 400; ++trial) {
        Mesh fan;
        for (int i = 0; i < 6; ++i)
            fan.positions.push_back({float(coord(rng)), float(coord(rng)), float(coord(rng) % 2)});
        fan.indices = {0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5};
        MeshProcessingOptions options = refinedTo(bounds[trial % 4]);
        const Mesh out = processMesh(fan, options);
        const double triangles = double(out.indices.size() / 3);
        if (triangles <= double(fan.indices.size() / 3)) continue; // nothing split
        ++refined;
        options.maxTriangles = triangles;
        EXPECT_NO_THROW(processMesh(fan, options)) << "trial " << trial;
        options.maxTriangles = triangles - 1;
        try {
            processMesh(fan, options);
            ADD_FAILURE() << "trial " << trial << ": " << triangles << " triangles past the limit";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("would refine"), std::string::npos)
                << "trial " << trial << ": " << e.what();
        }
    }
    EXPECT_GT(refined, 300);
}

// Meshes processed together (a built-in scene's, in parallel) share one limit: each takes its
// refined count before refining, and the one that finds too little left is refused with the
// figures, while the budget stops the others' refinements early.
TEST(MeshProcessing, MeshesSharingABudgetShareItsLimit) {
    Mesh sliver;
    sliver.positions = {{0.f, 0.f, 0.f}, {100.f, 0.f, 0.f}, {0.f, 0.01f, 0.f}};
    sliver.indices = {0, 1, 2};
    TriangleBudget budget(3000.0);
    MeshProcessingOptions options = refinedTo(1.f);
    options.budget = &budget;
    EXPECT_EQ(processMesh(sliver, options).indices.size() / 3, 2187u);
    EXPECT_EQ(budget.left(), 3000.0 - 2187.0);
    EXPECT_FALSE(budget.refused());
    try {
        processMesh(sliver, options);
        ADD_FAILURE() << "the second mesh was given triangles the budget does not have";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("refinement to 1 m makes more triangles than the 813 "
                                             "the scene's other meshes left of its limit"),
                  std::string::npos)
            << e.what();
    }
    EXPECT_TRUE(budget.refused());
    EXPECT_EQ(budget.left(), 813.0); // a refusal takes nothing
}

TEST(MeshProcessing, SoupCubeWeldsToEightCornersAndSplitsCreasesToTwentyFour) {
    MeshProcessingOptions noCreases;
    noCreases.creaseAngle = glm::pi<float>();
    const Mesh welded = processMesh(soupCube(), noCreases);
    EXPECT_EQ(welded.positions.size(), 8u);
    EXPECT_EQ(triangleCount(welded), 12u);
    // Smoothed across every edge, a corner's normal points into its own octant.
    for (std::size_t i = 0; i < welded.positions.size(); ++i)
        for (int axis = 0; axis < 3; ++axis)
            EXPECT_GT(welded.normals[i][axis] * welded.positions[i][axis], 0.f);

    const Mesh creased = processMesh(soupCube(), noRefinement());
    EXPECT_EQ(creased.positions.size(), 24u); // 8 corners x 3 faces
    EXPECT_EQ(triangleCount(creased), 12u);
    expectUnitNormals(creased);
    for (std::size_t t = 0; t < triangleCount(creased); ++t)
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 n(creased.normals[creased.indices[3 * t + std::size_t(k)]]);
            EXPECT_LT(angleBetween(n, faceNormal(creased, t)), 1e-6);
        }
}

TEST(MeshProcessing, WeldsWithinDistanceButKeepsUvSeams) {
    // Two unit quads sharing the edge x = 1, the second one's copy of it displaced by less
    // than the weld distance.
    MeshProcessingOptions options;
    options.creaseAngle = glm::pi<float>();
    options.weldDistance = 1e-4f;
    Mesh m;
    m.positions = {{0, 0, 0},        {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                   {1.00005f, 0, 0}, {2, 0, 0}, {2, 1, 0}, {1, 1.00005f, 0}};
    m.indices = {0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7};
    EXPECT_EQ(processMesh(m, options).positions.size(), 6u);

    // The same quads with a uv seam along the shared edge stay apart.
    m.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {0, 0}, {1, 0}, {1, 1}, {0, 1}};
    const Mesh seam = processMesh(m, options);
    EXPECT_EQ(seam.positions.size(), 8u);
    ASSERT_EQ(seam.uvs.size(), 8u);

    // Displaced by more than the weld distance: no weld either.
    options.weldDistance = 1e-5f;
    m.uvs.clear();
    EXPECT_EQ(processMesh(m, options).positions.size(), 8u);
}

TEST(MeshProcessing, RemovesDegenerateAndDuplicateTriangles) {
    Mesh m;
    m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {2, 0, 0}, {1e-7f, 1e-7f, 0}};
    m.indices = {
        0, 1, 2, // the one good triangle
        0, 1, 3, // collinear
        0, 0, 2, // repeated corner
        0, 4, 2, // welded to a repeated corner (vertex 4 lies within weldDistance of 0)
        1, 2, 0, // the good triangle again, starting at another corner
    };
    const Mesh out = processMesh(m, noRefinement());
    ASSERT_EQ(triangleCount(out), 1u);
    EXPECT_NEAR(meshArea(out), 0.5, 1e-7);

    // Below minTriangleArea, gone too.
    MeshProcessingOptions strict;
    strict.minTriangleArea = 1.f;
    EXPECT_EQ(triangleCount(processMesh(m, strict)), 0u);
}

TEST(MeshProcessing, RefinementBoundsEdgesKeepsAreaAndAngles) {
    const float maxEdge = 0.05f;
    // A 2 x 1 rectangle (open rim 6 m) and the unit cube (closed, 12 m of creases).
    Mesh rectangle;
    rectangle.positions = {{-1, -0.5f, 0}, {1, -0.5f, 0}, {1, 0.5f, 0}, {-1, 0.5f, 0}};
    rectangle.indices = {0, 1, 2, 0, 2, 3};
    struct Case {
        Mesh raw;
        double rimLength;
    };
    for (const Case& c : {Case{rectangle, 6.0}, Case{soupCube(), 12.0}}) {
        const Mesh out = processMesh(c.raw, refinedTo(maxEdge));
        expectUnitNormals(out);
        // The squared-length test runs on floats: 1e-6 relative covers its rounding.
        EXPECT_LE(longestEdge(out), maxEdge * (1.0 + 1e-6));
        const double before = meshArea(c.raw);
        const double tolerance =
            refinementAreaTolerance(c.rimLength, 1.0, longestEdge(c.raw), maxEdge);
        // One lost triangle (area >= maxEdge^2 / 8) would break the bound many times over.
        ASSERT_LT(tolerance, maxEdge * maxEdge / 8.0 / 10.0);
        EXPECT_NEAR(meshArea(out), before, tolerance);
        // Longest-edge bisection keeps every angle above half the input's smallest angle
        // (Rivara); an arbitrary split order would not.
        EXPECT_GE(smallestAngle(out), 0.5 * smallestAngle(c.raw) * (1.0 - 1e-6));
        // No triangle with edges <= maxEdge is larger than the equilateral one.
        EXPECT_GE(double(triangleCount(out)), before / (std::sqrt(3.0) / 4.0 * maxEdge * maxEdge));
    }
}

TEST(MeshProcessing, RefinedCubeKeepsFlatFaces) {
    const Mesh raw = soupCube();
    const Mesh out = processMesh(raw, refinedTo(0.1f));
    const double tolerance = refinementNormalTolerance(out, 0.5, longestEdge(raw), 0.1);
    ASSERT_LT(tolerance, 1e-2); // far below the 90 degrees of a crease
    for (std::size_t t = 0; t < triangleCount(out); ++t)
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 n(out.normals[out.indices[3 * t + std::size_t(k)]]);
            EXPECT_LT(angleBetween(n, faceNormal(out, t)), tolerance);
        }
}

TEST(MeshProcessing, RefinedCylinderHasFlatCapsAndSmoothSide) {
    constexpr int kSegments = 48;
    constexpr float kRadius = 0.5f, kHeight = 1.f;
    ProceduralMesh cylinder;
    const glm::vec2 profile[] = {{0.f, 0.f}, {kRadius, 0.f}, {kRadius, kHeight}, {0.f, kHeight}};
    cylinder.addLathe(glm::vec3(0.f), profile, kSegments);
    const Mesh raw = std::move(cylinder).release();
    const Mesh out = processMesh(raw, refinedTo(0.04f));
    expectUnitNormals(out);
    // A side face's normal points at the middle of its segment; every point of the face is
    // within half a segment of it in azimuth, and a vertex normal averages such normals.
    const double halfSegment = glm::pi<double>() / kSegments;
    const double tolerance = refinementNormalTolerance(out, kHeight, longestEdge(raw), 0.04);
    ASSERT_LT(tolerance, 0.1 * halfSegment);
    std::size_t side = 0, caps = 0;
    for (std::size_t i = 0; i < out.positions.size(); ++i) {
        const glm::dvec3 p(out.positions[i]);
        const glm::dvec3 n(out.normals[i]);
        if (std::abs(n.y) > 0.5) {
            ++caps;
            EXPECT_LT(angleBetween(n, glm::dvec3(0.0, p.y > 0.5 ? 1.0 : -1.0, 0.0)), tolerance);
            EXPECT_NEAR(p.y, p.y > 0.5 ? kHeight : 0.0, 1e-6);
        } else {
            ++side;
            EXPECT_LT(std::abs(n.y), tolerance);
            EXPECT_LE(angleBetween(n, glm::dvec3(p.x, 0.0, p.z)), halfSegment + tolerance);
        }
    }
    EXPECT_GT(side, 0u);
    EXPECT_GT(caps, 0u);
}

TEST(MeshProcessing, RefinedSphereStaysSmooth) {
    ProceduralMesh sphere;
    sphere.addSphere(glm::vec3(0.f), 1.f, 32, 16);
    const Mesh raw = std::move(sphere).release();
    // Every point of an input face sees the origin within the face's angular circumradius of
    // its normal (the face's circumcircle lies on the sphere), so every vertex normal, an
    // average of such face normals, lies within the largest circumradius of the analytic one.
    double bound = 0.0;
    for (std::size_t t = 0; t < triangleCount(raw); ++t)
        for (int k = 0; k < 3; ++k)
            bound = std::max(bound, angleBetween(faceNormal(raw, t), corner(raw, t, k)));
    ASSERT_LT(bound, 0.2); // a fine tessellation: about 6.5 degrees

    const Mesh out = processMesh(raw, refinedTo(0.05f));
    expectUnitNormals(out);
    EXPECT_EQ(distinctPositions(out), out.positions.size()); // no crease anywhere
    const double tolerance = refinementNormalTolerance(out, 1.0, longestEdge(raw), 0.05);
    for (std::size_t i = 0; i < out.positions.size(); ++i)
        EXPECT_LE(angleBetween(glm::dvec3(out.normals[i]), glm::dvec3(out.positions[i])),
                  bound + tolerance);
}

TEST(MeshProcessing, RefinementInterpolatesUvs) {
    // uv = (x, y) on a planar quad: midpoint splits must keep that linear relation.
    Mesh m;
    m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 0.5f, 0}, {0, 0.5f, 0}};
    m.uvs = {{0, 0}, {1, 0}, {1, 0.5f}, {0, 0.5f}};
    m.indices = {0, 1, 2, 0, 2, 3};
    const Mesh out = processMesh(m, refinedTo(0.1f));
    ASSERT_EQ(out.uvs.size(), out.positions.size());
    ASSERT_GT(out.positions.size(), 4u);
    for (std::size_t i = 0; i < out.positions.size(); ++i) {
        EXPECT_NEAR(out.uvs[i].x, out.positions[i].x, 1e-6f);
        EXPECT_NEAR(out.uvs[i].y, out.positions[i].y, 1e-6f);
    }
}

TEST(MeshProcessing, NonManifoldInputKeepsEveryTriangle) {
    // Three triangles on one edge (a book with three pages), a fourth touching the first only
    // at a vertex, and a fifth wound against the first across their shared edge.
    Mesh m;
    m.positions = {{0, 0, 0}, {0, 1, 0}, {1, 0, 0}, {-1, 0, 0},
                   {0, 0, 1}, {0, 2, 0}, {1, 2, 0}, {1, 1, 0}};
    m.indices = {0, 1, 2, 1, 0, 3, 0, 1, 4, 1, 5, 6, 1, 2, 7};
    const float maxEdge = 0.3f;
    const Mesh out = processMesh(m, refinedTo(maxEdge));
    expectUnitNormals(out);
    EXPECT_LE(longestEdge(out), maxEdge * (1.0 + 1e-6));
    // Every input edge may end up on a rim here, so all of them count as rim length.
    EXPECT_NEAR(meshArea(out), meshArea(m),
                refinementAreaTolerance(totalEdgeLength(m), 2.0, longestEdge(m), maxEdge));
    const double tolerance = refinementNormalTolerance(out, 2.0, longestEdge(m), maxEdge);
    for (std::size_t t = 0; t < triangleCount(out); ++t)
        for (int k = 0; k < 3; ++k) {
            const glm::dvec3 n(out.normals[out.indices[3 * t + std::size_t(k)]]);
            // Pages joined in the mesh are coplanar, the others are cut apart or meet at
            // 90 degrees or more: each vertex normal is its own face's.
            EXPECT_LT(angleBetween(n, faceNormal(out, t)), tolerance);
        }
}

} // namespace
} // namespace qgi
