#pragma once

#include <glm/vec3.hpp>

#include <cstdint>
#include <vector>

namespace qgi {

/// Half-open range of vertex indices [begin, end).
struct DirtyRange {
    std::uint32_t begin = 0;
    std::uint32_t end = 0;
};

/// Irradiance at each vertex of the entity's Mesh, and which ranges changed since the renderer
/// last uploaded them. Writers append to `dirty`; the renderer uploads and clears it.
struct VertexIrradiance {
    std::vector<glm::vec3> irradiance; ///< W/m^2, linear RGB, one per Mesh vertex
    std::vector<DirtyRange> dirty;     ///< ranges to upload; may overlap, renderer merges
};

} // namespace qgi
