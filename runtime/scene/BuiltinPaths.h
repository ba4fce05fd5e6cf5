#pragma once

#include "components/PathFollower.h"

#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>

#include <span>

namespace qgi {

/// Rotation that turns the local -Z axis (the forward axis of cameras, lights and the built-in
/// characters) towards `direction`, keeping +Y up. `direction` must not be vertical.
glm::quat facing(const glm::vec3& direction);

/// A closed walk through `corners` (metres, in the parent frame) at `speed` m/s, facing the
/// direction of travel and turning on the spot at each corner for `turnSeconds`. The last key
/// repeats the first, so the path loops seamlessly.
PathFollower walkingLoop(std::span<const glm::vec3> corners, float speed, float turnSeconds);

} // namespace qgi
