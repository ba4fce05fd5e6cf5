#pragma once

#include "components/VertexIrradiance.h"
#include "runtime/render/GlHandle.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

struct Mesh;

/// Vertex attribute locations shared by every scene shader (see shaders/scene.vert).
enum GpuMeshAttribute : GLuint {
    kAttributePosition = 0,
    kAttributeNormal = 1,
    kAttributeUv = 2,
    kAttributeIrradiance = 3,
};

/// A Mesh on the GPU: one buffer per attribute (irradiance changes alone, in ranges), an index
/// buffer and the vertex array that ties them to the shader locations above.
struct GpuMesh {
    GlVertexArray vertexArray;
    GlBuffer positions;
    GlBuffer normals;
    GlBuffer uvs;        ///< zeros when the mesh has none
    GlBuffer irradiance; ///< W/m^2 per vertex; zeros until uploaded
    GlBuffer indices;
    std::uint32_t vertexCount = 0;
    std::uint32_t indexCount = 0;
    Aabb bounds;       ///< object space
    bool drawn = true; ///< whether it was drawn last frame (a MobileMesh can be out of the world)
    /// The last pose it was drawn at that isUsablePose() accepted (runtime/math/Pose.h), and
    /// whether there was one: a pose past the rule keeps the mesh there, as the ray scene
    /// keeps it, instead of stretching the shadow maps' bounds over 1e20 m.
    glm::mat4 pose{1.f};
    bool posed = false;
};

/// Uploads a mesh (the caller has checked that every attribute has one entry per position).
GpuMesh createGpuMesh(const Mesh& mesh);

/// Draws the mesh's triangles with the current program and state.
void drawGpuMesh(const GpuMesh& mesh);

/// Sorts `ranges`, merges overlapping and touching ones and drops empty ones, in place.
void mergeDirtyRanges(std::vector<DirtyRange>& ranges);

/// Uploads the vertices named by `dirty` (merged first; ranges are clipped to the mesh and to
/// `irradiance`) and clears `dirty`. One glNamedBufferSubData per merged range.
void uploadIrradiance(GpuMesh& mesh, std::span<const glm::vec3> irradiance,
                      std::vector<DirtyRange>& dirty);

} // namespace qgi
