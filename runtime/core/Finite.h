#pragma once

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include <cmath>

namespace qgi {

/// True when no component is NaN or infinite. Bad input checks use these at load time.
inline bool isFinite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

inline bool isFinite(const glm::mat4& m) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            if (!std::isfinite(m[c][r])) return false;
    return true;
}

} // namespace qgi
