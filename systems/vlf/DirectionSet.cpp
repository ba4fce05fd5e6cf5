#include "systems/vlf/DirectionSet.h"

#include "runtime/core/Error.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

#include <cmath>
#include <map>

namespace qgi::vlf {
namespace {

using Corners = std::array<glm::vec3, 3>;

glm::vec3 arcMidpoint(const glm::vec3& a, const glm::vec3& b) {
    return glm::normalize(a + b);
}

/// The four children of a positively oriented spherical triangle, in descent order: the three
/// corner children (at a, b, c) then the middle one. All keep the positive orientation.
std::array<Corners, 4> children(const Corners& t) {
    const glm::vec3 ab = arcMidpoint(t[0], t[1]);
    const glm::vec3 bc = arcMidpoint(t[1], t[2]);
    const glm::vec3 ca = arcMidpoint(t[2], t[0]);
    return {Corners{t[0], ab, ca}, Corners{ab, t[1], bc}, Corners{ca, bc, t[2]},
            Corners{ab, bc, ca}};
}

Corners root(int quadrant) {
    const glm::vec3 x(1.f, 0.f, 0.f), y(0.f, 1.f, 0.f), z(0.f, 0.f, 1.f);
    switch (quadrant) {
    case 0:
        return {x, y, z};
    case 1:
        return {y, -x, z};
    case 2:
        return {-x, -y, z};
    default:
        return {-y, x, z};
    }
}

int quadrantOf(const glm::vec3& d) {
    if (d.y >= 0.f) return d.x > 0.f ? 0 : 1;
    return d.x < 0.f ? 2 : 3;
}

double triple(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
    return glm::dot(a, glm::cross(b, c));
}

/// Spherical area of the triangle whose corners are the projections of a, b, c (sr).
double sphericalArea(glm::dvec3 a, glm::dvec3 b, glm::dvec3 c) {
    a = glm::normalize(a);
    b = glm::normalize(b);
    c = glm::normalize(c);
    const double num = std::abs(triple(a, b, c));
    const double den = 1.0 + glm::dot(a, b) + glm::dot(b, c) + glm::dot(c, a);
    return 2.0 * std::atan2(num, den);
}

} // namespace

DirectionSet::DirectionSet(int level) : mLevel(level) {
    if (level < 0 || level > 7)
        fail("VLF direction level ", level, " is out of range (0..7: 3 to 32769 directions)");

    // Vertices keyed by their exact bits: a midpoint is computed from the same two floats
    // (in either order) wherever it occurs, and negation is exact, so duplicates match.
    std::map<std::array<float, 3>, std::uint32_t> ids;
    const auto orient = [&](const glm::vec3& p) -> OrientedDirection {
        glm::vec3 key = p;
        float sign = 1.f;
        // Equator: keep azimuth in [0, pi); the other half is the same line reversed.
        if (p.z == 0.f && (p.y < 0.f || (p.y == 0.f && p.x < 0.f))) {
            key = -p;
            sign = -1.f;
        }
        const std::array<float, 3> k{key.x, key.y, key.z};
        auto [it, added] = ids.try_emplace(k, std::uint32_t(mDirections.size()));
        if (added) mDirections.push_back(key);
        return {it->second, sign};
    };

    // Leaves in descent order: root-major, then child digits most significant first.
    std::vector<Corners> level0{root(0), root(1), root(2), root(3)};
    for (int l = 0; l < level; ++l) {
        std::vector<Corners> next;
        next.reserve(level0.size() * 4);
        for (const Corners& t : level0)
            for (const Corners& c : children(t))
                next.push_back(c);
        level0 = std::move(next);
    }
    mTriangleCorners = level0;
    mTriangles.reserve(level0.size());
    for (const Corners& t : level0)
        mTriangles.push_back({orient(t[0]), orient(t[1]), orient(t[2])});

    mCellSolidAngle.assign(mDirections.size(), 0.f);
    std::vector<double> area(mDirections.size(), 0.0);
    mCellParts.assign(mDirections.size(), {});
    for (std::size_t t = 0; t < mTriangles.size(); ++t) {
        const Corners& c = mTriangleCorners[t];
        const glm::vec3 g = (c[0] + c[1] + c[2]) / 3.f;
        for (int k = 0; k < 3; ++k) {
            const glm::vec3& p = c[k];
            const glm::vec3 midA = 0.5f * (p + c[(k + 1) % 3]);
            const glm::vec3 midB = 0.5f * (p + c[(k + 2) % 3]);
            const OrientedDirection od = mTriangles[t][k];
            area[od.index] += sphericalArea(p, midA, g) + sphericalArea(p, g, midB);
            mCellParts[od.index].push_back({p, midA, g, midB, od.sign});
        }
    }
    for (std::size_t i = 0; i < area.size(); ++i)
        mCellSolidAngle[i] = float(area[i]);
}

float DirectionSet::solidAngleWeight(std::size_t i) const {
    return mCellSolidAngle[i] / (2.f * glm::pi<float>() / float(mDirections.size()));
}

std::uint32_t DirectionSet::descend(const glm::vec3& d) const {
    const int q = quadrantOf(d);
    Corners t = root(q);
    std::uint32_t index = std::uint32_t(q);
    for (int l = 0; l < mLevel; ++l) {
        const std::array<Corners, 4> c = children(t);
        const Corners& mid = c[3]; // (ab, bc, ca)
        int child = 3;
        if (glm::dot(d, glm::cross(mid[2], mid[0])) < 0.f)
            child = 0; // beyond ca-ab: a
        else if (glm::dot(d, glm::cross(mid[0], mid[1])) < 0.f)
            child = 1; // beyond ab-bc: b
        else if (glm::dot(d, glm::cross(mid[1], mid[2])) < 0.f)
            child = 2; // beyond bc-ca: c
        t = c[child];
        index = index * 4 + std::uint32_t(child);
    }
    return index;
}

std::uint32_t DirectionSet::locateTriangle(const glm::vec3& direction) const {
    return descend(direction.z < 0.f ? -direction : direction);
}

DirectionTriangle DirectionSet::locate(const glm::vec3& direction) const {
    const float flip = direction.z < 0.f ? -1.f : 1.f;
    const glm::vec3 d = direction * flip;
    const std::uint32_t t = descend(d);
    const Corners& c = mTriangleCorners[t];
    const glm::dvec3 dd(d), a(c[0]), b(c[1]), e(c[2]);
    double w[3] = {triple(dd, b, e), triple(a, dd, e), triple(a, b, dd)};
    double sum = 0.0;
    for (double& x : w)
        sum += x = std::max(x, 0.0);
    DirectionTriangle out;
    for (int k = 0; k < 3; ++k) {
        out.corners[k] = mTriangles[t][k];
        out.corners[k].sign *= flip;
    }
    if (!(sum > 0.0)) { // degenerate query (zero vector): nearest corner by dot product
        int best = 0;
        for (int k = 1; k < 3; ++k)
            if (glm::dot(d, c[k]) > glm::dot(d, c[best])) best = k;
        out.weights[best] = 1.f;
        return out;
    }
    // Rounding leaves ~1e-17 on the zero weights at a stored direction: snap them, so that a
    // stored direction gets weight exactly 1.
    double kept = 0.0;
    for (double& x : w) {
        if (x < 1e-9 * sum) x = 0.0;
        kept += x;
    }
    for (int k = 0; k < 3; ++k)
        out.weights[k] = float(w[k] / kept);
    return out;
}

DirectionSample DirectionSet::sampleCell(std::size_t i, float sign, std::mt19937& rng) const {
    const std::vector<CellPart>& parts = mCellParts[i];
    std::uniform_real_distribution<float> uniform(0.f, 1.f);
    const std::size_t k =
        std::min(parts.size() - 1, std::size_t(uniform(rng) * float(parts.size())));
    const CellPart& part = parts[k];
    // Two flat triangles of the part's quadrilateral, one chosen uniformly.
    const bool first = uniform(rng) < 0.5f;
    const glm::vec3 p0 = part.corner;
    const glm::vec3 p1 = first ? part.midA : part.centroid;
    const glm::vec3 p2 = first ? part.centroid : part.midB;
    float r1 = uniform(rng), r2 = uniform(rng);
    if (r1 + r2 > 1.f) {
        r1 = 1.f - r1;
        r2 = 1.f - r2;
    }
    const glm::vec3 q = p0 + r1 * (p1 - p0) + r2 * (p2 - p0);
    const glm::vec3 cross = glm::cross(p1 - p0, p2 - p0);
    const float flatArea = 0.5f * glm::length(cross);
    const glm::vec3 normal = cross / (2.f * flatArea);
    const float len = glm::length(q);
    // Uniform in flat area, so the solid-angle density is 1 / (area * dOmega/dA) with
    // dOmega/dA = |n.q| / |q|^3; the weight undoes the choice of part and half.
    const float jacobian = std::abs(glm::dot(normal, q)) / (len * len * len);
    DirectionSample s;
    s.direction = q / len * (part.sign * sign);
    s.solidAngle = float(parts.size()) * 2.f * flatArea * jacobian;
    return s;
}

SubfieldFrame makeSubfieldFrame(const glm::vec3& direction) {
    const glm::vec3 n = glm::normalize(direction);
    const float sign = std::copysign(1.f, n.z);
    const float a = -1.f / (sign + n.z);
    const float b = n.x * n.y * a;
    SubfieldFrame f;
    f.n = n;
    f.u = glm::normalize(glm::vec3(1.f + sign * n.x * n.x * a, sign * b, -sign * n.x));
    f.v = glm::cross(n, f.u);
    return f;
}

} // namespace qgi::vlf
