#include "systems/vlf/VlfSystem.h"

#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "systems/vlf/VlfBake.h"
#include "systems/vlf/VlfCache.h"
#include "systems/vlf/VlfField.h"
#include "systems/vlf/VlfScene.h"

namespace qgi {

VlfSystem::VlfSystem(const VlfSystemSettings& settings) : mSettings(settings) {
    validate(settings.bake);
}

void VlfSystem::build(Registry& registry) {
    RayScene* rays = registry.ctx().find<RayScene>();
    const auto scene = vlf::VlfScene::fromRegistry(registry, rays ? &rays->device() : nullptr);
    VlfSettings bake = mSettings.bake;
    bake.progress = true;
    bool baked = false;
    vlf::VlfBakeStats stats;
    VlfField field;
    field.vlf = vlf::VlfCache::loadOrBake(*scene, bake, mSettings.cacheFile, &baked, &stats);
    const vlf::VlfMemory mem = field.vlf.memory();
    if (baked)
        logInfo("VLF: baked ", scene->faces().size(), " faces, ", mem.directions, " directions, ",
                bake.linesPerSide, "x", bake.linesPerSide, " lines in ", stats.seconds, " s; ",
                mem.tileCells, " directional and ", mem.diffuseTexels, " diffuse elements, ",
                double(mem.renderBytes) / 1e6, " MB (bake peak ", double(mem.bakeBytes) / 1e6,
                " MB)");
    for (std::uint32_t f = 0; f < scene->faces().size(); ++f)
        if (scene->faces()[f].isSpecular() && !scene->entities().empty())
            field.specularFaces[scene->entities()[scene->faceGroups()[f]]].push_back(f);
    registry.ctx().emplaceOrReplace<VlfField>(std::move(field));
}

} // namespace qgi
