#pragma once

#include "runtime/ecs/Entity.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

namespace qgi {

class Registry;

/** Every StaticMesh and MobileMesh as the irradiance estimators see them: vertices (position,
 *  unit normal) and triangles in world space, numbered globally with static meshes first, and
 *  the writing of estimates into each entity's VertexIrradiance with its dirty ranges.
 *  build() is set-up and throws; the rest is for the frame and never throws.             */
class ReceiverSet {
public:
    /// One mesh: a slice of the set's vertex and triangle arrays.
    struct Receiver {
        Entity entity;
        bool mobile = false;
        std::uint32_t firstVertex = 0; ///< into the set's vertex arrays
        std::uint32_t vertexCount = 0;
        std::uint32_t firstTriangle = 0; ///< into the set's triangle arrays
        std::uint32_t triangleCount = 0;
        glm::mat4 pose{1.f}; ///< object to world, as the world-space arrays have it
        Aabb bounds;         ///< world bounds of its vertices at `pose`
        /// Mobiles: every vertex's tangent plane has the whole mesh behind it, within
        /// kConvexTolerance (a convex mesh with outward normals). A segment that starts on
        /// such a mesh cannot cross one of its discs from the front. Checked once in object
        /// space (any invertible pose keeps it); false for meshes over kConvexCheckPairs.
        bool convex = false;
    };

    /// How far (relative to the mesh's bounding diagonal) a vertex may lie in front of another
    /// vertex's tangent plane in a mesh still called convex: rounding of flat faces.
    static constexpr float kConvexTolerance = 1e-5f;
    /// The convexity check compares every vertex with the tangent plane of each distinct
    /// normal; mobiles whose vertices times distinct normals pass this are not checked (and
    /// not called convex). A box of any refinement is checked; a smooth mesh, up to 8192
    /// vertices.
    static constexpr std::uint64_t kConvexCheckPairs = std::uint64_t(8192) * 8192;

    /// Reads StaticMesh/MobileMesh + Mesh + WorldTransform and emplaces (or resizes) a zeroed
    /// VertexIrradiance on each. Throws qgi::Error naming the entity and field for a mesh whose
    /// positions, normals, indices or world matrix cannot be used.
    void build(Registry& registry);

    /// Re-poses a mobile's vertices and triangles at its current WorldTransform. Returns false
    /// (and keeps the old pose) when the entity is gone or the matrix is not finite and
    /// invertible.
    bool refreshPose(const Registry& registry, std::uint32_t receiver);

    std::span<const Receiver> receivers() const { return mReceivers; }
    /// Receiver index of a mesh entity, or -1.
    std::int64_t find(Entity entity) const;
    /// Vertices [0, staticVertexCount()) belong to static meshes.
    std::uint32_t staticVertexCount() const { return mStaticVertexCount; }
    std::size_t vertexCount() const { return mPositions.size(); }
    std::size_t triangleCount() const { return mTriangles.size(); }

    std::span<const glm::vec3> positions() const { return mPositions; }     ///< metres, world
    std::span<const glm::vec3> normals() const { return mNormals; }         ///< unit, world
    std::span<const glm::uvec3> triangles() const { return mTriangles; }    ///< global vertex ids
    std::span<const float> triangleAreas() const { return mTriangleAreas; } ///< m^2, world

    /// Writes irradiance[v] (W/m^2, indexed globally) for every vertex v of `sortedVertices`
    /// (ascending, no repeats) into its entity's VertexIrradiance, and appends one dirty range
    /// per run of consecutive vertices.
    void publish(Registry& registry, std::span<const glm::vec3> irradiance,
                 std::span<const std::uint32_t> sortedVertices) const;
    /// Writes every vertex of `receiver`, one dirty range.
    void publishReceiver(Registry& registry, std::span<const glm::vec3> irradiance,
                         std::uint32_t receiver) const;

private:
    void placeReceiver(std::uint32_t receiver, const glm::mat4& pose);

    std::vector<Receiver> mReceivers;
    std::unordered_map<Entity, std::uint32_t> mIndex;
    std::uint32_t mStaticVertexCount = 0;
    std::vector<glm::vec3> mPositions;
    std::vector<glm::vec3> mNormals;
    std::vector<glm::uvec3> mTriangles;
    std::vector<float> mTriangleAreas;
    /// Object-space copies of the mobiles' vertices, indexed by global vertex - static count.
    std::vector<glm::vec3> mLocalPositions;
    std::vector<glm::vec3> mLocalNormals;
};

} // namespace qgi
