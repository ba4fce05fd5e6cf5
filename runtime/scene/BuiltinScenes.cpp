#include "runtime/scene/BuiltinScenes.h"

#include "runtime/scene/BuiltinAtrium.h"
#include "runtime/scene/BuiltinCornellBox.h"
#include "runtime/scene/BuiltinSceneBuilder.h"
#include "runtime/scene/SceneInfo.h"

#include <array>
#include <cmath>

namespace qgi {
namespace {

struct BuiltinScene {
    std::string_view name;
    float defaultMaxEdgeLength; // metres
    void (*build)(BuiltinSceneBuilder&);
};

constexpr std::array<BuiltinScene, 3> kScenes{{
    {"cornell", kCornellBoxMaxEdgeLength, buildCornellBox},
    {"cornell-glossy", kCornellBoxMaxEdgeLength, buildCornellBoxGlossy},
    {"atrium", kAtriumMaxEdgeLength, buildAtrium},
}};

const BuiltinScene* findScene(std::string_view name) {
    for (const BuiltinScene& scene : kScenes)
        if (scene.name == name) return &scene;
    return nullptr;
}

} // namespace

std::vector<std::string> builtinSceneNames() {
    std::vector<std::string> names;
    for (const BuiltinScene& scene : kScenes)
        names.emplace_back(scene.name);
    return names;
}

bool isBuiltinScene(std::string_view name) {
    return findScene(name) != nullptr;
}

void buildBuiltinScene(Registry& registry, std::string_view name, const SceneOptions& options) {
    const BuiltinScene* scene = findScene(name);
    if (!scene) fail("unknown built-in scene '", name, "' (built-in scenes: cornell, cornell-glossy, atrium)");
    if (!std::isfinite(options.maxEdgeLength) || options.maxEdgeLength < 0.f)
        fail("scene option maxEdgeLength ", options.maxEdgeLength,
             " must be a finite length in metres, or 0 for the scene's default");
    QGI_ASSERT(registry.aliveCount() == 0 && !registry.ctx().contains<SceneInfo>(),
               "buildBuiltinScene needs an empty registry");
    const float maxEdgeLength =
        options.maxEdgeLength > 0.f ? options.maxEdgeLength : scene->defaultMaxEdgeLength;
    BuiltinSceneBuilder builder(registry, std::string(scene->name), maxEdgeLength);
    scene->build(builder);
}

} // namespace qgi
