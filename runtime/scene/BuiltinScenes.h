#pragma once

#include "runtime/ecs/Registry.h"

#include <string>
#include <string_view>
#include <vector>

namespace qgi {

struct SceneOptions {
    /// Refinement bound for meshes, metres; 0: the scene's own default (SceneInfo records it).
    float maxEdgeLength = 0.f;
};

/// Names of the scenes built in code: "cornell", "cornell-glossy", "atrium".
std::vector<std::string> builtinSceneNames();
bool isBuiltinScene(std::string_view name);

/// Populates an empty registry with a built-in scene: entities with Name, Transform,
/// WorldTransform, Mesh + Material + StaticMesh/MobileMesh/Avatar, lights, a Camera with a
/// PathFollower, PathFollowers on mobiles and avatars; and the SceneInfo and TextureLibrary
/// resources. Throws qgi::Error for an unknown name.
void buildBuiltinScene(Registry& registry, std::string_view name, const SceneOptions& options);

} // namespace qgi
