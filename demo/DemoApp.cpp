#include "demo/DemoApp.h"

#include "components/Camera.h"
#include "components/DirectionalLight.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/PointCacheShaded.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/Transform.h"
#include "components/WorldTransform.h"
#include "demo/CameraPath.h"
#include "demo/FlyController.h"
#include "demo/Overlay.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/io/AtomicFile.h"
#include "runtime/io/CacheFile.h"
#include "runtime/io/IrradianceExport.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/render/GlWindow.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneLoader.h"
#include "runtime/scene/SceneQueries.h"
#include "systems/frame/FrameSchedule.h"
#include "systems/point_cache/PointCacheFile.h"
#include "systems/sh_probes/AvatarShExport.h"
#include "systems/vlf/Vlf.h"
#include "systems/vlf/VlfCache.h"
#include "systems/vlf/VlfScene.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>

namespace qgi::demo {

namespace {

/// A scene without a camera (a level from a tool that keeps its cameras elsewhere) gets one
/// beyond the +Z side of its bounds, above the middle, looking at the centre from far enough
/// to see the whole scene: at least 20 degrees down, so that a flat level (a floor, a
/// terrain) is not seen edge-on.
Entity addDefaultCamera(Registry& registry) {
    const Aabb& bounds = registry.ctx().get<SceneInfo>().bounds;
    const glm::vec3 center = bounds.empty() ? glm::vec3(0.f) : bounds.center();
    const glm::vec3 extent = bounds.empty() ? glm::vec3(1.f) : bounds.extent();
    Camera camera;
    camera.active = true;
    const float radius = std::max(0.5f * glm::length(extent), 0.01f);
    const float distance = radius / std::tan(0.5f * camera.yfov);
    const float back = 0.5f * extent.z + distance;
    const float up = std::max(0.25f * extent.y, std::tan(glm::radians(20.f)) * back);
    const glm::vec3 eye = center + glm::vec3(0.f, up, back);
    camera.znear = std::max(1e-3f * distance, 1e-3f);
    camera.zfar = std::max(camera.zfar, 4.f * (distance + radius));
    Transform pose;
    pose.translation = eye;
    pose.rotation = glm::quatLookAt(glm::normalize(center - eye), glm::vec3(0.f, 1.f, 0.f));
    const Entity e = registry.create();
    registry.emplace<Name>(e, "default camera");
    registry.emplace<Camera>(e, camera);
    registry.emplace<Transform>(e, pose);
    registry.emplace<WorldTransform>(e, glm::translate(glm::mat4(1.f), eye) *
                                            glm::mat4_cast(pose.rotation));
    logInfo("the scene has no camera: added one at (", eye.x, ", ", eye.y, ", ", eye.z,
            ") looking at its centre");
    return e;
}

/// A scene with nothing to light is an error; one with nothing that emits, a warning.
void checkLitScene(const Registry& registry) {
    const SceneInfo& info = registry.ctx().get<SceneInfo>();
    const std::string name = info.source.starts_with("builtin:") ? info.name : info.source;
    std::size_t triangles = 0;
    bool emissive = false;
    registry.view<const Mesh>().each([&](Entity e, const Mesh& mesh) {
        triangles += mesh.indices.size() / 3;
        const Material* m = registry.tryGet<Material>(e);
        emissive |= m && m->emission != glm::vec3(0.f);
    });
    if (triangles == 0)
        fail("scene '", name,
             "' has no triangles to light (its meshes are empty or have no area; points and "
             "lines are skipped)");
    const bool lights = !registry.view<const PointLight>().entities().empty() ||
                        !registry.view<const SpotLight>().entities().empty() ||
                        !registry.view<const DirectionalLight>().entities().empty();
    if (!lights && !emissive && registry.ctx().get<SceneInfo>().environment == glm::vec3(0.f))
        logWarning("scene '", name,
                   "' has no lights, no emissive surfaces and a black sky: "
                   "the image will be black");
}

void applyCameraPath(Registry& registry, const std::string& choice) {
    Entity camera = findActiveCamera(registry);
    if (!camera) camera = addDefaultCamera(registry);
    if (choice == "scene") return;
    if (choice == "none") {
        registry.remove<PathFollower>(camera);
        return;
    }
    registry.emplaceOrReplace<PathFollower>(camera, loadCameraPath(choice));
}

/// What --export-irradiance holds, in each mode (a comment in the PLY header).
constexpr const char* kPhotonExportNote = "photon mode: all light, from photons";
constexpr const char* kHybridExportNote =
    "hybrid mode: the direct light of the lights the renderer draws (point, spot and "
    "directional lights, emissive surfaces with a light stand-in) is left out; the rest (light "
    "that reflected at least once, and the direct light of emissive surfaces without a stand-in) "
    "is in";

/// The signal that asked the frame loop to stop (SIGINT or SIGTERM), or 0. Lock-free, so the
/// handler may set it on any thread.
std::atomic<int> gInterrupt{0};
static_assert(std::atomic<int>::is_always_lock_free);

extern "C" void onInterrupt(int signal) {
    const int savedErrno = errno;
    gInterrupt.store(signal, std::memory_order_relaxed);
    constexpr char kMessage[] =
        "\nqgi-demo: interrupted: stopping after this frame and writing the outputs (again to "
        "quit at once)\n";
    [[maybe_unused]] const ssize_t written = ::write(2, kMessage, sizeof kMessage - 1);
    errno = savedErrno;
}

/// While alive, Ctrl-C (SIGINT) and SIGTERM end the frame loop after the frame in progress, so
/// that the outputs of the frames run are written; a second one ends the process at once (the
/// handlers are one-shot). A signal the process was started ignoring (a background job's
/// SIGINT) stays ignored. Before the loop (a long bake) the defaults stand.
class InterruptGuard {
public:
    InterruptGuard() {
        gInterrupt = 0;
        struct sigaction action {};
        action.sa_handler = onInterrupt;
        sigemptyset(&action.sa_mask);
        action.sa_flags = SA_RESETHAND | SA_RESTART;
        for (auto& [signal, previous] : mPrevious) {
            sigaction(signal, nullptr, &previous);
            if (previous.sa_handler != SIG_IGN) sigaction(signal, &action, nullptr);
        }
    }
    ~InterruptGuard() {
        for (const auto& [signal, previous] : mPrevious)
            sigaction(signal, &previous, nullptr);
    }
    InterruptGuard(const InterruptGuard&) = delete;
    InterruptGuard& operator=(const InterruptGuard&) = delete;

private:
    std::pair<int, struct sigaction> mPrevious[2] = {{SIGINT, {}}, {SIGTERM, {}}};
};

/// The files the demo reads (the scene, unless built in; a camera path file), which no output
/// may overwrite.
std::vector<std::filesystem::path> inputFiles(const DemoOptions& options) {
    std::vector<std::filesystem::path> inputs;
    if (!isBuiltinScene(options.scene)) inputs.emplace_back(options.scene);
    if (options.cameraPath != "scene" && options.cameraPath != "none")
        inputs.emplace_back(options.cameraPath);
    return inputs;
}

/// Claims `file` for `option`: no other output of the run may write the same file (through
/// symbolic links, dangling ones included).
void claimOutput(const std::filesystem::path& file, const char* option,
                 std::vector<std::pair<std::filesystem::path, const char*>>& written) {
    const std::filesystem::path name = writeTarget(file);
    for (const auto& [other, by] : written)
        if (name == other) fail(option, ": '", file.string(), "' is written by ", by, " too");
    written.emplace_back(name, option);
}

/// Checks an output option before the run: a file path (or, `extended`, a base path that
/// names the files BASE + each of `extensions`) that can be written, that is no input of the
/// run, no file another output writes (`written`, which gets this option's files) and no FIFO
/// or device (opening one would block or write who knows where).
void prepareOutput(const std::optional<std::string>& base, const char* option,
                   const std::vector<std::filesystem::path>& inputs,
                   std::vector<std::pair<std::filesystem::path, const char*>>& written,
                   bool extended = false, std::initializer_list<const char*> extensions = {}) {
    if (!base) return;
    namespace fs = std::filesystem;
    if (base->empty()) fail(option, ": the path is empty");
    std::error_code error;
    std::vector<fs::path> files;
    if (!extended) files.emplace_back(*base);
    for (const char* extension : extensions)
        files.emplace_back(*base + extension);
    for (const fs::path& file : files) {
        claimOutput(file, option, written);
        const bool present = fs::exists(file, error);
        if (error) fail(option, ": '", file.string(), "': ", error.message());
        if (!present) continue;
        for (const fs::path& input : inputs)
            if (fs::equivalent(file, input, error))
                fail(option, ": '", file.string(), "' is an input of this run; not overwritten");
        if (fs::is_directory(file, error))
            fail(option, ": '", file.string(), "' is a folder; not written");
        if (!fs::is_regular_file(file, error))
            fail(option, ": '", file.string(), "' is not a regular file; not written");
    }
    // A base path (`extended`) names files BASE.ext: a folder of that name is no obstacle.
    if (base->back() == '/' || (!extended && fs::is_directory(*base, error)))
        fail(option, ": '", *base, "' is a folder; give a file path");
    // The folder the write goes to (a link's target's), where its temporary file is made.
    const fs::path folder = writeTarget(files.front()).parent_path();
    fs::create_directories(folder, error);
    if (error)
        fail(option, ": cannot create the folder '", folder.string(), "': ", error.message());
    // Write permission alone does not tell (root may write anywhere but /proc and /sys): create
    // a file there and remove it again.
    const fs::path probe = folder / (".qgi-write-test-" + std::to_string(::getpid()));
    const bool writable = std::ofstream(probe).good();
    fs::remove(probe, error);
    if (!writable) fail(option, ": the folder '", folder.string(), "' is not writable");
}

/// `--vlf auto`: on when the static scene has glossy or mirror faces, but not more than 256 of
/// them. The VLF stores light per planar face, so a curved glossy mesh (every triangle its own
/// face, tiles in every direction) makes a large, slow field: that needs `--vlf on`.
bool wantVlf(const Registry& registry) {
    bool any = false;
    registry.view<const StaticMesh, const Material>().each(
        [&](const StaticMesh&, const Material& m) {
            any |= vlf::VlfScene::fromComponent(m).specular != glm::vec3(0.f);
        });
    if (!any) return false;
    const auto scene = vlf::VlfScene::fromRegistry(registry, nullptr, /*traced=*/false);
    std::size_t specular = 0;
    for (const vlf::Face& f : scene->faces())
        specular += f.isSpecular();
    if (specular > 256) {
        logInfo("VLF off: ", specular, " glossy or mirror faces (curved glossy meshes); ",
                "--vlf on bakes them anyway");
        return false;
    }
    return true;
}

/// The cache file an option names: "none" none, "auto" <scene><extension> in the working
/// folder (none, with a warning, when somebody's file is there), else the path given (checked
/// before the load by checkCacheTarget).
std::filesystem::path cacheFileOf(const std::string& option, const char* name,
                                  const Registry& world, const char* extension,
                                  std::string_view magic, const char* what) {
    if (option == "none") return {};
    if (option != "auto") return option;
    std::filesystem::path file = world.ctx().get<SceneInfo>().name + extension;
    if (!mayReplaceWithCache(file, magic)) {
        logWarning(name, " auto (the default): ", file.string(), " exists and is not ", what,
                   " file, so it is left alone and the bake is not kept (", name,
                   " FILE names another file; none says nothing)");
        file.clear();
    }
    return file;
}

/// The frame schedule; a VLF beyond the machine's memory or the GL limit (found before its
/// bake) is told in the demo's own options.
FrameSchedule buildSchedule(Registry& world, const FrameSettings& settings,
                            const DemoOptions& options) {
    try {
        return FrameSchedule(world, settings);
    } catch (const vlf::VlfTooLarge& e) {
        fail("--vlf-level ", options.vlfLevel, " --vlf-lines ", options.vlfLines,
             ": the VLF of this scene ", e.detail, "; lower --vlf-level or --vlf-lines",
             options.vlf == "auto" ? " (or --vlf off)" : "");
    }
}

} // namespace

int runDemo(const DemoOptions& options) {
    if (options.quiet) setLogLevel(LogLevel::Warning);
    const std::vector<std::filesystem::path> inputs = inputFiles(options);
    std::vector<std::pair<std::filesystem::path, const char*>> written;
    prepareOutput(options.screenshot, "--screenshot", inputs, written, true, {".png", ".exr"});
    prepareOutput(options.profile, "--profile", inputs, written, true, {".json", ".csv"});
    prepareOutput(options.exportScene, "--export-scene", inputs, written);
    prepareOutput(options.exportIrradiance, "--export-irradiance", inputs, written);
    prepareOutput(options.exportAvatars, "--export-avatars", inputs, written);
    // An earlier export (or an empty file made for it) is rewritten; any other file is
    // somebody's.
    const auto ownExportOnly = [](const std::optional<std::string>& path, const char* option,
                                  bool (*isExport)(const std::filesystem::path&),
                                  const char* what) {
        std::error_code sizeError;
        if (path && std::filesystem::exists(*path, sizeError) &&
            std::filesystem::file_size(*path, sizeError) != 0 && !isExport(*path))
            fail(option, ": '", *path, "' exists and is not ", what, " of qgi's; not overwritten");
    };
    ownExportOnly(options.exportIrradiance, "--export-irradiance", isIrradiancePly,
                  "an irradiance export");
    ownExportOnly(options.exportAvatars, "--export-avatars", isAvatarShCsv, "an avatar SH export");
    // Cache files are rewritten when stale: never over somebody's file, nor over another
    // output of the run.
    const bool pointCacheNamed =
        options.pointCacheFile != "auto" && options.pointCacheFile != "none";
    const bool vlfCacheNamed = options.vlfCache != "auto" && options.vlfCache != "none";
    if (pointCacheNamed) {
        claimOutput(options.pointCacheFile, "--point-cache-file", written);
        checkCacheTarget(options.pointCacheFile, kPointCacheMagic,
                         "point cache file (--point-cache-file)");
    }
    if (vlfCacheNamed) {
        claimOutput(options.vlfCache, "--vlf-cache", written);
        checkCacheTarget(options.vlfCache, vlf::VlfCache::kMagic, "VLF cache file (--vlf-cache)");
    }

    // The window comes first: without a GL 4.5 context there is nothing to show, and the user
    // should learn that before a long scene load.
    WindowSettings windowSettings;
    windowSettings.width = options.width;
    windowSettings.height = options.height;
    windowSettings.headless = options.headless;
    const bool egl = options.context == "egl" || (options.context == "auto" && options.headless &&
                                                  !GlWindow::displayAvailable());
    if (egl && options.context == "auto")
        logInfo("no display: rendering headless through EGL (--context window needs an X "
                "server such as Xvfb)");
    windowSettings.platform = egl ? GlPlatform::Egl : GlPlatform::Window;
    windowSettings.debugContext = windowSettings.debugContext || options.glDebug;
    windowSettings.title = "qgi - " + options.scene;
    GlWindow window(windowSettings);

    Registry world;
    FrameProfiler& profiler = world.ctx().emplace<FrameProfiler>();
    const auto loadStart = std::chrono::steady_clock::now();
    {
        FrameProfiler::Scope scope(&profiler, "load.scene");
        loadScene(world, options.scene, SceneOptions{options.maxEdgeLength});
    }
    checkLitScene(world);
    applyCameraPath(world, options.cameraPath);
    if (options.exportScene) {
        exportGltf(world, *options.exportScene);
        logInfo("wrote ", *options.exportScene);
    }

    FrameSettings frameSettings;
    if (options.photons > 0) {
        frameSettings.photons->photonCount = options.photons;
        frameSettings.photons->seed = options.seed;
        frameSettings.photons->fullRecompute = options.fullRecompute;
        frameSettings.irradiance.estimator = parseIrradianceEstimator(options.estimator);
        frameSettings.irradiance.discRadius = options.discRadius;
        if (options.discRadius > 0.f && options.estimator == "impact")
            logWarning("--disc-radius has no effect with --estimator impact (it counts the "
                       "photons landing on each vertex's triangles)");
    } else {
        frameSettings.photons.reset();
        if (options.mode == "photon")
            logWarning("--photons 0 in photon mode: all light comes from photons, so only "
                       "emissive surfaces will show");
        if (options.exportIrradiance)
            logWarning("--photons 0: --export-irradiance will write zero irradiance");
    }
    if (options.vlf == "on" || (options.vlf == "auto" && wantVlf(world))) {
        VlfSystemSettings vlf;
        vlf.bake.directionLevel = options.vlfLevel;
        vlf.bake.linesPerSide = options.vlfLines;
        vlf.bake.seed = options.seed;
        vlf.cacheFile = cacheFileOf(options.vlfCache, "--vlf-cache", world, ".vlf",
                                    vlf::VlfCache::kMagic, "a VLF cache");
        frameSettings.vlf = vlf;
    }
    frameSettings.irradiance.hybrid = options.mode == "hybrid";
    frameSettings.probes->hybrid = options.mode == "hybrid";
    frameSettings.probes->seed = options.seed;
    const bool pointCache = options.pointCache || pointCacheNamed || options.showPoints;
    const bool anyTagged = !world.view<const PointCacheShaded>().entities().empty();
    if (pointCache && options.mode != "hybrid")
        logWarning("--point-cache: the point cache shades hybrid mode only; not built");
    else if (pointCache && !anyTagged)
        logWarning("--point-cache: no surface is tagged for it (glTF node extras "
                   "{\"pointCache\": true}); not built");
    else if (pointCache) {
        frameSettings.pointCache = PointCacheSettings{};
        frameSettings.pointCache->seed = options.seed;
        frameSettings.pointCache->cacheFile =
            cacheFileOf(options.pointCacheFile, "--point-cache-file", world, ".pcache",
                        kPointCacheMagic, "a point cache")
                .string();
    }
    RenderSettings& render = *frameSettings.render;
    render.width = window.width();
    render.height = window.height();
    render.mode = options.mode == "photon" ? ShadingMode::Photon : ShadingMode::Hybrid;
    render.exposure =
        options.exposure > 0.f ? options.exposure : world.ctx().get<SceneInfo>().exposure;
    FrameSchedule frame = buildSchedule(world, frameSettings, options);
    const GlfwInput input(window.handle());
    FlyController controller(input);
    if (frame.renderer()) frame.renderer()->setShowPointCache(options.showPoints);
    // The overlay draws through GLFW: not in an EGL pbuffer.
    std::unique_ptr<Overlay> overlay;
    const bool overlayWanted =
        options.overlay == "on" || (options.overlay == "auto" && !options.headless);
    if (overlayWanted && window.handle()) {
        try {
            overlay = std::make_unique<Overlay>(window.handle());
        } catch (const Error& e) {
            if (options.overlay == "on") throw;
            logWarning(e.what(), "; running without it (--overlay off says nothing)");
        }
    } else if (options.overlay == "on") {
        logWarning("--overlay on: an EGL pbuffer has no window to draw it in; running without "
                   "the overlay (--context window draws it)");
    }
    OverlayInfo overlayInfo;
    overlayInfo.scene = world.ctx().get<SceneInfo>().name;
    overlayInfo.lighting =
        options.photons > 0
            ? str(options.mode, " mode, ", options.photons, " photons, ", options.estimator,
                  options.fullRecompute ? ", full recompute" : "")
            : str(options.mode, " mode, no photons");
    bool pointKeyWasDown = false;
    if (!options.headless)
        frame.schedule().add("input", "input", [&](Registry& r, const FrameContext& f) {
            controller.update(r, f);
        });

    const double loadSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - loadStart).count();
    const auto& info = world.ctx().get<SceneInfo>();
    logInfo("scene '", info.name, "' ready in ", loadSeconds, " s: ", world.aliveCount(),
            " entities, mesh edge bound ", info.maxEdgeLength, " m");

    std::string failures; // outputs that could not be written
    FrameContext context;
    context.seed = options.seed;
    auto last = std::chrono::steady_clock::now();
    const InterruptGuard interruptGuard;
    for (std::uint64_t f = 0; options.frames == 0 || f < std::uint64_t(options.frames); ++f) {
        if (gInterrupt) {
            logWarning(
                "stopped after ", f, options.frames ? str(" of ", options.frames) : "", " frames",
                options.screenshot ? ": no screenshot (it is taken after the last frame)" : "");
            break;
        }
        window.pollEvents();
        if (window.shouldClose()) break;
        if (!options.headless && glfwGetKey(window.handle(), GLFW_KEY_ESCAPE) == GLFW_PRESS) break;
        if (!options.headless && frame.renderer()) { // P: point-set view on / off
            const bool down = glfwGetKey(window.handle(), GLFW_KEY_P) == GLFW_PRESS;
            if (down && !pointKeyWasDown)
                frame.renderer()->setShowPointCache(!frame.renderer()->showPointCache());
            pointKeyWasDown = down;
        }

        const auto now = std::chrono::steady_clock::now();
        const double realDt = std::chrono::duration<double>(now - last).count();
        last = now;
        context.dt = f == 0 ? 0.f : float(options.headless ? options.dt : realDt);
        context.time += context.dt;
        context.frameIndex = f;

        const bool lastFrame = options.frames != 0 && f + 1 == std::uint64_t(options.frames);
        const bool f12 = !options.headless && glfwGetKey(window.handle(), GLFW_KEY_F12) == GLFW_PRESS;
        const bool screenshot = options.screenshot && (lastFrame || f12) && frame.renderer();
        if (screenshot) frame.renderer()->requestScreenshot(*options.screenshot);
        frame.run(world, context);
        if (overlay) {
            const Entity selected = controller.selectedMobile();
            overlayInfo.selected = selected ? entityName(world, selected) : "";
            overlayInfo.lampsOff = controller.lampsOff();
            overlayInfo.pointsShown = frame.renderer() && frame.renderer()->showPointCache();
            overlay->draw(profiler, overlayInfo);
            controller.setMouseTaken(overlay->wantsMouse());
        }
        window.swapBuffers();
        // A headless run exists to write its outputs: one that could not be written fails it
        // (after the others were written, below).
        if (screenshot && options.headless) {
            const auto& outcome = frame.renderer()->lastScreenshot();
            if (!outcome || !outcome->error.empty())
                failures +=
                    str(failures.empty() ? "" : "; ",
                        "--screenshot: ", outcome ? outcome->error : "no frame was rendered");
        }
        if (options.headless && !options.quiet && (f + 1) % 60 == 0)
            logInfo("frame ", f + 1, "/", options.frames);
    }

    // Each output is written even when another fails; the run fails after all were tried.
    const auto write = [&](const char* option, const auto& fn) {
        try {
            fn();
        } catch (const std::exception& e) {
            failures += str(failures.empty() ? "" : "; ", option, ": ", e.what());
        }
    };
    // What the lighting exports hold, in the log.
    const bool hybrid = options.mode == "hybrid";
    const char* const holds =
        hybrid ? " (hybrid mode: without the direct light the renderer draws)" : "";
    if (options.exportIrradiance)
        write("--export-irradiance", [&] {
            exportVertexIrradiance(world, *options.exportIrradiance, PlyFormat::BinaryLittleEndian,
                                   hybrid ? kHybridExportNote : kPhotonExportNote);
            logInfo("wrote ", *options.exportIrradiance, holds);
        });
    if (options.exportAvatars)
        write("--export-avatars", [&] {
            exportAvatarSh(world, *options.exportAvatars);
            logInfo("wrote ", *options.exportAvatars, holds);
        });
    if (options.profile)
        write("--profile", [&] {
            profiler.writeChromeTrace(*options.profile + ".json");
            profiler.writeCsv(*options.profile + ".csv");
            logInfo("wrote ", *options.profile, ".json and .csv");
        });
    if (!failures.empty()) fail(failures);
    if (!options.quiet) std::printf("\n%s", profiler.summaryTable().c_str());
    if (const int signal = gInterrupt) {
        // End by the signal itself, as its default would have: a shell loop or make stops on a
        // child killed by SIGINT, not on one that exits with 130.
        std::fflush(nullptr);
        std::signal(signal, SIG_DFL);
        std::raise(signal);
    }
    return 0;
}

} // namespace qgi::demo
