#pragma once

#include "systems/vlf/VlfSettings.h"

#include <filesystem>

namespace qgi {

class Registry;

struct VlfSystemSettings {
    VlfSettings bake;
    /// Cache file: loaded when it holds this scene and settings, else (re)baked and written.
    /// Empty: bake every start without a file.
    std::filesystem::path cacheFile;
};

/** Virtual Light Field of the static scene (seed 002): bakes it at load, or loads it from the
 *  cache file keyed by scene and settings, and publishes it as the VlfField world resource.
 *  The field is static, so nothing runs per frame: the renderer looks it up per fragment
 *  (shaders/common/vlf.glsl) for glossy and mirror static surfaces.
 *  Reads:  const StaticMesh, const Mesh, const WorldTransform, const Material, const
 *          PointLight / SpotLight / DirectionalLight (+ LightStandIn), ctx<const SceneInfo>
 *  Writes: ctx<VlfField>                                                                  */
class VlfSystem {
public:
    /// Throws qgi::Error on bad settings.
    explicit VlfSystem(const VlfSystemSettings& settings);
    /// Bakes or loads; throws qgi::Error on a scene it cannot bake (no static triangles).
    void build(Registry& registry);

private:
    VlfSystemSettings mSettings;
};

} // namespace qgi
