#pragma once
// Small meshes built by hand for the unit tests.

#include "components/Mesh.h"

#include <glm/geometric.hpp>

#include <cstdint>

namespace qgi::test {

/// n x n quads spanning origin + [0, 1] u + [0, 1] v, facing cross(u, v). Vertex (i, j) is
/// origin + i/n u + j/n v, at index i * (n + 1) + j.
inline Mesh gridMesh(glm::vec3 origin, glm::vec3 u, glm::vec3 v, int n) {
    Mesh mesh;
    const glm::vec3 normal = glm::normalize(glm::cross(u, v));
    for (int i = 0; i <= n; ++i)
        for (int j = 0; j <= n; ++j) {
            mesh.positions.push_back(origin + (float(i) / float(n)) * u +
                                     (float(j) / float(n)) * v);
            mesh.normals.push_back(normal);
        }
    const auto at = [n](int i, int j) { return std::uint32_t(i * (n + 1) + j); };
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            mesh.indices.insert(mesh.indices.end(), {at(i, j), at(i + 1, j), at(i + 1, j + 1),
                                                     at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    return mesh;
}

/// One parallelogram: corners origin, origin + u, origin + u + v, origin + v (two triangles),
/// facing cross(u, v).
inline Mesh quadMesh(glm::vec3 origin, glm::vec3 u, glm::vec3 v) {
    Mesh mesh;
    const glm::vec3 normal = glm::normalize(glm::cross(u, v));
    for (const glm::vec3& p : {origin, origin + u, origin + u + v, origin + v}) {
        mesh.positions.push_back(p);
        mesh.normals.push_back(normal);
    }
    mesh.indices = {0, 1, 2, 0, 2, 3};
    return mesh;
}

/// Axis-aligned box centred on the origin: 12 triangles facing outwards, or inwards (a room).
/// `openTop` leaves out the +y face.
inline Mesh boxMesh(const glm::vec3& half, bool inward = false, bool openTop = false) {
    Mesh mesh;
    for (int i = 0; i < 8; ++i)
        mesh.positions.push_back(
            {i & 1 ? half.x : -half.x, i & 2 ? half.y : -half.y, i & 4 ? half.z : -half.z});
    for (int axis = 0; axis < 3; ++axis) {
        for (int side = 0; side < 2; ++side) {
            if (openTop && axis == 1 && side == 1) continue;
            const int bitA = 1 << ((axis + 1) % 3), bitB = 1 << ((axis + 2) % 3);
            const int base = side ? 1 << axis : 0;
            const std::uint32_t c[4] = {std::uint32_t(base), std::uint32_t(base | bitA),
                                        std::uint32_t(base | bitA | bitB),
                                        std::uint32_t(base | bitB)};
            glm::vec3 outward(0.f);
            outward[axis] = side ? 1.f : -1.f;
            const glm::vec3 n = glm::cross(mesh.positions[c[1]] - mesh.positions[c[0]],
                                           mesh.positions[c[2]] - mesh.positions[c[0]]);
            const bool flip = (glm::dot(n, outward) < 0.f) != inward;
            if (flip)
                mesh.indices.insert(mesh.indices.end(), {c[0], c[2], c[1], c[0], c[3], c[2]});
            else
                mesh.indices.insert(mesh.indices.end(), {c[0], c[1], c[2], c[0], c[2], c[3]});
        }
    }
    for (std::size_t i = 0; i < mesh.positions.size(); ++i)
        mesh.normals.push_back(glm::normalize(mesh.positions[i]));
    return mesh;
}

} // namespace qgi::test
