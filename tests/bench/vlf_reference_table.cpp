// The VLF's diffuse irradiance on the cornell box against the independent Monte Carlo reference,
// as the direction count grows (issue: "error against the brute-force reference as directions
// grow"). The mobile block is removed first: the VLF holds the static scene only, and the
// reference must see the same geometry. The sky is black for both.
//
//   vlf_reference_table [--levels 2,3,4,5] [--vertices 240] [--reference-paths 16384]
//                       [--iterations 5] [--seed 1]
//
// Markdown table on stdout: per direction level, bake time, and |E_vlf - E_ref| / E_ref over
// the static vertices with open neighbourhoods (median, p90) and the summed ratio.
#include "components/MobileMesh.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/vlf/VlfBake.h"
#include "systems/vlf/VlfScene.h"
#include "tests/reference/IrradianceReference.h"
#include "tests/reference/VertexSamples.h"

#include <glm/geometric.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace qgi {
namespace {

struct Options {
    std::vector<int> levels{2, 3, 4, 5};
    std::size_t vertices = 240;
    std::uint32_t referencePaths = 16384;
    int iterations = 5;
    std::uint64_t seed = 1; ///< VlfSettings::seed of every bake
};

Options parse(int argc, char** argv) {
    Options o;
    const auto number = [](const std::string& text, const char* flag, long lo, long hi) {
        char* end = nullptr;
        const long v = std::strtol(text.c_str(), &end, 10);
        if (!end || *end || v < lo || v > hi)
            fail(flag, " wants a whole number in [", lo, ", ", hi, "], not '", text, "'");
        return v;
    };
    for (int i = 1; i < argc; ++i) {
        const std::string flag = argv[i];
        if (flag == "--help" || flag == "-h") {
            std::puts("vlf_reference_table [--levels L,L,...] [--vertices N] [--reference-paths N] "
                      "[--iterations N] [--seed N]\nVLF diffuse irradiance on cornell (static "
                      "part) against the Monte Carlo reference; Markdown on stdout.");
            std::exit(0);
        }
        if (i + 1 >= argc) fail(flag, " needs a value (see --help)");
        const std::string value = argv[++i];
        if (flag == "--levels") {
            o.levels.clear();
            std::stringstream list(value);
            for (std::string item; std::getline(list, item, ',');)
                o.levels.push_back(int(number(item, "--levels", 1, 6)));
        } else if (flag == "--vertices") {
            o.vertices = std::size_t(number(value, "--vertices", 1, 100000));
        } else if (flag == "--reference-paths") {
            o.referencePaths = std::uint32_t(number(value, "--reference-paths", 2, 10000000));
        } else if (flag == "--iterations") {
            o.iterations = int(number(value, "--iterations", 1, 16));
        } else if (flag == "--seed") {
            o.seed = std::uint64_t(number(value, "--seed", 0, 1000000000));
        } else {
            fail("unknown option ", flag, " (see --help)");
        }
    }
    return o;
}

int run(const Options& options) {
    Registry world;
    buildBuiltinScene(world, "cornell", SceneOptions{});
    for (const Entity e : world.view<const MobileMesh>().entities())
        world.destroy(e);
    world.ctx().get<SceneInfo>().environment = glm::vec3(0.f);
    RayScene& rays = world.ctx().emplace<RayScene>();
    rays.build(world);
    const auto samples = reference::openStaticVertices(world, rays, 0.01f, options.vertices);
    std::fprintf(stderr, "reference: %zu vertices x %u paths ...\n", samples.size(),
                 options.referencePaths);
    const auto expected =
        reference::photonReferenceAt(world, rays, samples, options.referencePaths);

    const std::unique_ptr<vlf::VlfScene> scene = vlf::VlfScene::fromRegistry(world);
    // The face whose triangles hold each vertex (a plane-and-rectangle test picks the wrong
    // half of the non-planar red wall near its diagonal, where the map holds nothing).
    std::vector<std::optional<std::uint32_t>> faceOf;
    std::size_t unmatched = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        faceOf.push_back(scene->faceAt(samples[i].position, samples[i].normal));
        unmatched += !faceOf.back();
    }
    if (unmatched > 0) std::fprintf(stderr, "%zu vertices lie on no VLF face\n", unmatched);

    std::printf("cornell without its mobile block, black sky, %d iterations, 64 x 64 lines; "
                "%zu static vertices with open neighbourhoods, Monte Carlo reference at %u paths "
                "each\n\n",
                options.iterations, samples.size(), options.referencePaths);
    std::printf("| directions | bake (s) | error median | error p90 | sum |\n|---|---|---|---|---|\n");
    for (const int level : options.levels) {
        VlfSettings settings;
        settings.directionLevel = level;
        settings.iterations = options.iterations;
        settings.seed = options.seed;
        std::fprintf(stderr, "bake at level %d ...\n", level);
        const auto start = std::chrono::steady_clock::now();
        const vlf::Vlf field = vlf::bakeVlf(*scene, settings);
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        std::vector<double> estimates, references;
        for (std::size_t i = 0; i < samples.size(); ++i) {
            references.push_back(expected[i].mean.r + expected[i].mean.g + expected[i].mean.b);
            if (!faceOf[i]) {
                estimates.push_back(std::nan("")); // on no face: left out
                continue;
            }
            const glm::vec3 e =
                field.sampleTexels(field.irradiance(), *faceOf[i], samples[i].position);
            estimates.push_back(double(e.r) + e.g + e.b);
        }
        const reference::ErrorSummary errors = reference::summariseErrors(estimates, references);
        std::printf("| %zu | %.2f | %.1f %% | %.1f %% | %+.1f %% |\n",
                    std::size_t(2 * (1u << (2 * level)) + 1), seconds, 100 * errors.median,
                    100 * errors.p90, 100 * errors.sum);
        std::fflush(stdout);
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
        std::fprintf(stderr, "vlf_reference_table: %s\n", e.what());
        return 2;
    }
}
