// SH probe irradiance in the built-in cornell scene (photon-mode semantics) against the
// independent brute-force Monte Carlo reference (tests/reference), at the centre of an
// avatar-sized sphere (radius 7.5 cm, the scene's avatar) for 32 normals spread over it.
//
// Input. The probes read per-vertex irradiance; here it comes from the reference itself
// (samplesPerPoint = kVertexSamples per vertex), so the test measures the probe system alone,
// not the photon transport. That input is noisy (relative standard error about
// 1/sqrt(kVertexSamples) per vertex) and linear across each triangle; a probe averages
// hundreds of vertices, so we allow 5% of the reference value for it (kInputAllowance). The
// mesh is refined to 4 cm triangles (the scene default is 2 cm) to keep the input cheap.
//
// Bounds for one normal n at one point:
//   |E_probe - E_ref| <= 4 sigma_ref + 3/32 x integral of L  (+ spread off the probe nodes)
//                        + kInputAllowance x E_ref
//  - sigma_ref: the reference's standard error (4096 paths; 4 sigma: a false alarm in
//    1/16000 of the 256 comparisons);
//  - 3/32 x integral of L over the sphere (= L00 / Y00, from the probe's own coefficients):
//    the order-2 truncation bound for any non-negative radiance (a sum of directional
//    sources, each off by at most 3/32 of its irradiance; runtime/math/SphericalHarmonics.h);
//  - off the probe nodes, the spread (max - min) of the 8 corner probes' irradiance for n:
//    trilinear interpolation returns a weighted mean of them, and irradiance that is monotone
//    across a cell lies within their range.
// Averaged over the 32 nearly uniform normals, band 0 is all that remains of the truncation
// (its mean over the sphere is exact), so the average is held to the statistics, the input
// allowance and the spread alone: a global scale error of 10% fails it.
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/math/SphericalHarmonics.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/sh_probes/ProbeVolume.h"
#include "systems/sh_probes/ShProbeSystem.h"
#include "tests/reference/IrradianceReference.h"

#include <glm/mat3x3.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace qgi {
namespace {

constexpr std::uint32_t kVertexSamples = 128;
constexpr double kInputAllowance = 0.05;
constexpr std::uint32_t kNormals = 32;

void fillVertexIrradianceFromReference(Registry& world, const RayScene& scene) {
    reference::ReferenceSettings settings;
    settings.samplesPerPoint = kVertexSamples;
    settings.seed = 11;
    const reference::IrradianceReference ref(world, scene, settings);
    std::vector<Entity> entities;
    world.view<const Mesh, const WorldTransform>().each(
        [&](Entity e, const Mesh&, const WorldTransform&) {
            if (world.has<StaticMesh>(e) || world.has<MobileMesh>(e)) entities.push_back(e);
        });
    for (const Entity e : entities) {
        const Mesh& mesh = world.get<Mesh>(e);
        const glm::mat4& m = world.get<WorldTransform>(e).matrix;
        const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(m)));
        std::vector<glm::vec3> xs, ns;
        for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
            const glm::vec3 n = glm::normalize(normalMatrix * mesh.normals[v]);
            // Just off the surface on its front side, where the estimate is well defined.
            xs.push_back(glm::vec3(m * glm::vec4(mesh.positions[v], 1.f)) + 1e-4f * n);
            ns.push_back(n);
        }
        const auto estimates = ref.estimate(xs, ns);
        VertexIrradiance& vi = world.emplaceOrReplace<VertexIrradiance>(e);
        vi.irradiance.clear();
        for (const auto& est : estimates)
            vi.irradiance.push_back(glm::vec3(est.mean));
    }
}

TEST(ShProbesAccuracy, CornellSphereAgreesWithMonteCarloReference) {
    Registry world;
    buildBuiltinScene(world, "cornell",
                      SceneOptions{0.04f}); // 4 cm triangles: a quarter of the vertices
    RayScene& scene = world.ctx().emplace<RayScene>();
    scene.build(world);
    fillVertexIrradianceFromReference(world, scene);

    ShProbeSettings settings;
    settings.spacing = 0.07f; // about the avatar's size
    settings.raysPerProbe = 2048;
    settings.hybrid = false; // photon mode: the luminaire's light arrives as emission
    ShProbeSystem system(settings);
    system.build(world);
    system.projectAll(world);
    const ProbeVolume& volume = world.ctx().get<ProbeVolume>();
    const ProbeGrid& grid = volume.grid();

    // Sphere centres in free space: above the short block, high in the middle, low in the
    // front-left corner where the scene's avatar walks, behind the short block. Each is
    // taken as given (off the nodes) and at its nearest probe node.
    const glm::vec3 bases[] = {{0.09f, 0.30f, -0.17f},
                               {0.f, 0.40f, -0.28f},
                               {-0.20f, 0.10f, -0.10f},
                               {0.20f, 0.25f, -0.40f}};
    struct Point {
        glm::vec3 x;
        bool node;
    };
    std::vector<Point> points;
    for (const glm::vec3& b : bases) {
        points.push_back({b, false});
        glm::ivec3 cell;
        glm::vec3 t;
        grid.locate(b, cell, t);
        const std::uint32_t node = grid.probeIndex(cell + glm::ivec3(glm::round(t)));
        ASSERT_TRUE(volume.enabled(node));
        points.push_back({grid.position(node), true});
    }
    std::vector<glm::vec3> normals;
    for (std::uint32_t k = 0; k < kNormals; ++k)
        normals.push_back(sh::fibonacciDirection(k, kNormals));

    std::vector<glm::vec3> xs, ns;
    for (const Point& p : points)
        for (const glm::vec3& n : normals) {
            xs.push_back(p.x);
            ns.push_back(n);
        }
    reference::ReferenceSettings refSettings;
    refSettings.samplesPerPoint = 4096;
    refSettings.seed = 5;
    const auto ref = reference::estimateIrradiance(world, scene, xs, ns, refSettings);

    std::size_t k = 0;
    for (const Point& p : points) {
        sh::ShRgb L;
        ProbeBlend blend;
        ASSERT_TRUE(volume.interpolate(p.x, L, &blend));
        const glm::vec3 truncation = sh::kDirectionalMaxError * sh::integral(L);
        double sumProbe[3] = {}, sumRef[3] = {}, varRef[3] = {}, sumSpread[3] = {};
        for (const glm::vec3& n : normals) {
            const glm::vec3 e = sh::irradiance(L, n);
            glm::vec3 lo(1e30f), hi(-1e30f);
            for (int c = 0; c < 8; ++c)
                if (blend.weights[c] > 0.f) {
                    const glm::vec3 corner =
                        sh::irradiance(volume.coefficients(blend.probes[c]), n);
                    lo = glm::min(lo, corner);
                    hi = glm::max(hi, corner);
                }
            const glm::vec3 spread = p.node ? glm::vec3(0.f) : hi - lo;
            for (int c = 0; c < 3; ++c) {
                const double r = ref[k].mean[c], se = ref[k].standardError[c];
                const double bound = 4.0 * se + truncation[c] + spread[c] + kInputAllowance * r;
                EXPECT_NEAR(e[c], r, bound) << "point " << p.x.x << "," << p.x.y << "," << p.x.z
                                            << (p.node ? " (node)" : "") << " normal " << n.x << ","
                                            << n.y << "," << n.z << " channel " << c;
                sumProbe[c] += e[c];
                sumRef[c] += r;
                varRef[c] += se * se;
                sumSpread[c] += spread[c];
            }
            ++k;
        }
        for (int c = 0; c < 3; ++c) {
            const double meanProbe = sumProbe[c] / kNormals, meanRef = sumRef[c] / kNormals;
            const double bound = 4.0 * std::sqrt(varRef[c]) / kNormals + kInputAllowance * meanRef +
                                 sumSpread[c] / kNormals;
            EXPECT_NEAR(meanProbe, meanRef, bound) << "normal-averaged, point " << p.x.x << ","
                                                   << p.x.y << "," << p.x.z << " channel " << c;
            std::printf("point (%.3f %.3f %.3f)%s ch%d: mean E probe %.3f ref %.3f (bound %.3f)\n",
                        p.x.x, p.x.y, p.x.z, p.node ? " node" : "     ", c, meanProbe, meanRef,
                        bound);
        }
    }
}

} // namespace
} // namespace qgi
