#include "tests/reference/VertexSamples.h"

#include "tests/reference/IrradianceReference.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <cmath>

namespace qgi::reference {

bool openNeighbourhood(const RayScene& scene, const glm::vec3& x, const glm::vec3& n, float r) {
    const glm::vec3 t = glm::normalize(std::abs(n.x) < 0.9f ? glm::cross(n, glm::vec3(1, 0, 0))
                                                            : glm::cross(n, glm::vec3(0, 1, 0)));
    const glm::vec3 b = glm::cross(n, t);
    const glm::vec3 start = x + n * 1e-4f;
    if (scene.occluded(Ray{start, 0.f, n, 2.f * r})) return false;
    for (int k = 0; k < 8; ++k) {
        const float a = glm::two_pi<float>() * float(k) / 8.f;
        const glm::vec3 d = std::cos(a) * t + std::sin(a) * b;
        if (scene.occluded(Ray{start, 0.f, d, 2.f * r})) return false;
    }
    return true;
}

namespace {

/// Whether the vertex's surface goes on for 2r all around it: a ray dropped onto the tangent
/// plane 2r away, in each of 8 directions, meets a surface there. (A disc that hangs over a
/// free edge, as at a block's rim, averages light the surface itself does not get.)
bool surfaceAround(const RayScene& scene, const glm::vec3& x, const glm::vec3& n, float r) {
    const glm::vec3 t = glm::normalize(std::abs(n.x) < 0.9f ? glm::cross(n, glm::vec3(1, 0, 0))
                                                            : glm::cross(n, glm::vec3(0, 1, 0)));
    const glm::vec3 b = glm::cross(n, t);
    for (int k = 0; k < 8; ++k) {
        const float a = glm::two_pi<float>() * float(k) / 8.f;
        const glm::vec3 above = x + 2.f * r * (std::cos(a) * t + std::sin(a) * b) + 0.2f * r * n;
        if (!scene.occluded(Ray{above, 0.f, -n, 0.4f * r})) return false;
    }
    return true;
}

template <typename Kind>
std::vector<VertexSample> openVerticesOf(const Registry& registry, const RayScene& scene, float r,
                                         std::size_t count, bool wholeDisc) {
    std::vector<VertexSample> all;
    registry.view<const Kind, const Mesh, const WorldTransform>().each(
        [&](Entity e, const Kind&, const Mesh& mesh, const WorldTransform& world) {
            const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(world.matrix)));
            const VertexIrradiance* irradiance = registry.tryGet<VertexIrradiance>(e);
            for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
                const glm::vec3 x = glm::vec3(world.matrix * glm::vec4(mesh.positions[v], 1.f));
                const glm::vec3 n = glm::normalize(normalMatrix * mesh.normals[v]);
                if (!openNeighbourhood(scene, x, n, r)) continue;
                if (wholeDisc && !surfaceAround(scene, x, n, r)) continue;
                const bool lit = irradiance && v < irradiance->irradiance.size();
                all.push_back({x, n, lit ? irradiance->irradiance[v] : glm::vec3(0.f), e});
            }
        });
    if (all.size() <= count) return all;
    std::vector<VertexSample> picked;
    for (std::size_t i = 0; i < count; ++i)
        picked.push_back(all[i * all.size() / count]);
    return picked;
}

} // namespace

std::vector<VertexSample> openStaticVertices(const Registry& registry, const RayScene& scene,
                                             float r, std::size_t count) {
    return openVerticesOf<StaticMesh>(registry, scene, r, count, false);
}

std::vector<VertexSample> openMobileVertices(const Registry& registry, const RayScene& scene,
                                             float r, std::size_t count) {
    return openVerticesOf<MobileMesh>(registry, scene, r, count, true);
}

std::vector<IrradianceEstimate> photonReferenceAt(const Registry& registry, const RayScene& scene,
                                                  std::span<const VertexSample> samples,
                                                  std::uint32_t paths, bool includeDirect) {
    std::vector<glm::vec3> xs, ns;
    for (const VertexSample& s : samples) {
        xs.push_back(s.position);
        ns.push_back(s.normal);
    }
    ReferenceSettings settings;
    settings.samplesPerPoint = paths;
    settings.includeEnvironment = false;
    settings.includeDirect = includeDirect;
    return IrradianceReference(registry, scene, settings).estimate(xs, ns);
}

double percentile(std::vector<double> values, double p) {
    if (values.empty()) return 0.0;
    std::sort(values.begin(), values.end());
    return values[std::min(values.size() - 1, std::size_t(p * double(values.size())))];
}

ErrorSummary summariseErrors(const std::vector<double>& estimates,
                             const std::vector<double>& references) {
    std::vector<double> relative;
    double total = 0, totalReference = 0;
    for (std::size_t i = 0; i < estimates.size() && i < references.size(); ++i) {
        if (!(references[i] > 0.0) || std::isnan(estimates[i])) continue;
        relative.push_back(std::abs(estimates[i] - references[i]) / references[i]);
        total += estimates[i];
        totalReference += references[i];
    }
    ErrorSummary out;
    out.points = relative.size();
    out.median = percentile(relative, 0.5);
    out.p90 = percentile(relative, 0.9);
    out.sum = totalReference > 0.0 ? total / totalReference - 1.0 : 0.0;
    return out;
}

} // namespace qgi::reference
