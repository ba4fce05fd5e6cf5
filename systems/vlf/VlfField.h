#pragma once

#include "runtime/ecs/Entity.h"
#include "systems/vlf/Vlf.h"

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace qgi {

/// World resource: the baked Virtual Light Field of the static scene, for the renderer's
/// glossy and mirror lookup and for CPU queries (tools, tests). Created by VlfSystem at
/// load; never changes during the frame.
struct VlfField {
    vlf::Vlf vlf;
    /// Static mesh entity -> the indices of its specular faces in vlf.faces().
    std::unordered_map<Entity, std::vector<std::uint32_t>> specularFaces;
};

} // namespace qgi
