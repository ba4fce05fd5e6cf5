// DETP vertex irradiance against the independent Monte Carlo reference (tests/reference: path
// tracing with next-event estimation, its own code): the built-in cornell scene in photon mode,
// and a room lit by a point light, a spot light and the sun in hybrid mode (where photons carry
// only light that has reflected at least once).
//
// Statistics behind the bounds. At vertex v the DETP estimate is a sum of the powers p_j of
// the segments crossing its disc, divided by pi r^2. Treating the crossings as a Poisson
// process, its standard error is sqrt(sum p_j^2) / (pi r^2), computed here from the segments
// themselves. The reference reports its own standard error. If DETP were unbiased, the
// normalised errors z = (E_detp - E_ref) / sqrt(se_detp^2 + se_ref^2) would be standard
// normal, so |z| would have median 0.674 and 90th percentile 1.645. Over n vertices the
// sample quantile q_p of |z| has standard error sqrt(p (1 - p) / n) / f(q_p), f being the
// density of |z| (2 phi); the spread bounds are the quantiles plus 4 of those standard errors.
// The relative errors |E_detp - E_ref| / E_ref are bounded the same way, by the quantiles of
// the mixture of the vertices' normal errors, each of relative spread sigma_v / E_ref(v).
// DETP is biased by the disc's smoothing (the mean irradiance over a disc of radius r, not the
// value at its centre), which matters only where irradiance curves within the disc (shadow
// edges); the vertices tested here are spread over whole surfaces, where that is rare. A
// systematic error hides in per-vertex noise, so the test also checks the mean of the signed
// z (standard error 1/sqrt(n)) and the summed irradiance, each to 4 sigma: scaling the
// estimate by 0.95 fails both.
#include "components/DirectionalLight.h"
#include "components/MobileMesh.h"
#include "components/SpotLight.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/detp/DiscCrossing.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "tests/reference/IrradianceReference.h"
#include "tests/reference/VertexSamples.h"
#include "tests/unit/test_photon_scenes.h"

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace qgi {
namespace {

using reference::percentile;
using reference::VertexSample;

/// Vertices compared, and reference paths per vertex.
constexpr std::size_t kVertices = 240;
constexpr std::uint32_t kReferencePaths = 16384;

/// Upper bound (4 standard errors) on the sample p-quantile of |z| over n standard normal z.
double quantileBound(double p, double n) {
    const double q = p == 0.5 ? 0.6744897501960817 : 1.6448536269514722; // of |z|
    QGI_ASSERT(p == 0.5 || p == 0.9, "quantileBound: median or 90th percentile only");
    const double density = 2.0 * std::exp(-0.5 * q * q) / std::sqrt(glm::two_pi<double>());
    return q + 4.0 * std::sqrt(p * (1.0 - p) / n) / density;
}

/// Upper bound (4 standard errors) on the sample p-quantile of the relative errors
/// |E_detp - E_ref| / E_ref over n vertices whose errors are normal with relative standard
/// deviations `spread` (sigma / E_ref per vertex): the p-quantile x of their mixture, solving
/// mean_v P(|z| <= x / spread_v) = p, plus 4 sqrt(p (1 - p) / n) / (the mixture's density at x).
double relativeQuantileBound(double p, const std::vector<double>& spread) {
    const double n = double(spread.size());
    const auto cdf = [&](double x) {
        double sum = 0.0;
        for (const double s : spread)
            sum += std::erf(x / (s * std::sqrt(2.0)));
        return sum / n;
    };
    double lo = 0.0, hi = 1.0;
    while (cdf(hi) < p)
        hi *= 2.0;
    for (int i = 0; i < 100; ++i)
        (cdf(0.5 * (lo + hi)) < p ? lo : hi) = 0.5 * (lo + hi);
    const double x = hi;
    double density = 0.0;
    for (const double s : spread)
        density +=
            2.0 * std::exp(-0.5 * (x / s) * (x / s)) / (s * std::sqrt(glm::two_pi<double>()));
    density /= n;
    return x + 4.0 * std::sqrt(p * (1.0 - p) / n) / density;
}

/// Checks the irradiance DETP gave `samples` (disc radius r) against the reference, with the
/// statistics above. Hybrid mode leaves out the first segments of the lights the renderer
/// draws, and compares with the reference's reflected light only. On a sample of a mobile
/// (cornell's block, which is convex), segments that leave that mobile are not counted (they
/// cannot cross a convex mobile's own discs from the front but by rounding; the system skips
/// them for convex mobiles too).
void expectSamplesAgreeWithReference(Registry& world, const DetpSettings& detpSettings, float r,
                                     const std::vector<VertexSample>& samples,
                                     std::uint32_t photonCount, const char* label) {
    const RayScene& scene = world.ctx().get<RayScene>();
    // DETP's own statistics from the stored segments, by brute force (which also checks the
    // system's disc index on the scene).
    const PhotonStore& store = world.ctx().get<PhotonStore>();
    const PhotonSegments& s = store.segments;
    std::vector<double> sum(samples.size()), sumSquares(samples.size());
    std::vector<std::size_t> crossings(samples.size());
    tbb::parallel_for(std::size_t(0), samples.size(), [&](std::size_t i) {
        double total = 0, squares = 0;
        std::size_t count = 0;
        const Entity own = world.has<MobileMesh>(samples[i].mesh) ? samples[i].mesh : Entity{};
        for (const PhotonPath& path : store.paths) {
            const bool skipsFirst = detpSettings.hybrid && store.lights[path.light].directDrawn;
            for (std::uint32_t k = skipsFirst ? 1 : 0; k < path.count; ++k) {
                const std::size_t j = path.first + k;
                if (own && k > 0 && s.hitEntity[j - 1] == own) continue; // leaves the mobile
                if (crossesDisc(s.origin[j], s.direction[j], s.length[j], samples[i].position,
                                samples[i].normal, r)) {
                    const double p = double(s.power[j].r) + s.power[j].g + s.power[j].b;
                    total += p;
                    squares += p * p;
                    ++count;
                }
            }
        }
        sum[i] = total;
        sumSquares[i] = squares;
        crossings[i] = count;
    });

    const auto expected =
        reference::photonReferenceAt(world, scene, samples, kReferencePaths, !detpSettings.hybrid);

    const double discArea = glm::pi<double>() * double(r) * double(r);
    std::vector<double> relative, normalised, spread;
    double signedZ = 0, totalEstimate = 0, totalReference = 0, totalVariance = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const glm::vec3& e = samples[i].irradiance;
        const double estimate = double(e.r) + e.g + e.b;
        // The same crossings on both sides (n of them, positive powers) differ only by
        // rounding, relative to the estimate: the system's double sum per channel and the sum
        // here are each within n 2^-53 of the exact one; the system rounds each channel to float
        // (2^-24); the remaining double roundings (channel sums, pi r^2 and its inverse, a
        // product or quotient) and second-order terms are below 2^-40 and fit in a second 2^-24.
        // A missed or extra crossing worth more than this bound fails.
        const double roundingBound = estimate * (0x1p-23 + 2.0 * double(crossings[i]) * 0x1p-53);
        EXPECT_NEAR(estimate, sum[i] / discArea, roundingBound)
            << "disc index != brute force at " << i << " (" << crossings[i] << " crossings)";
        const double ref = expected[i].mean.r + expected[i].mean.g + expected[i].mean.b;
        const double refError = expected[i].standardError.r + expected[i].standardError.g +
                                expected[i].standardError.b; // channels are correlated: add
        const double detpError = std::sqrt(sumSquares[i]) / discArea;
        if (ref <= 0.0) {
            // No light reaches it at all (the face of a block resting on the floor): no
            // segment crosses its disc either, so the estimate is exactly 0.
            EXPECT_EQ(crossings[i], 0u) << "vertex " << i << " is dark in the reference";
            EXPECT_EQ(estimate, 0.0) << "vertex " << i << " is dark in the reference";
            continue;
        }
        const double sigma = std::sqrt(detpError * detpError + refError * refError);
        relative.push_back(std::abs(estimate - ref) / ref);
        spread.push_back(sigma / ref);
        normalised.push_back(std::abs(estimate - ref) / sigma);
        signedZ += (estimate - ref) / sigma;
        totalEstimate += estimate;
        totalReference += ref;
        totalVariance += sigma * sigma;
    }
    ASSERT_GE(relative.size(), 200u);
    const double n = double(relative.size());
    const double medianZ = percentile(normalised, 0.5), p90Z = percentile(normalised, 0.9);
    const double meanZ = signedZ / n;
    const double totalZ = (totalEstimate - totalReference) / std::sqrt(totalVariance);
    const double medianRelative = percentile(relative, 0.5);
    const double p90Relative = percentile(relative, 0.9);
    std::printf("%s, %u photons, r = %.4f m, %zu vertices: relative error median %.1f%% (bound "
                "%.1f%%), 90th percentile %.1f%% (bound %.1f%%); |z| median %.2f (bound %.2f), "
                "90th percentile %.2f (bound %.2f); mean signed z %.3f (bound %.3f); summed "
                "irradiance ratio %.4f (z = %.2f)\n",
                label, photonCount, double(r), relative.size(), 100 * medianRelative,
                100 * relativeQuantileBound(0.5, spread), 100 * p90Relative,
                100 * relativeQuantileBound(0.9, spread), medianZ, quantileBound(0.5, n), p90Z,
                quantileBound(0.9, n), meanZ, 4.0 / std::sqrt(n), totalEstimate / totalReference,
                totalZ);
    // The relative errors the issue reports, against what the vertices' own standard errors
    // allow; then the same spread normalised per vertex, which weighs every vertex alike.
    EXPECT_LE(medianRelative, relativeQuantileBound(0.5, spread));
    EXPECT_LE(p90Relative, relativeQuantileBound(0.9, spread));
    EXPECT_LE(medianZ, quantileBound(0.5, n));
    EXPECT_LE(p90Z, quantileBound(0.9, n));
    // No systematic error: unbiased errors average out, so z's mean has standard error
    // 1/sqrt(n), and the summed irradiance has standard error sqrt(sum of variances).
    EXPECT_LE(std::abs(meanZ), 4.0 / std::sqrt(n));
    EXPECT_LE(std::abs(totalZ), 4.0);
}

/// Runs the photon update and DETP once on `world` and checks kVertices static vertices with
/// open neighbourhoods against the reference.
void expectAgreesWithReference(Registry& world, const PhotonSettings& photonSettings,
                               const DetpSettings& detpSettings, const char* label) {
    PhotonUpdateSystem photons(photonSettings);
    DetpIrradianceSystem detp(detpSettings);
    detp.build(world);
    photons.update(world, FrameContext{});
    detp.update(world, FrameContext{});
    const float r = detp.discRadius();
    const std::vector<VertexSample> samples =
        reference::openStaticVertices(world, world.ctx().get<RayScene>(), r, kVertices);
    ASSERT_EQ(samples.size(), kVertices);
    expectSamplesAgreeWithReference(world, detpSettings, r, samples, photonSettings.photonCount,
                                    label);
}

TEST(DetpAccuracy, CornellPhotonModeAgreesWithMonteCarloReference) {
    // (cornell's bulb is a LightStandIn: it shoots no photons and the reference ignores it.
    // Were it counted, the ceiling 2 cm above it would dominate the sum, where the disc average
    // is legitimately 15 % below the centre value by the point-light closed form.)
    Registry world;
    buildBuiltinScene(world, "cornell", SceneOptions{});
    world.ctx().emplace<RayScene>().build(world);
    PhotonSettings photonSettings;
    photonSettings.photonCount = 500'000;
    photonSettings.seed = 3;
    expectAgreesWithReference(world, photonSettings, DetpSettings{}, "cornell photon mode");
}

// The moved block's own vertices, re-estimated in full at each move (its discs through its
// moving index, its paths through the path grid): after five 1 cm slides in play, kVertices
// of them (on its faces, 2r clear of its rims and of the floor) against the reference with the
// block where it now stands.
TEST(DetpAccuracy, CornellMovedBlockAgreesWithMonteCarloReference) {
    Registry world;
    buildBuiltinScene(world, "cornell", SceneOptions{});
    RayScene& scene = world.ctx().emplace<RayScene>();
    scene.build(world);
    PhotonSettings photonSettings;
    photonSettings.photonCount = 500'000;
    photonSettings.seed = 5;
    PhotonUpdateSystem photons(photonSettings);
    DetpIrradianceSystem detp(DetpSettings{});
    detp.build(world);
    photons.update(world, FrameContext{});
    detp.update(world, FrameContext{});
    world.clearChanges();
    const Entity block = world.view<const MobileMesh>().entities().front();
    const glm::mat4 rest = world.get<WorldTransform>(block).matrix;
    for (int frame = 1; frame <= 5; ++frame) {
        world.patch<WorldTransform>(block).matrix =
            glm::translate(glm::mat4(1.f), glm::vec3(0.01f * float(frame), 0.f, 0.f)) * rest;
        scene.syncMoved(world);
        photons.update(world, FrameContext{std::uint64_t(frame), 0.0, 0.f, 0});
        detp.update(world, FrameContext{std::uint64_t(frame), 0.0, 0.f, 0});
        ASSERT_FALSE(detp.lastFrame().full);
        ASSERT_EQ(detp.lastFrame().movedMobiles, 1u);
        world.clearChanges();
    }
    const float r = detp.discRadius();
    const std::vector<VertexSample> samples =
        reference::openMobileVertices(world, scene, r, kVertices);
    ASSERT_EQ(samples.size(), kVertices);
    expectSamplesAgreeWithReference(world, DetpSettings{}, r, samples, photonSettings.photonCount,
                                    "cornell moved block, photon mode");
}

/// A 2 m room of coloured walls tessellated to 8 cm, lit by a point light, a spot light and the
/// sun through the open half of its ceiling: each kind of light the renderer draws itself in
/// hybrid mode.
void buildLitRoom(Registry& world) {
    const auto wall = [&](glm::vec3 origin, glm::vec3 u, glm::vec3 v, glm::vec3 albedo) {
        Material m;
        m.baseColor = albedo;
        test::addMesh(world, test::gridMesh(origin, u, v, 25), glm::mat4(1.f), m, false, "wall");
    };
    const glm::vec3 x(2.f, 0.f, 0.f), y(0.f, 2.f, 0.f), z(0.f, 0.f, 2.f);
    const glm::vec3 corner(-1.f, 0.f, -1.f);
    wall(corner, z, x, glm::vec3(0.6f));                   // floor, facing +y
    wall(corner + y, x, 0.5f * z, glm::vec3(0.7f));        // half a ceiling, -y
    wall(corner, y, z, glm::vec3(0.6f, 0.15f, 0.1f));      // x = -1, facing +x
    wall(corner + x, z, y, glm::vec3(0.15f, 0.5f, 0.15f)); // x = +1, facing -x
    wall(corner, x, y, glm::vec3(0.7f));                   // z = -1, facing +z
    wall(corner + z, y, x, glm::vec3(0.2f, 0.3f, 0.6f));   // z = +1, facing -z

    test::addPointLight(world, glm::vec3(-0.4f, 1.3f, -0.3f), 2.f, glm::vec3(1.f, 0.9f, 0.8f));
    const auto aimed = [](const glm::vec3& at, const glm::vec3& direction) {
        // Local -Z along `direction` (lights shine along -Z).
        const glm::vec3 back = -glm::normalize(direction);
        const glm::vec3 side = glm::normalize(glm::cross(glm::vec3(1.f, 0.f, 0.f), back));
        return glm::mat4(glm::vec4(glm::cross(side, back), 0.f), glm::vec4(side, 0.f),
                         glm::vec4(back, 0.f), glm::vec4(at, 1.f));
    };
    const Entity spot = world.create();
    world.emplace<SpotLight>(spot, SpotLight{glm::vec3(0.8f, 0.9f, 1.f), 6.f, 0.3f, 0.5f});
    world.emplace<WorldTransform>(spot,
                                  aimed(glm::vec3(0.5f, 1.8f, -0.5f), glm::vec3(0.1f, -1.f, 0.2f)));
    const Entity sun = world.create();
    world.emplace<DirectionalLight>(sun, DirectionalLight{glm::vec3(1.f, 0.95f, 0.85f), 3.f});
    world.emplace<WorldTransform>(sun, aimed(glm::vec3(0.f), glm::vec3(-0.3f, -1.f, 0.35f)));
}

TEST(DetpAccuracy, HybridModeWithPunctualLightsAgreesWithMonteCarloReference) {
    Registry world;
    buildLitRoom(world);
    world.ctx().emplace<RayScene>().build(world);
    PhotonSettings photonSettings;
    photonSettings.photonCount = 400'000;
    photonSettings.seed = 7;
    DetpSettings detpSettings;
    detpSettings.hybrid = true;
    detpSettings.discRadius = 0.05f;
    expectAgreesWithReference(world, photonSettings, detpSettings, "lit room hybrid mode");
}

} // namespace
} // namespace qgi
