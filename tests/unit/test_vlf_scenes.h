#pragma once
// Small hand-built scenes for the VLF tests: quads grouped into faces with one material each.

#include "systems/vlf/VlfScene.h"

#include <glm/geometric.hpp>

#include <memory>
#include <vector>

namespace qgi::test {

struct VlfSceneBuilder {
    std::vector<vlf::VlfScene::Triangle> triangles;
    std::vector<std::uint32_t> groups;
    std::vector<vlf::VlfScene::Material> materials;
    std::vector<vlf::PunctualLight> lights;
    glm::vec3 environment{0.f};

    std::uint32_t material(const glm::vec3& diffuse, const glm::vec3& emission = glm::vec3(0.f),
                           const glm::vec3& specular = glm::vec3(0.f), float exponent = 0.f) {
        materials.push_back({diffuse, emission, specular, exponent});
        return std::uint32_t(materials.size() - 1);
    }
    /// Quad a b c d (a planar parallelogram or rectangle), front side where
    /// cross(b - a, c - a) points; two triangles.
    void quad(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const glm::vec3& d,
              std::uint32_t group) {
        triangles.push_back({a, b, c, 0});
        triangles.push_back({a, c, d, 0});
        groups.push_back(group);
        groups.push_back(group);
    }
    /// Axis-aligned box [lo, hi] with six faces facing inwards (a room) or outwards (a block);
    /// `groupOf(axis, side)` picks each face's material (side 0: the lo face).
    template <typename GroupOf>
    void box(const glm::vec3& lo, const glm::vec3& hi, bool inward, GroupOf groupOf) {
        for (int axis = 0; axis < 3; ++axis)
            for (int side = 0; side < 2; ++side) {
                const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
                glm::vec3 p[4];
                for (int k = 0; k < 4; ++k) {
                    p[k][axis] = side ? hi[axis] : lo[axis];
                    p[k][a1] = (k == 1 || k == 2) ? hi[a1] : lo[a1];
                    p[k][a2] = (k >= 2) ? hi[a2] : lo[a2];
                }
                glm::vec3 want(0.f);
                want[axis] = (side ? 1.f : -1.f) * (inward ? -1.f : 1.f);
                const glm::vec3 n = glm::cross(p[1] - p[0], p[2] - p[0]);
                const std::uint32_t g = groupOf(axis, side);
                if (glm::dot(n, want) > 0.f)
                    quad(p[0], p[1], p[2], p[3], g);
                else
                    quad(p[0], p[3], p[2], p[1], g);
            }
    }
    std::unique_ptr<vlf::VlfScene> build() const {
        return std::make_unique<vlf::VlfScene>(triangles, groups, materials, lights, environment);
    }
};

/// Index of the face whose plane holds `point` with normal `normal` (or -1).
inline int findFace(const vlf::VlfScene& scene, const glm::vec3& normal, const glm::vec3& point) {
    for (std::size_t i = 0; i < scene.faces().size(); ++i) {
        const vlf::Face& f = scene.faces()[i];
        if (glm::dot(f.normal, normal) > 0.999f &&
            std::abs(glm::dot(f.normal, point) - f.offset) < 1e-4f)
            return int(i);
    }
    return -1;
}

/// A 2 m room with one emissive wall (radiance `lamp`), a glossy floor, a mirror wall and
/// grey diffuse walls: every kind of face the VLF stores.
inline std::unique_ptr<vlf::VlfScene> glossyRoom(float lamp = 4.f) {
    VlfSceneBuilder b;
    const std::uint32_t wall = b.material(glm::vec3(0.5f));
    const std::uint32_t light = b.material(glm::vec3(0.f), glm::vec3(lamp));
    const std::uint32_t glossy = b.material(glm::vec3(0.3f), glm::vec3(0.f), glm::vec3(0.6f), 10.f);
    const std::uint32_t mirror = b.material(glm::vec3(0.f), glm::vec3(0.f), glm::vec3(0.8f), 0.f);
    b.box({-1.f, 0.f, -1.f}, {1.f, 2.f, 1.f}, true, [&](int axis, int side) {
        if (axis == 1 && side == 0) return glossy;
        if (axis == 0 && side == 1) return light;
        if (axis == 2 && side == 0) return mirror;
        return wall;
    });
    return b.build();
}

} // namespace qgi::test
