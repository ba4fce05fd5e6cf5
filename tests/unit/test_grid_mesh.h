#pragma once
// A flat grid mesh for the estimator tests.

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

} // namespace qgi::test
