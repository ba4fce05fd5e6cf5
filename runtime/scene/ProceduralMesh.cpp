#include "runtime/scene/ProceduralMesh.h"

#include "runtime/core/Error.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace qgi {

void ProceduralMesh::addTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                                 const glm::vec3& facing) {
    const bool flip = glm::dot(glm::cross(b - a, c - a), facing) < 0.f;
    const auto first = std::uint32_t(mMesh.positions.size());
    mMesh.positions.push_back(a);
    mMesh.positions.push_back(flip ? c : b);
    mMesh.positions.push_back(flip ? b : c);
    mMesh.indices.insert(mMesh.indices.end(), {first, first + 1, first + 2});
}

void ProceduralMesh::addQuad(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                             const glm::vec3& d, const glm::vec3& facing) {
    addTriangle(a, b, c, facing);
    addTriangle(a, c, d, facing);
}

void ProceduralMesh::addBox(const glm::vec3& lo, const glm::vec3& hi, unsigned faces) {
    const auto corner = [&](int x, int y, int z) {
        return glm::vec3(x ? hi.x : lo.x, y ? hi.y : lo.y, z ? hi.z : lo.z);
    };
    for (int axis = 0; axis < 3; ++axis) {
        const int u = (axis + 1) % 3;
        const int v = (axis + 2) % 3;
        for (int side = 0; side < 2; ++side) {
            if (!(faces & (1u << (2 * axis + side)))) continue;
            glm::ivec3 c[4];
            for (int k = 0; k < 4; ++k) {
                c[k][axis] = side;
                c[k][u] = (k == 1 || k == 2) ? 1 : 0;
                c[k][v] = (k >= 2) ? 1 : 0;
            }
            glm::vec3 facing(0.f);
            facing[axis] = side ? 1.f : -1.f;
            addQuad(corner(c[0].x, c[0].y, c[0].z), corner(c[1].x, c[1].y, c[1].z),
                    corner(c[2].x, c[2].y, c[2].z), corner(c[3].x, c[3].y, c[3].z), facing);
        }
    }
}

void ProceduralMesh::addLathe(const glm::vec3& base, std::span<const glm::vec2> profile,
                              int segments) {
    QGI_ASSERT(segments >= 3 && profile.size() >= 2);
    std::vector<glm::vec3> radial(std::size_t(segments) + 1);
    for (int j = 0; j < segments; ++j) {
        const float angle = glm::two_pi<float>() * float(j) / float(segments);
        radial[std::size_t(j)] = glm::vec3(std::cos(angle), 0.f, std::sin(angle));
    }
    radial.back() = radial.front(); // the seam closes exactly
    const auto point = [&](const glm::vec2& p, std::size_t j) {
        return base + p.x * radial[j] + glm::vec3(0.f, p.y, 0.f);
    };
    for (std::size_t i = 0; i + 1 < profile.size(); ++i) {
        const glm::vec2 p0 = profile[i];
        const glm::vec2 p1 = profile[i + 1];
        if (p0.x == 0.f && p1.x == 0.f) continue;
        const glm::vec2 normal(p1.y - p0.y, p0.x - p1.x); // right of the direction of travel
        for (std::size_t j = 0; j < std::size_t(segments); ++j) {
            const glm::vec3 facing = normal.x * glm::normalize(radial[j] + radial[j + 1]) +
                                     glm::vec3(0.f, normal.y, 0.f);
            if (p0.x == 0.f)
                addTriangle(point(p0, j), point(p1, j), point(p1, j + 1), facing);
            else if (p1.x == 0.f)
                addTriangle(point(p0, j), point(p0, j + 1), point(p1, j), facing);
            else
                addQuad(point(p0, j), point(p0, j + 1), point(p1, j + 1), point(p1, j), facing);
        }
    }
}

void ProceduralMesh::addCylinder(const glm::vec3& base, float radius, float height, int segments,
                                 bool inward) {
    const glm::vec2 bottom(radius, 0.f);
    const glm::vec2 top(radius, height);
    const glm::vec2 profile[2] = {inward ? top : bottom, inward ? bottom : top};
    addLathe(base, profile, segments);
}

namespace {

// Points of a circular arc in the (radius, height) plane from latitude `from` to `to`
// (radians, -pi/2 is the bottom pole), appended to `profile`; the poles land exactly on the
// axis so the lathe closes the surface there.
void appendArc(std::vector<glm::vec2>& profile, float radius, float centerHeight, float from,
               float to, int steps) {
    for (int k = 0; k <= steps; ++k) {
        const float latitude = from + (to - from) * float(k) / float(steps);
        const bool pole = std::abs(std::abs(latitude) - glm::half_pi<float>()) < 1e-6f;
        profile.emplace_back(pole ? 0.f : radius * std::cos(latitude),
                             centerHeight + radius * std::sin(latitude));
    }
}

} // namespace

void ProceduralMesh::addSphere(const glm::vec3& center, float radius, int segments, int rings) {
    std::vector<glm::vec2> profile;
    appendArc(profile, radius, 0.f, -glm::half_pi<float>(), glm::half_pi<float>(), rings);
    addLathe(center, profile, segments);
}

void ProceduralMesh::addCapsule(const glm::vec3& center, float radius, float height, int segments,
                                int rings) {
    QGI_ASSERT(height >= 2.f * radius);
    const float halfStraight = 0.5f * height - radius;
    std::vector<glm::vec2> profile;
    appendArc(profile, radius, -halfStraight, -glm::half_pi<float>(), 0.f, rings);
    appendArc(profile, radius, halfStraight, 0.f, glm::half_pi<float>(), rings);
    addLathe(center, profile, segments);
}

void ProceduralMesh::append(const ProceduralMesh& other, const glm::mat4& transform) {
    const auto offset = std::uint32_t(mMesh.positions.size());
    for (const glm::vec3& p : other.mMesh.positions)
        mMesh.positions.push_back(glm::vec3(transform * glm::vec4(p, 1.f)));
    for (const std::uint32_t i : other.mMesh.indices)
        mMesh.indices.push_back(offset + i);
}

Mesh ProceduralMesh::release() && {
    return std::move(mMesh);
}

} // namespace qgi
