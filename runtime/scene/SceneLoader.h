#pragma once

#include "runtime/scene/BuiltinScenes.h"

#include <filesystem>
#include <string_view>

namespace qgi {

/// Loads a built-in scene by name, or a .gltf / .glb file by path, into an empty registry.
/// Throws qgi::Error with a one-line message naming the file and the field on bad input;
/// on error the registry is left empty (nothing half-loaded).
void loadScene(Registry& registry, std::string_view nameOrPath, const SceneOptions& options);

/// Imports a glTF 2.0 file (see GltfImporter.h for the mapping).
void importGltf(Registry& registry, const std::filesystem::path& path, const SceneOptions& options);

/// Writes the registry's scene as glTF 2.0 (.gltf with an embedded base64 buffer, or .glb by
/// extension) with the same conventions the importer reads, so export + import round-trips.
void exportGltf(const Registry& registry, const std::filesystem::path& path);

} // namespace qgi
