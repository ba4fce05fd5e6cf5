#pragma once

#include "runtime/ecs/Registry.h"

namespace qgi {

/// The camera the scene is seen through: the first Camera with `active` set, else the first
/// Camera; null when there is none. Every consumer (renderer, demo input) uses this one rule.
Entity findActiveCamera(const Registry& registry);

} // namespace qgi
