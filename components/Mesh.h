#pragma once

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <cstdint>
#include <vector>

namespace qgi {

/// An indexed triangle mesh in object space, after import processing (welded, degenerate
/// triangles removed, refined to the edge bound, normals that keep creases). Lighting is
/// computed per vertex, so a vertex sits wherever light is meant to change.
struct Mesh {
    std::vector<glm::vec3> positions; ///< metres, object space
    std::vector<glm::vec3> normals;   ///< unit, object space, one per position
    std::vector<glm::vec2> uvs;       ///< texture coordinates; empty when the mesh has none
    std::vector<std::uint32_t> indices; ///< three per triangle, counter-clockwise front faces
};

} // namespace qgi
