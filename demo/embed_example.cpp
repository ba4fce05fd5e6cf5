// The smallest program that lights a scene with qgi from a game loop of its own, without qgi's
// renderer: load a scene, build the frame, move a mobile from game code every frame (and take
// it out of the world now and then, as a pool does), and read back the per-vertex irradiance
// that changed, which is what an engine uploads to its vertex buffers. README.md, "Using qgi in
// your engine", walks through it.
//
//   qgi-embed-example [SCENE [FRAMES [PHOTONS]]]

#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/Transform.h"
#include "components/VertexIrradiance.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/scene/SceneLoader.h"
#include "systems/frame/FrameSchedule.h"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>

namespace {

constexpr const char* kUsage =
    "usage: qgi-embed-example [SCENE [FRAMES [PHOTONS]]]\n"
    "  SCENE    a built-in scene (cornell, atrium) or a .gltf/.glb file; default cornell\n"
    "  FRAMES   frames to run, 1 to 100000; default 30\n"
    "  PHOTONS  photons in the ray set, 1000 to 10000000; default 200000\n"
    "Moves the scene's first mobile 1 cm a frame along +x, takes it out of the world every\n"
    "tenth frame (a pooled object despawned for a frame), and prints, per frame, how many\n"
    "vertices' irradiance changed and what the lighting systems cost.\n";

/// A whole number in [low, high] from a command-line argument, or a qgi::Error naming it.
unsigned long wholeNumber(std::string_view text, const char* what, unsigned long low,
                          unsigned long high) {
    unsigned long value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    if (error != std::errc{} || end != text.data() + text.size() || value < low || value > high)
        qgi::fail(what, " '", text, "' is not a whole number from ", low, " to ", high);
    return value;
}

int run(int argc, char** argv) {
    const std::string scene = argc > 1 ? argv[1] : "cornell";
    const unsigned long frames = argc > 2 ? wholeNumber(argv[2], "FRAMES", 1, 100'000) : 30;
    const unsigned long photons =
        argc > 3 ? wholeNumber(argv[3], "PHOTONS", 1'000, 10'000'000) : 200'000;

    // 1. The world: a registry holding the scene's entities (meshes, lights, mobiles, ...).
    qgi::Registry world;
    qgi::loadScene(world, scene, qgi::SceneOptions{});

    // 2. The frame: the systems in their order, lighting only (the engine draws).
    qgi::FrameSettings settings;
    settings.render.reset();
    settings.photons->photonCount = std::uint32_t(photons);
    qgi::FrameSchedule frame(world, settings);

    // 3. Game code owns one mobile: drop its scripted path and drive its Transform.
    const auto mobiles = world.view<const qgi::MobileMesh, const qgi::Transform>().entities();
    if (mobiles.empty()) qgi::fail(scene, ": the scene has no mobile mesh to move");
    const qgi::Entity mobile = mobiles.front();
    world.remove<qgi::PathFollower>(mobile);
    const qgi::Name* name = world.tryGet<qgi::Name>(mobile);
    std::printf("moving '%s' 1 cm a frame along +x\n", name ? name->value.c_str() : "mobile");

    qgi::FrameContext context;
    for (unsigned long f = 0; f < frames; ++f) {
        context.frameIndex = f;
        context.dt = f == 0 ? 0.f : 1.f / 60.f;
        context.time += context.dt;
        if (f > 0) world.patch<qgi::Transform>(mobile).translation.x += 0.01f; // patch: seen
        // A pooled object: every tenth frame it leaves the world for one frame and comes back.
        const bool out = f % 10 == 9;
        if (world.get<qgi::MobileMesh>(mobile).active == out)
            world.patch<qgi::MobileMesh>(mobile).active = !out;
        const auto start = std::chrono::steady_clock::now();
        frame.run(world, context);
        const double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();

        // 4. What changed: each mesh's VertexIrradiance lists the ranges written since they were
        //    last cleared. Upload irradiance[begin, end) (W/m^2, linear RGB) and clear them.
        std::size_t meshes = 0, vertices = 0;
        world.view<qgi::VertexIrradiance>().each([&](qgi::VertexIrradiance& lit) {
            if (lit.dirty.empty()) return;
            ++meshes;
            // Ranges may overlap: sorted by start, each counts beyond what came before it.
            std::sort(lit.dirty.begin(), lit.dirty.end(),
                      [](const auto& a, const auto& b) { return a.begin < b.begin; });
            std::uint32_t covered = 0;
            for (const qgi::DirtyRange& range : lit.dirty) {
                const std::uint32_t begin = std::max(range.begin, covered);
                if (range.end > begin) vertices += range.end - begin;
                covered = std::max(covered, range.end);
            }
            lit.dirty.clear();
        });
        const auto& photonFrame = frame.photons()->lastFrame();
        std::printf("frame %3lu: %8.2f ms | photons %s, %6zu paths re-traced | %7zu vertices "
                    "on %2zu meshes changed%s\n",
                    f, ms, photonFrame.full ? "shot anew" : "updated  ", photonFrame.retracedPaths,
                    vertices, meshes, out ? " | mobile out of the world" : "");
    }
    return 0;
}

} // namespace

int main(int argc, char** argv) {
    if (argc > 1 && (std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0)) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    if (argc > 4) {
        std::fputs(kUsage, stderr);
        return 2;
    }
    try {
        return run(argc, argv);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "qgi-embed-example: %s\n", e.what());
        return 1;
    }
}
