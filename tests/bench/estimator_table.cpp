// The comparison of seed 000's tables 2.1 and 2.6-2.8 on the built-in cornell scene, photon
// mode: DETP, impact count and k-NN photon maps at several photon counts, each timed (first
// shot, full estimate, and a frame while the mobile block moves 1 cm) and checked against the
// independent Monte Carlo reference at the same static vertices.
//
//   estimator_table [--photons 100000,250000,...] [--vertices 240] [--reference-paths 16384]
//                   [--frames 8] [--max-edge M] [--disc-radius R]
//
// --max-edge refines the scene to another triangle size (metres; default the scene's 2 cm):
// impact count's support is a vertex's one-ring, so its error follows the tessellation, while
// DETP's disc (--disc-radius, default 1 cm) does not.
//
// Prints a Markdown table on stdout (docs/BENCHMARKS.md), progress on stderr. Errors:
//   median / p90: of |E - E_ref| / E_ref over the vertices (noise and bias together);
//   sum: total estimated irradiance over the vertices / the reference's, minus 1 (the bias
//        that survives averaging: the photon map's border and smoothing bias shows here).
#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "tests/reference/IrradianceReference.h"
#include "tests/reference/VertexSamples.h"

#include <glm/gtc/matrix_transform.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

namespace qgi {
namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

struct Options {
    std::vector<std::uint32_t> photons{100'000, 250'000, 500'000, 1'000'000, 2'000'000};
    std::size_t vertices = 240;
    std::uint32_t referencePaths = 16384;
    std::uint32_t frames = 8;
    float maxEdge = 0.f;     ///< 0: the scene's default refinement
    float discRadius = 0.01f; ///< the seed's reference setting for every tessellation
};

Options parse(int argc, char** argv) {
    Options o;
    const auto number = [](const char* text, const char* flag) {
        char* end = nullptr;
        const unsigned long long v = std::strtoull(text, &end, 10);
        if (!end || *end || v == 0 || v > 100'000'000ull)
            fail(flag, " wants a positive whole number up to 1e8, not '", text, "'");
        return v;
    };
    for (int i = 1; i < argc; ++i) {
        const std::string flag = argv[i];
        if (flag == "--help" || flag == "-h") {
            std::puts("estimator_table [--photons N,N,...] [--vertices N] [--reference-paths N] "
                      "[--frames N] [--max-edge M] [--disc-radius R]\nDETP vs impact count vs photon map on cornell against the "
                      "Monte Carlo reference; Markdown on stdout.");
            std::exit(0);
        }
        if (i + 1 >= argc) fail(flag, " needs a value (see --help)");
        const char* value = argv[++i];
        if (flag == "--photons") {
            o.photons.clear();
            std::stringstream list(value);
            for (std::string item; std::getline(list, item, ',');)
                o.photons.push_back(std::uint32_t(number(item.c_str(), "--photons")));
        } else if (flag == "--vertices") {
            o.vertices = number(value, "--vertices");
        } else if (flag == "--reference-paths") {
            o.referencePaths = std::uint32_t(number(value, "--reference-paths"));
        } else if (flag == "--frames") {
            o.frames = std::uint32_t(number(value, "--frames"));
        } else if (flag == "--max-edge" || flag == "--disc-radius") {
            char* end = nullptr;
            const float v = std::strtof(value, &end);
            if (!end || *end || !(v >= 0.001f && v <= 1.f))
                fail(flag, " wants metres between 0.001 and 1, not '", value, "'");
            (flag == "--max-edge" ? o.maxEdge : o.discRadius) = v;
        } else {
            fail("unknown option ", flag, " (see --help)");
        }
    }
    return o;
}

struct Row {
    double shot = 0, estimate = 0, photonFrame = 0, estimateFrame = 0;
    double median = 0, p90 = 0, sum = 0;
};

Row measure(std::uint32_t photons, IrradianceEstimator estimator, float radius,
            const std::vector<reference::IrradianceEstimate>& expected, const Options& options) {
    Registry world;
    buildBuiltinScene(world, "cornell", SceneOptions{options.maxEdge});
    world.ctx().emplace<RayScene>().build(world);
    PhotonSettings photonSettings;
    photonSettings.photonCount = photons;
    photonSettings.seed = 3;
    photonSettings.punctualLights = false; // photon mode: the luminaire, not its stand-in
    PhotonUpdateSystem photonSystem(photonSettings);
    DetpSettings settings;
    settings.estimator = estimator;
    settings.discRadius = radius;
    DetpIrradianceSystem irradiance(settings);
    irradiance.build(world);

    Row row;
    auto start = Clock::now();
    photonSystem.update(world, FrameContext{});
    row.shot = secondsSince(start);
    start = Clock::now();
    irradiance.update(world, FrameContext{});
    row.estimate = secondsSince(start);
    world.clearChanges();

    const RayScene& scene = world.ctx().get<RayScene>();
    const auto samples = reference::openStaticVertices(world, scene, radius, options.vertices);
    std::vector<double> estimates, references;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const glm::vec3& e = samples[i].irradiance;
        estimates.push_back(double(e.r) + e.g + e.b);
        references.push_back(expected[i].mean.r + expected[i].mean.g + expected[i].mean.b);
    }
    const reference::ErrorSummary errors = reference::summariseErrors(estimates, references);
    row.median = errors.median;
    row.p90 = errors.p90;
    row.sum = errors.sum;

    // Frames: the block slides 1 cm along x per frame.
    const Entity mobile = world.view<const MobileMesh>().entities().front();
    const glm::mat4 rest = world.get<WorldTransform>(mobile).matrix;
    for (std::uint32_t f = 1; f <= options.frames; ++f) {
        world.patch<WorldTransform>(mobile).matrix =
            glm::translate(glm::mat4(1.f), glm::vec3(0.01f * float(f), 0.f, 0.f)) * rest;
        world.ctx().get<RayScene>().syncMoved(world);
        const FrameContext frame{f, 0.0, 0.f, 0};
        start = Clock::now();
        photonSystem.update(world, frame);
        row.photonFrame += secondsSince(start) / options.frames;
        start = Clock::now();
        irradiance.update(world, frame);
        row.estimateFrame += secondsSince(start) / options.frames;
        world.clearChanges();
    }
    return row;
}

int run(const Options& options) {
    // The reference at the rest pose, once: the vertices every estimator is judged at.
    Registry world;
    buildBuiltinScene(world, "cornell", SceneOptions{options.maxEdge});
    RayScene& scene = world.ctx().emplace<RayScene>();
    scene.build(world);
    const float radius = options.discRadius;
    const auto samples = reference::openStaticVertices(world, scene, radius, options.vertices);
    std::fprintf(stderr, "reference: %zu vertices x %u paths ...\n", samples.size(),
                 options.referencePaths);
    auto start = Clock::now();
    const auto expected =
        reference::photonReferenceAt(world, scene, samples, options.referencePaths);
    std::fprintf(stderr, "reference: %.1f s\n", secondsSince(start));

    std::printf("cornell refined to %.3f m edges, photon mode, r = %.4f m, %zu static vertices "
                "with open neighbourhoods, Monte Carlo reference at %u paths each; frame = the "
                "block sliding 1 cm\n\n",
                double(world.ctx().get<SceneInfo>().maxEdgeLength), double(radius), samples.size(),
                options.referencePaths);
    std::printf("| estimator | photons | first shot (s) | full estimate (s) | frame: photons "
                "(ms) | frame: estimate (ms) | error median | error p90 | sum |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|\n");
    for (const IrradianceEstimator estimator :
         {IrradianceEstimator::Detp, IrradianceEstimator::ImpactCount,
          IrradianceEstimator::PhotonMap}) {
        for (const std::uint32_t photons : options.photons) {
            std::fprintf(stderr, "%s, %u photons ...\n",
                         std::string(irradianceEstimatorName(estimator)).c_str(), photons);
            const Row r = measure(photons, estimator, radius, expected, options);
            std::printf("| %s | %u | %.2f | %.2f | %.1f | %.1f | %.1f %% | %.1f %% | %+.1f %% |\n",
                        std::string(irradianceEstimatorName(estimator)).c_str(), photons, r.shot,
                        r.estimate, 1e3 * r.photonFrame, 1e3 * r.estimateFrame, 100 * r.median,
                        100 * r.p90, 100 * r.sum);
            std::fflush(stdout);
        }
    }
    return 0;
}

} // namespace
} // namespace qgi

int main(int argc, char** argv) {
    try {
        qgi::setLogLevel(qgi::LogLevel::Warning);
        return qgi::run(qgi::parse(argc, argv));
    } catch (const qgi::Error& e) {
        std::fprintf(stderr, "estimator_table: %s\n", e.what());
        return 2;
    }
}
