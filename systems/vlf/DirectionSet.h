#pragma once

#include <glm/vec3.hpp>

#include <array>
#include <cstdint>
#include <random>
#include <vector>

namespace qgi::vlf {

/// One corner of a spherical triangle of the direction set: the stored direction it refers to
/// and the orientation in which it appears there (an equator corner with azimuth in [pi, 2 pi)
/// is the stored direction reversed).
struct OrientedDirection {
    std::uint32_t index = 0; ///< into DirectionSet::directions()
    float sign = 1.f;        ///< +1 or -1: the corner is sign * directions()[index]
};

/// The spherical triangle that contains a query direction, with the barycentric weights of the
/// query on the triangle's flat chord (>= 0, summing to 1; exactly 1 at a stored direction).
struct DirectionTriangle {
    std::array<OrientedDirection, 3> corners;
    std::array<float, 3> weights{};
};

/// A jittered transport direction inside one stored direction's cell (seed 002, section 2.8 of
/// the digest): `direction` is a unit vector on the stored direction's side of the sphere and
/// `solidAngle` (sr) the weight of the sample; averaged over samples it equals the cell's solid
/// angle, so quadrature with it is unbiased.
struct DirectionSample {
    glm::vec3 direction{0.f};
    float solidAngle = 0.f;
};

/** The octahedral direction set of seed 002 (thesis section 4.2.2, digest section 1.3).
 *
 *  Level L subdivides the four upper faces of the octahedron L times 1 -> 4, with the edge
 *  midpoints projected onto the unit sphere. The vertices in the closed upper hemisphere
 *  (z >= 0) are the stored directions, each standing for a line in both orientations; the
 *  equator is held once, with azimuth in [0, pi). Count: 2 * 4^L + 1 (33, 129, 513, 2049 at
 *  L = 2..5).
 *
 *  Cells: each spherical triangle is split into three parts by the segments joining its chord
 *  centroid to its edge midpoints; a direction's cell is the union of the parts at its corners
 *  (projected onto the sphere), so the cells tile the hemisphere and their solid angles sum to
 *  2 pi. cellSolidAngle is the exact spherical area of a cell.
 *
 *  Lookup: fold the query into the upper hemisphere, pick the root triangle by quadrant, then
 *  descend L levels choosing one of four children by three plane-side tests (O(L), no search).
 *  Immutable after construction, so queries are thread safe.                                */
class DirectionSet {
public:
    /// Throws qgi::Error unless 0 <= level <= 7.
    explicit DirectionSet(int level);

    int level() const { return mLevel; }
    std::size_t size() const { return mDirections.size(); }
    const std::vector<glm::vec3>& directions() const { return mDirections; }
    const glm::vec3& direction(std::size_t i) const { return mDirections[i]; }
    /// Solid angle of direction i's cell, sr. Sums to 2 pi over the set.
    float cellSolidAngle(std::size_t i) const { return mCellSolidAngle[i]; }
    /// Solid-angle correction factor of the thesis: cell solid angle / (2 pi / size()).
    float solidAngleWeight(std::size_t i) const;
    /// Number of spherical triangles in the upper hemisphere: 4 * 4^L.
    std::size_t triangleCount() const { return mTriangles.size(); }

    /// The triangle containing `direction` (any non-zero vector; the lower hemisphere is
    /// reached through the antipode, so the returned corners may be reversed stored
    /// directions). Weights are the query's barycentrics on the triangle's flat chord.
    DirectionTriangle locate(const glm::vec3& direction) const;
    /// Index of the triangle that locate() finds (for tests against brute force).
    std::uint32_t locateTriangle(const glm::vec3& direction) const;
    /// The corners of triangle t.
    const std::array<OrientedDirection, 3>& triangle(std::uint32_t t) const {
        return mTriangles[t];
    }

    /// A jittered direction in direction i's cell (seeded by the caller's generator), on the
    /// side of `sign * direction(i)`. solidAngle is the sample's quadrature weight (see
    /// DirectionSample).
    DirectionSample sampleCell(std::size_t i, float sign, std::mt19937& rng) const;

private:
    struct CellPart { // the flat quadrilateral corner, centroid-side of one triangle corner
        glm::vec3 corner, midA, centroid, midB; // on the triangle's chord plane
        float sign = 1.f;                       // orientation of the corner's stored direction
    };
    std::uint32_t descend(const glm::vec3& upperDirection) const;

    int mLevel = 0;
    std::vector<glm::vec3> mDirections;
    std::vector<float> mCellSolidAngle;
    std::vector<std::array<OrientedDirection, 3>> mTriangles; ///< leaf order = descent order
    std::vector<std::array<glm::vec3, 3>> mTriangleCorners;   ///< oriented corner vectors
    std::vector<std::vector<CellPart>> mCellParts;            ///< per direction
};

/// Orthonormal frame of a parallel subfield: u, v span its plane, n is its direction
/// (right-handed: cross(u, v) = n). Built with the branch-free choice of a helper axis, so
/// it is continuous except at one pole.
struct SubfieldFrame {
    glm::vec3 u{1.f, 0.f, 0.f}, v{0.f, 1.f, 0.f}, n{0.f, 0.f, 1.f};
};
SubfieldFrame makeSubfieldFrame(const glm::vec3& direction);

} // namespace qgi::vlf
