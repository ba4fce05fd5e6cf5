#pragma once

#include <glm/mat4x4.hpp>

namespace qgi {

/// Object-to-world matrix, computed by the transform system from Transform and its parents.
/// Patched (so `registry.changed<WorldTransform>()` lists it) only when the matrix changes.
struct WorldTransform {
    glm::mat4 matrix{1.f};
};

} // namespace qgi
