#include "runtime/scene/SceneLoader.h"

#include "runtime/core/Error.h"

#include <algorithm>
#include <cctype>

namespace qgi {

void loadScene(Registry& registry, std::string_view nameOrPath, const SceneOptions& options) {
    if (isBuiltinScene(nameOrPath)) {
        buildBuiltinScene(registry, nameOrPath, options);
        return;
    }
    std::string extension = std::filesystem::path(nameOrPath).extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    if (extension != ".gltf" && extension != ".glb") {
        std::string names;
        for (const std::string& name : builtinSceneNames())
            names += (names.empty() ? "" : ", ") + name;
        fail("'", nameOrPath, "' is neither a built-in scene (", names,
             ") nor a .gltf or .glb file");
    }
    importGltf(registry, std::filesystem::path(nameOrPath), options);
}

} // namespace qgi
