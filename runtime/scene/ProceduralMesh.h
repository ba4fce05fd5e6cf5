#pragma once

#include "components/Mesh.h"

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <cstddef>
#include <span>

namespace qgi {

/// A raw triangle soup assembled from simple shapes, for the built-in scenes. Every shape is
/// given the direction its front faces look, and each triangle is wound counter-clockwise seen
/// from that side, so no call site has to get a winding order right. Shapes share no vertices;
/// processMesh welds them, splits long edges and computes the normals.
class ProceduralMesh {
public:
    /// Faces of an axis-aligned box; leave out the hidden ones (resting on the floor, buried in
    /// a wall) so they cost no triangles and catch no photons inside solid matter.
    enum BoxFaces : unsigned {
        kMinX = 1u << 0,
        kMaxX = 1u << 1,
        kMinY = 1u << 2,
        kMaxY = 1u << 3,
        kMinZ = 1u << 4,
        kMaxZ = 1u << 5,
        kAllFaces = 0x3fu,
    };

    void addTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                     const glm::vec3& facing);
    /// A planar quad; a, b, c, d go around its rim in either direction.
    void addQuad(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const glm::vec3& d,
                 const glm::vec3& facing);
    /// Axis-aligned box with outward faces.
    void addBox(const glm::vec3& min, const glm::vec3& max, unsigned faces = kAllFaces);

    /// Surface of revolution about the vertical axis through `base`. `profile` holds
    /// (radius, height) points; the surface faces to the right of the profile's direction of
    /// travel in the (radius, height) plane: going up at a constant radius faces outwards,
    /// going inwards at a constant height faces up. Zero radius closes the surface at the axis.
    void addLathe(const glm::vec3& base, std::span<const glm::vec2> profile, int segments);
    /// Vertical cylinder side from base.y to base.y + height, facing outwards (or inwards).
    void addCylinder(const glm::vec3& base, float radius, float height, int segments,
                     bool inward = false);
    /// UV sphere, `rings` bands from pole to pole.
    void addSphere(const glm::vec3& center, float radius, int segments, int rings);
    /// Vertical capsule of total `height` (caps included) centred on `center`.
    void addCapsule(const glm::vec3& center, float radius, float height, int segments, int rings);

    /// Appends another soup with its positions transformed by `transform` (a rigid motion,
    /// optionally uniformly scaled: windings stay front-facing).
    void append(const ProceduralMesh& other, const glm::mat4& transform);

    std::size_t triangleCount() const { return mMesh.indices.size() / 3; }
    /// Moves the soup out (positions and indices; no normals: processMesh computes them).
    Mesh release() &&;

private:
    Mesh mMesh;
};

} // namespace qgi
