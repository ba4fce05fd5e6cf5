#include "runtime/io/IrradianceExport.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/scene/SceneQueries.h"

#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

namespace qgi {

PlyMesh gatherVertexIrradiance(const Registry& registry) {
    PlyMesh out;
    registry.view<const Mesh, const WorldTransform>().each([&](Entity e, const Mesh& mesh,
                                                               const WorldTransform& world) {
        const bool mobile = registry.has<MobileMesh>(e);
        if (!mobile && !registry.has<StaticMesh>(e)) return;
        if (outOfWorld(registry, e)) return;
        const auto* irradiance = registry.tryGet<VertexIrradiance>(e);
        const auto base = std::uint32_t(out.positions.size());
        const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(world.matrix)));
        for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
            out.positions.push_back(glm::vec3(world.matrix * glm::vec4(mesh.positions[v], 1.f)));
            out.normals.push_back(glm::normalize(normalMatrix * mesh.normals[v]));
            const bool known = irradiance && v < irradiance->irradiance.size();
            out.irradiance.push_back(known ? irradiance->irradiance[v] : glm::vec3(0.f));
            out.mobile.push_back(mobile ? 1 : 0);
        }
        for (std::uint32_t index : mesh.indices)
            out.triangles.push_back(base + index);
    });
    return out;
}

void exportVertexIrradiance(const Registry& registry, const std::filesystem::path& path,
                            PlyFormat format, std::string_view note) {
    writePly(path, gatherVertexIrradiance(registry), format, note);
}

} // namespace qgi
