#pragma once

#include <glm/common.hpp>
#include <glm/vec3.hpp>
#include <glm/vector_relational.hpp>

#include <algorithm>
#include <limits>
#include <string>
#include <utility>

namespace qgi {

/// Axis-aligned box, metres.
struct Aabb {
    glm::vec3 min{std::numeric_limits<float>::max()};
    glm::vec3 max{-std::numeric_limits<float>::max()};

    bool empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
    void extend(const glm::vec3& p) {
        min = glm::min(min, p);
        max = glm::max(max, p);
    }
    void extend(const Aabb& b) {
        if (b.empty()) return;
        extend(b.min);
        extend(b.max);
    }
    glm::vec3 center() const { return 0.5f * (min + max); }
    glm::vec3 extent() const { return max - min; }
};

/// Whether `outer` holds `inner`.
inline bool contains(const Aabb& outer, const Aabb& inner) {
    return glm::all(glm::lessThanEqual(outer.min, inner.min)) &&
           glm::all(glm::lessThanEqual(inner.max, outer.max));
}

/// The part [near, far] of origin + t * direction, t in [near, far] on entry, inside the box
/// [low, high] (slab test); empty when near > far on return. T is the arithmetic: double
/// where the clipped ends must not add float rounding (DiscIndex starts Embree's rays there).
template <typename T, typename Vec>
std::pair<T, T> clipToBox(const glm::vec3& origin, const glm::vec3& direction, T near, T far,
                          const Vec& low, const Vec& high) {
    for (int axis = 0; axis < 3; ++axis) {
        if (direction[axis] == 0.f) {
            if (origin[axis] < low[axis] || origin[axis] > high[axis]) return {T(1), T(0)};
            continue;
        }
        T t0 = (T(low[axis]) - T(origin[axis])) / T(direction[axis]);
        T t1 = (T(high[axis]) - T(origin[axis])) / T(direction[axis]);
        if (t0 > t1) std::swap(t0, t1);
        near = std::max(near, t0);
        far = std::min(far, t1);
    }
    return {near, far};
}

/// Whether origin + t * direction meets `box` for some t in [0, length] (slab test; t and
/// length in units of |direction|). An axis the direction does not move along needs the
/// origin inside the box's slab on that axis. `inverse` is 1 / direction, for testing one
/// segment against many boxes.
inline bool segmentMeetsBox(const glm::vec3& origin, const glm::vec3& direction,
                            const glm::vec3& inverse, float length, const Aabb& box) {
    float near = 0.f, far = length;
    for (int axis = 0; axis < 3; ++axis) {
        if (direction[axis] == 0.f) {
            if (origin[axis] < box.min[axis] || origin[axis] > box.max[axis]) return false;
            continue;
        }
        float t0 = (box.min[axis] - origin[axis]) * inverse[axis];
        float t1 = (box.max[axis] - origin[axis]) * inverse[axis];
        if (t0 > t1) std::swap(t0, t1);
        near = std::max(near, t0);
        far = std::min(far, t1);
        if (near > far) return false;
    }
    return true;
}

inline bool segmentMeetsBox(const glm::vec3& origin, const glm::vec3& direction, float length,
                            const Aabb& box) {
    return segmentMeetsBox(origin, direction, 1.f / direction, length, box);
}

/// World resource describing the loaded scene as a whole.
struct SceneInfo {
    std::string name;           ///< built-in name or the glTF file's stem
    std::string source;         ///< "builtin:<name>" or the path it was loaded from
    Aabb bounds;                ///< world bounds of every mesh at load time (mobiles at rest)
    glm::vec3 environment{0.f}; ///< radiance of the sky seen by rays that leave, W/(m^2 sr)
    float maxEdgeLength = 0.f;  ///< metres: the refinement bound the meshes were processed with
    float exposure = 1.f;       ///< suggested multiplier on radiance for viewing (demo default)
};

} // namespace qgi
