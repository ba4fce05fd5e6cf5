// Runs the qgi-demo binary the way a user would and checks what it writes.
#include "runtime/io/Exr.h"
#include "runtime/io/Ply.h"
#include "runtime/io/Png.h"
#include "runtime/scene/SceneLoader.h"
#include "systems/sh_probes/AvatarShExport.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/StaticMesh.h"

#include <glm/geometric.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <set>
#include <string>

namespace qgi {
namespace {

namespace fs = std::filesystem;

struct RunResult {
    int exitCode = -1;
    std::string output; // stdout and stderr
};

/// Runs the demo with `arguments`, the variables in `unset` removed from its environment.
/// Runs qgi-demo with `arguments`, without the environment variables in `unset`, in the
/// folder `workingDir` (when given).
RunResult runDemo(const std::string& arguments, std::initializer_list<const char*> unset = {},
                  const fs::path& workingDir = {}) {
    std::string command = workingDir.empty() ? "env" : "cd '" + workingDir.string() + "' && env";
    for (const char* name : unset)
        command.append(" -u ").append(name);
    command.append(" ").append(QGI_DEMO_PATH).append(" ").append(arguments).append(" 2>&1");
    RunResult result;
    FILE* pipe = popen(command.c_str(), "r");
    if (!pipe) return result;
    char buffer[4096];
    while (std::fgets(buffer, sizeof buffer, pipe)) result.output += buffer;
    const int status = pclose(pipe);
    result.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return result;
}

fs::path scratchDir() {
    const fs::path dir = fs::temp_directory_path() / "qgi_demo_smoke";
    fs::create_directories(dir);
    return dir;
}

TEST(DemoSmoke, HeadlessCornellWritesEveryRequestedFile) {
    const fs::path dir = scratchDir();
    const std::string base = (dir / "cornell").string();
    const int frames = 6;
    const RunResult run = runDemo("--scene cornell --headless --frames " + std::to_string(frames) +
                                  " --width 160 --height 120 --screenshot " + base +
                                  " --profile " + base + " --export-scene " + base + ".gltf");
    ASSERT_EQ(run.exitCode, 0) << run.output;

    // Screenshot: tonemapped PNG and linear EXR of the requested size, finite, not all black.
    const Image8 png = readPng(base + ".png");
    EXPECT_EQ(png.width, 160);
    EXPECT_EQ(png.height, 120);
    const ImageF exr = readExr(base + ".exr");
    ASSERT_EQ(exr.width, 160);
    ASSERT_EQ(exr.height, 120);
    double sum = 0.0;
    for (float v : exr.rgba) {
        ASSERT_TRUE(std::isfinite(v));
        ASSERT_GE(v, 0.f);
        sum += v;
    }
    EXPECT_GT(sum, 0.0) << "the lit Cornell box rendered black";

    // Profile: a valid trace with every schedule entry in every frame, a CSV row per frame.
    std::ifstream traceFile(base + ".json");
    const auto trace = nlohmann::json::parse(traceFile);
    std::set<std::string> names;
    int frameEvents = 0;
    for (const auto& e : trace.at("traceEvents")) {
        if (e.at("ph") != "X") continue;
        names.insert(e.at("name").get<std::string>());
        if (e.at("cat") == "frame") ++frameEvents;
    }
    EXPECT_EQ(frameEvents, frames);
    for (const char* entry : {"animation", "transform", "raytrace.sync", "photon.update",
                              "detp.irradiance", "render"})
        EXPECT_TRUE(names.count(entry)) << "no trace event for " << entry;
    // No lag: within every frame the moved poses reach the ray scene, then the photons, then
    // the irradiance, then the image.
    const std::vector<std::string> order{"transform", "raytrace.sync", "photon.update",
                                         "detp.irradiance", "render"};
    for (const auto& frame : trace.at("traceEvents")) {
        if (frame.at("ph") != "X" || frame.at("cat") != "frame") continue;
        const double begin = frame.at("ts").get<double>();
        const double end = begin + frame.at("dur").get<double>();
        std::vector<double> starts(order.size(), -1.0);
        for (const auto& e : trace.at("traceEvents")) {
            if (e.at("ph") != "X") continue;
            const double ts = e.at("ts").get<double>();
            const auto it = std::find(order.begin(), order.end(), e.at("name").get<std::string>());
            if (it != order.end() && ts >= begin && ts <= end)
                starts[std::size_t(it - order.begin())] = ts;
        }
        for (std::size_t i = 0; i < order.size(); ++i)
            ASSERT_GE(starts[i], begin) << order[i] << " missing from a frame";
        EXPECT_TRUE(std::is_sorted(starts.begin(), starts.end()))
            << "the frame's systems ran out of order";
    }
    std::ifstream csv(base + ".csv");
    std::string line;
    int rows = -1; // header
    while (std::getline(csv, line)) ++rows;
    EXPECT_EQ(rows, frames);

    // The summary table is printed at exit.
    EXPECT_NE(run.output.find("p95 ms"), std::string::npos) << run.output;

    // The exported scene imports again with the same number of meshes.
    Registry original, reimported;
    loadScene(original, "cornell", SceneOptions{});
    loadScene(reimported, base + ".gltf", SceneOptions{});
    EXPECT_EQ(reimported.count<Mesh>(), original.count<Mesh>());
}

TEST(DemoSmoke, HelpExitsZeroAndListsTheOptions) {
    const RunResult run = runDemo("--help");
    EXPECT_EQ(run.exitCode, 0);
    for (const char* option :
         {"--scene", "--headless", "--frames", "--width", "--height", "--camera-path",
          "--screenshot", "--profile", "--seed", "--export-scene", "--context", "--gl-debug",
          "--photons", "--mode", "--estimator", "--disc-radius", "--full-recompute",
          "--export-irradiance", "--overlay"})
        EXPECT_NE(run.output.find(option), std::string::npos) << option;
}

/// A demo run's exported irradiance (--export-irradiance), with what the test derives from it.
struct ExportedLight {
    PlyMesh ply;
    std::string output; ///< what the demo printed
    /// W landing on the static surfaces by the export: sum over static vertices of E times a
    /// third of the area of the triangles around the vertex (for the impact count this is
    /// exactly the power of the impacts on static triangles), summed over the channels.
    double staticFlux = 0.0;
};

/// Runs the demo on the Cornell box for `frames` frames (its block moves on its scripted path)
/// with 20k photons, `options` added, and reads the PLY it writes after the last frame.
ExportedLight exportLight(const std::string& name, const std::string& options, int frames = 3) {
    const fs::path ply = scratchDir() / (name + ".ply");
    fs::remove(ply);
    ExportedLight light;
    const RunResult run = runDemo("--scene cornell --headless --frames " + std::to_string(frames) +
                                  " --width 32 --height 32 --photons 20000 --seed 7 --vlf off " +
                                  options + " --export-irradiance " + ply.string());
    light.output = run.output;
    EXPECT_EQ(run.exitCode, 0) << options << ": " << run.output;
    if (run.exitCode != 0) return light;
    light.ply = readPly(ply);
    const PlyMesh& mesh = light.ply;
    std::vector<double> area(mesh.positions.size(), 0.0);
    for (std::size_t t = 0; t + 2 < mesh.triangles.size(); t += 3) {
        const glm::dvec3 a(mesh.positions[mesh.triangles[t]]);
        const glm::dvec3 b(mesh.positions[mesh.triangles[t + 1]]);
        const glm::dvec3 c(mesh.positions[mesh.triangles[t + 2]]);
        const double third = glm::length(glm::cross(b - a, c - a)) / 6.0;
        for (std::size_t k = 0; k < 3; ++k)
            area[mesh.triangles[t + k]] += third;
    }
    for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
        const glm::vec3& e = mesh.irradiance[v];
        EXPECT_TRUE(std::isfinite(e.x) && std::isfinite(e.y) && std::isfinite(e.z) && e.x >= 0.f &&
                    e.y >= 0.f && e.z >= 0.f)
            << options << ": vertex " << v;
        if (!mesh.mobile[v]) light.staticFlux += area[v] * (double(e.x) + e.y + e.z);
    }
    return light;
}

// Each lighting option of the demo reaches the systems and shows in what the demo exports. The
// physics of each estimator and mode is tested against closed forms and references in the unit
// and accuracy tests; here the claims are about the demo's plumbing.
TEST(DemoSmoke, LightingOptionsReachTheExportedIrradiance) {
    const ExportedLight base = exportLight("light_base", "--mode photon");
    ASSERT_FALSE(base.ply.positions.empty());
    // --photons reaches the photon update: the store holds that many paths.
    EXPECT_NE(base.output.find("photons: 20000 from "), std::string::npos) << base.output;

    // One row per vertex of every static and mobile mesh (not the avatars), the mobile
    // block's flagged.
    Registry scene;
    loadScene(scene, "cornell", SceneOptions{});
    std::size_t vertices = 0, mobileVertices = 0;
    for (const Entity e : scene.view<const Mesh>().entities()) {
        const std::size_t n = scene.get<Mesh>(e).positions.size();
        if (scene.has<StaticMesh>(e)) vertices += n;
        if (scene.has<MobileMesh>(e)) {
            vertices += n;
            mobileVertices += n;
        }
    }
    EXPECT_EQ(base.ply.positions.size(), vertices);
    EXPECT_EQ(std::size_t(std::count(base.ply.mobile.begin(), base.ply.mobile.end(), 1)),
              mobileVertices);
    EXPECT_GT(mobileVertices, 0u);
    EXPECT_GT(base.staticFlux, 0.0) << "the Cornell box exported no light";
    EXPECT_NE(base.output.find("detp over"), std::string::npos) << base.output;

    // --full-recompute: every photon re-shot and every vertex re-estimated each frame (no
    // incremental stage runs), from the same photons. The incremental ray set differs only in
    // the landings it kept while the block slid (within 1e-6 of the scene's size of a fresh
    // shot's), which can move a segment across a disc's rim only within that distance of it:
    // a handful of crossings among about 90k, each changing one vertex. So all but a few
    // vertices agree to float rounding.
    const ExportedLight full = exportLight("light_full", "--mode photon --full-recompute");
    ASSERT_EQ(full.ply.positions.size(), base.ply.positions.size());
    EXPECT_TRUE(full.ply.positions == base.ply.positions) << "the block moved differently";
    EXPECT_EQ(full.output.find("detp.irradiance/delta"), std::string::npos) << full.output;
    EXPECT_EQ(full.output.find("photon.update/find"), std::string::npos) << full.output;
    EXPECT_NE(base.output.find("detp.irradiance/delta"), std::string::npos) << base.output;
    std::size_t differing = 0;
    for (std::size_t v = 0; v < base.ply.irradiance.size(); ++v)
        for (int c = 0; c < 3; ++c) {
            const float a = base.ply.irradiance[v][c], b = full.ply.irradiance[v][c];
            if (std::abs(a - b) > std::ldexp(std::max(a, b), -20)) {
                ++differing;
                break;
            }
        }
    EXPECT_LE(differing, 20u);

    // Every frame: a frame earlier the block stood elsewhere and the light around it differed.
    // (That the light of a frame is that frame's, not the one before, is the order of the
    // systems in each frame: HeadlessCornellWritesEveryRequestedFile.)
    const ExportedLight earlier = exportLight("light_frame2", "--mode photon", 2);
    ASSERT_EQ(earlier.ply.positions.size(), base.ply.positions.size());
    std::size_t blockMoved = 0, staticChanged = 0;
    for (std::size_t v = 0; v < base.ply.positions.size(); ++v) {
        if (base.ply.mobile[v])
            blockMoved += earlier.ply.positions[v] != base.ply.positions[v] ? 1 : 0;
        else
            staticChanged += earlier.ply.irradiance[v] != base.ply.irradiance[v] ? 1 : 0;
    }
    EXPECT_EQ(blockMoved, mobileVertices) << "the block did not move between frames 2 and 3";
    EXPECT_GT(staticChanged, 100u) << "the light around the block did not change";

    // Another estimator or radius: a different estimate of the same light. Their totals may
    // differ by their biases at the box's edges and corners (a few per cent) and by noise
    // (about 0.5 % for 20k photons); the quarter allowed catches a wrong unit or a lost factor
    // (pi, 2, 3) while leaving room for those.
    for (const auto& [name, options, says] :
         {std::tuple{"light_impact", "--estimator impact", "impact over"},
          std::tuple{"light_photonmap", "--estimator photonmap", "photonmap over"},
          std::tuple{"light_radius", "--disc-radius 0.02", "disc radius 0.02 m"}}) {
        const ExportedLight other = exportLight(name, std::string("--mode photon ") + options);
        ASSERT_EQ(other.ply.positions.size(), base.ply.positions.size()) << options;
        EXPECT_NE(other.output.find(says), std::string::npos) << other.output;
        EXPECT_FALSE(other.ply.irradiance == base.ply.irradiance) << options;
        EXPECT_NEAR(other.staticFlux / base.staticFlux, 1.0, 0.25) << options;
    }

    // Hybrid mode: the point light's direct light is the shader's, so the photons bring only
    // what bounced; some, and less than all of it.
    const ExportedLight hybrid = exportLight("light_hybrid", "--mode hybrid");
    EXPECT_GT(hybrid.staticFlux, 0.0);
    EXPECT_LT(hybrid.staticFlux, 0.8 * base.staticFlux);
}

TEST(DemoSmoke, BadOptionsGiveOneLineErrorAndExitCode2) {
    for (const char* args :
         {"--frames -3", "--width 0", "--mode sideways", "--no-such-flag", "--photons abc",
          "--width 1280.5", "--seed -1", "--dt nan", "--exposure inf", "--vlf-lines 12",
          "--context sideways", "--photons 0x10", "--photons 1e1000", "--export-scene out.txt",
          "--screenshot ''", "--point-cache-file ''", "--disc-radius 1e-400"}) {
        const RunResult run = runDemo(std::string(args) + " --headless");
        EXPECT_EQ(run.exitCode, 2) << args << ": " << run.output;
        // One line, naming the option.
        const std::string option = std::string(args).substr(0, std::string(args).find(' '));
        EXPECT_TRUE(run.output.starts_with("qgi-demo: error: ")) << args << ": " << run.output;
        EXPECT_EQ(std::count(run.output.begin(), run.output.end(), '\n'), 1) << run.output;
        EXPECT_NE(run.output.find(option), std::string::npos) << args << ": " << run.output;
    }
    // An overflowing number is called too large, not "not a whole number".
    EXPECT_NE(runDemo("--photons 1e1000 --headless").output.find("'1e1000' is too large"),
              std::string::npos);
    // A number too small for a float would read as 0, the scene's default: refused.
    EXPECT_NE(runDemo("--exposure 1e-46 --headless").output.find("'1e-46' is too small"),
              std::string::npos);
    // A value out of range is told the range as the help writes it.
    EXPECT_NE(runDemo("--disc-radius 500 --headless")
                  .output.find("--disc-radius: 500 is not in the range 0 to 100 (see --help)"),
              std::string::npos);
}

TEST(DemoSmoke, AFileWithNothingToLightIsNamed) {
    // Lines only (skipped with a warning), and one triangle with no area.
    const fs::path dir = scratchDir();
    const fs::path flat = dir / "zero_area.gltf";
    std::ofstream(flat) << R"({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}], "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [2, 0, 0]}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36, "uri":
            "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAQAAAAAAAAAAA"}]})";
    for (const fs::path& scene :
         {fs::path(QGI_TEST_DATA_DIR) / "gltf" / "unusual" / "lines_only.gltf", flat}) {
        const RunResult run =
            runDemo("--headless --frames 1 --width 16 --height 16 --scene " + scene.string());
        EXPECT_EQ(run.exitCode, 1) << run.output;
        EXPECT_NE(run.output.find(scene.string() + "' has no triangles to light"),
                  std::string::npos)
            << run.output;
    }
}

TEST(DemoSmoke, WholeNumbersMayBeWrittenInScientificForm) {
    // "--photons 1e6" is a million; the run then stops at a missing scene file (exit 1: the
    // command line was accepted, where a bad option exits 2). An option given twice takes its
    // last value.
    const std::string missing = " --headless --scene " + (scratchDir() / "none.gltf").string();
    EXPECT_EQ(runDemo("--photons 1e6 --frames 1e1" + missing).exitCode, 1);
    EXPECT_EQ(runDemo("--frames 2 --frames 3" + missing).exitCode, 1);
    EXPECT_EQ(runDemo("--photons 1e6.5" + missing).exitCode, 2); // the check can fail
    // --help wins over the rest of the line, a bad value included.
    EXPECT_EQ(runDemo("--help --photons -1").exitCode, 0);
    // Leading zeros are decimal (CLI11 alone would read 010 as octal 8): ten frames profiled.
    const std::string base = (scratchDir() / "ten").string();
    ASSERT_EQ(runDemo("--scene cornell --headless --frames 010 --width 16 --height 16 "
                      "--photons 0 --vlf off --profile " +
                      base)
                  .exitCode,
              0);
    std::ifstream csv(base + ".csv");
    std::size_t lines = 0;
    for (std::string line; std::getline(csv, line);)
        ++lines;
    EXPECT_EQ(lines, 11u); // a header and ten frames
}

TEST(DemoSmoke, OutputThatCannotBeWrittenFailsBeforeTheRun) {
    // A file where a folder should be: the folder cannot be created.
    const fs::path blocker = scratchDir() / "blocker";
    std::ofstream(blocker) << "x";
    const std::string inside = (blocker / "out" / "shot").string();
    for (const char* option : {"--screenshot ", "--profile ", "--export-irradiance "}) {
        const RunResult run = runDemo("--scene cornell --headless --frames 1 --photons 1000 " +
                                      std::string(option) + inside);
        EXPECT_EQ(run.exitCode, 1) << option << run.output;
        EXPECT_NE(run.output.find("cannot create the folder"), std::string::npos) << run.output;
        EXPECT_EQ(run.output.find("ready in"), std::string::npos) << "the scene was loaded first";
    }
}

TEST(DemoSmoke, AScreenshotOverAFolderIsRefusedBeforeTheRun) {
    // shot.png is a folder: refused with the other checks at start, not after the last frame
    // (when a long run would have been spent for it).
    const fs::path dir = scratchDir() / "shot_folder";
    fs::remove_all(dir);
    fs::create_directories(dir / "shot.png");
    const RunResult run =
        runDemo("--scene cornell --headless --frames 2 --width 32 --height 32 "
                "--photons 1000 --screenshot " +
                (dir / "shot").string() + " --export-irradiance " + (dir / "light.ply").string());
    EXPECT_EQ(run.exitCode, 1) << run.output;
    EXPECT_NE(run.output.find("--screenshot: '" + (dir / "shot.png").string() +
                              "' is a folder; not written"),
              std::string::npos)
        << run.output;
    EXPECT_EQ(run.output.find("ready in"), std::string::npos) << "the scene was loaded first";
    EXPECT_FALSE(fs::exists(dir / "shot.exr"));
}

TEST(DemoSmoke, OutputsNamedWithoutAFolderGoToTheWorkingFolder) {
    const fs::path dir = scratchDir() / "bare_names";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const RunResult run = runDemo("--scene cornell --headless --frames 1 --width 16 --height 16 "
                                  "--photons 1000 --vlf off --screenshot shot --profile prof "
                                  "--export-irradiance light.ply --export-avatars avatars.csv",
                                  {}, dir);
    ASSERT_EQ(run.exitCode, 0) << run.output;
    for (const char* file :
         {"shot.png", "shot.exr", "prof.json", "prof.csv", "light.ply", "avatars.csv"})
        EXPECT_GT(fs::file_size(dir / file), 0u) << file;
}

TEST(DemoSmoke, OutputPathsThatNameNoFileAreRefused) {
    // An empty path is a command-line error (2), a folder a problem with the output (1).
    for (const auto& [args, code] :
         {std::pair{"--screenshot ''", 2}, std::pair{"--profile /tmp/", 1},
          std::pair{"--export-irradiance /tmp", 1}, std::pair{"--export-avatars /tmp", 1}}) {
        const RunResult run = runDemo(std::string("--headless --frames 1 ") + args);
        EXPECT_EQ(run.exitCode, code) << args << ": " << run.output;
        EXPECT_EQ(run.output.find("ready in"), std::string::npos) << args;
    }
    // A name longer than the file system allows: the option is named, before the load.
    const std::string tooLong = (scratchDir() / std::string(300, 'c')).string();
    for (const auto& [option, extension] :
         {std::pair{"--export-irradiance", ".ply"}, std::pair{"--screenshot", ""},
          std::pair{"--export-scene", ".glb"}}) {
        const RunResult run =
            runDemo("--headless --frames 1 " + std::string(option) + " " + tooLong + extension);
        EXPECT_EQ(run.exitCode, 1) << option << run.output;
        EXPECT_EQ(run.output.rfind(std::string("qgi-demo: error: ") + option + ":", 0), 0u)
            << run.output;
        EXPECT_NE(run.output.find("File name too long"), std::string::npos) << run.output;
        EXPECT_EQ(run.output.find("ready in"), std::string::npos) << option;
    }
}

TEST(DemoSmoke, SomebodysFileIsNeverTakenForACache) {
    const fs::path notes = scratchDir() / "notes.txt";
    std::ofstream(notes) << "my notes";
    for (const char* option : {"--point-cache-file ", "--vlf-cache "}) {
        const RunResult run = runDemo("--scene cornell --headless --frames 1 --photons 1000 " +
                                      std::string(option) + notes.string());
        EXPECT_EQ(run.exitCode, 1) << option << run.output;
        EXPECT_NE(run.output.find("not overwritten"), std::string::npos) << run.output;
    }
    std::ifstream in(notes);
    std::string text;
    std::getline(in, text);
    EXPECT_EQ(text, "my notes");
}

TEST(DemoSmoke, OutputsNeverOverwriteTheSceneOrSomebodysFile) {
    const fs::path dir = scratchDir() / "own_files";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path scene = dir / "level.gltf";
    const fs::path good = fs::path(QGI_TEST_DATA_DIR) / "gltf" / "good";
    fs::copy_file(good / "triangle.gltf", scene);
    fs::copy_file(good / "triangle.bin", dir / "triangle.bin");
    const auto size = fs::file_size(scene);
    for (const char* option : {"--export-irradiance ", "--export-scene ", "--export-avatars "}) {
        const RunResult run = runDemo("--headless --frames 1 --photons 1000 --scene " +
                                      scene.string() + " " + option + scene.string());
        EXPECT_EQ(run.exitCode, 1) << option << run.output;
        EXPECT_NE(run.output.find("is an input of this run"), std::string::npos) << run.output;
    }
    EXPECT_EQ(fs::file_size(scene), size);
    // Nor the camera path, nor another output's file, nor a FIFO (which would block).
    const fs::path path = dir / "path.csv";
    std::ofstream(path) << "0,0,0.3,1,0,0\n";
    const fs::path fifo = dir / "pipe.png";
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    fs::create_symlink("light.ply", dir / "link.ply");
    for (const auto& [options, says] :
         {std::pair{"--camera-path " + path.string() + " --export-avatars " + path.string(),
                    std::string("is an input of this run")},
          std::pair{"--profile " + (dir / "run").string() + " --export-avatars " +
                        (dir / "run.csv").string(),
                    std::string("is written by --profile too")},
          std::pair{"--screenshot " + (dir / "pipe").string(),
                    std::string("is not a regular file")},
          // A dangling link to another output's file names that file.
          std::pair{"--export-irradiance " + (dir / "light.ply").string() + " --export-avatars " +
                        (dir / "link.ply").string(),
                    std::string("is written by --export-irradiance too")},
          // A cache file is an output too.
          std::pair{"--vlf on --vlf-cache " + (dir / "field.ply").string() +
                        " --export-irradiance " + (dir / "field.ply").string(),
                    std::string("is written by --export-irradiance too")}}) {
        const RunResult run =
            runDemo("--scene cornell --headless --frames 1 --photons 1000 " + options);
        EXPECT_EQ(run.exitCode, 1) << options << run.output;
        EXPECT_NE(run.output.find(says), std::string::npos) << run.output;
    }

    // --export-irradiance rewrites an earlier export, never another kind of file.
    const fs::path notes = dir / "notes.ply";
    std::ofstream(notes) << "my notes";
    const RunResult run = runDemo("--scene cornell --headless --frames 1 --photons 1000 "
                                  "--export-irradiance " +
                                  notes.string());
    EXPECT_EQ(run.exitCode, 1) << run.output;
    EXPECT_NE(run.output.find("is not an irradiance export"), std::string::npos) << run.output;
    EXPECT_EQ(fs::file_size(notes), 8u);
    // An empty file made for it (mktemp) is taken.
    const fs::path empty = dir / "empty.ply";
    std::ofstream(empty).flush();
    EXPECT_EQ(runDemo("--scene cornell --headless --frames 1 --photons 1000 --vlf off "
                      "--export-irradiance " +
                      empty.string())
                  .exitCode,
              0);
    EXPECT_TRUE(isIrradiancePly(empty));

    // So does --export-avatars, which then rewrites its own export.
    const fs::path sheet = dir / "budget.csv";
    std::ofstream(sheet) << "item,cost\n";
    const std::string avatars = "--scene cornell --headless --frames 1 --photons 1000 --vlf off "
                                "--export-avatars ";
    const RunResult refused = runDemo(avatars + sheet.string());
    EXPECT_EQ(refused.exitCode, 1) << refused.output;
    EXPECT_NE(refused.output.find("is not an avatar SH export"), std::string::npos)
        << refused.output;
    EXPECT_EQ(fs::file_size(sheet), 10u);
    const fs::path own = dir / "avatars.csv";
    ASSERT_EQ(runDemo(avatars + own.string()).exitCode, 0);
    EXPECT_TRUE(isAvatarShCsv(own));
    EXPECT_EQ(runDemo(avatars + own.string()).exitCode, 0) << "an earlier export is replaced";
}

TEST(DemoSmoke, AScreenshotNamedAfterItsImageWritesThatImage) {
    const fs::path dir = scratchDir() / "named_shot";
    fs::remove_all(dir);
    const RunResult run =
        runDemo("--scene cornell --headless --frames 1 --width 16 --height 16 --photons 0 "
                "--vlf off --screenshot " +
                (dir / "shot.png").string() + " --profile " + (dir / "run.json").string());
    ASSERT_EQ(run.exitCode, 0) << run.output;
    EXPECT_EQ(readPng(dir / "shot.png").width, 16);
    EXPECT_TRUE(fs::exists(dir / "shot.exr"));
    EXPECT_TRUE(fs::exists(dir / "run.json"));
    EXPECT_TRUE(fs::exists(dir / "run.csv"));
    EXPECT_FALSE(fs::exists(dir / "shot.png.png"));
}

// SIGTERM (or Ctrl-C's SIGINT, which a background job such as this one starts ignoring) on a
// long headless run stops it after the frame in progress and still writes what the frames run
// produced; then the process ends by the signal (the shell reports 143).
TEST(DemoSmoke, AnInterruptedRunStillWritesItsOutputs) {
    const fs::path dir = scratchDir() / "interrupted";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path log = dir / "log.txt";
    const std::string demo = std::string(QGI_DEMO_PATH) +
                             " --scene cornell --headless --frames 100000 --width 16 --height 16 "
                             "--photons 1000 --vlf off --profile " +
                             (dir / "run").string() + " --export-irradiance " +
                             (dir / "light.ply").string();
    // Started in the background; interrupted once its frames have begun.
    const std::string script = demo + " > " + log.string() + " 2>&1 & pid=$!; " +
                               "for i in $(seq 600); do grep -q 'ready in' " + log.string() +
                               " && break; sleep 0.1; done; sleep 0.5; kill -TERM $pid; wait $pid";
    const fs::path file = dir / "interrupt.sh";
    std::ofstream(file) << script << "\n";
    const int status = std::system(("timeout 120 sh " + file.string()).c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 143);
    std::ifstream in(log);
    const std::string output((std::istreambuf_iterator<char>(in)), {});
    EXPECT_NE(output.find("stopped after"), std::string::npos) << output;
    EXPECT_FALSE(readPly(dir / "light.ply").positions.empty());
    std::ifstream csv(dir / "run.csv");
    std::size_t rows = 0;
    for (std::string line; std::getline(csv, line);)
        ++rows;
    EXPECT_GT(rows, 1u);
    EXPECT_LT(rows, 100000u);
}

TEST(DemoSmoke, CameraPathsAreReadStrictly) {
    const fs::path dir = scratchDir() / "camera_paths";
    fs::create_directories(dir);
    const auto run = [&](const std::string& name, const std::string& text) {
        std::ofstream(dir / name) << text;
        return runDemo("--scene cornell --headless --frames 2 --width 16 --height 16 --photons 0 "
                       "--vlf off --quiet --camera-path " +
                       (dir / name).string() + " --screenshot " + (dir / name).string());
    };
    EXPECT_EQ(run("good.csv", "time,x,y,z,yaw_deg,pitch_deg\n0,0,0.3,1,0,0\n1,0.1,0.3,1,10,-5\n")
                  .exitCode,
              0);
    // The camera follows it: turned 40 degrees, or on the scene's own camera (none), it sees
    // another picture.
    EXPECT_EQ(run("turned.csv", "0,0,0.3,1,40,0\n1,0.1,0.3,1,50,-5\n").exitCode, 0);
    ASSERT_EQ(runDemo("--scene cornell --headless --frames 2 --width 16 --height 16 --photons 0 "
                      "--vlf off --quiet --camera-path none --screenshot " +
                      (dir / "scene").string())
                  .exitCode,
              0);
    const ImageF good = readExr((dir / "good.csv.exr").string()),
                 turned = readExr((dir / "turned.csv.exr").string()),
                 scene = readExr((dir / "scene.exr").string());
    EXPECT_FALSE(good.rgba == turned.rgba);
    EXPECT_FALSE(good.rgba == scene.rgba);
    for (const auto& [name, text, says] :
         {std::tuple{"garbage.csv", "hello world\n0,0,0.3,1,0,0\n", "expected six numbers"},
          std::tuple{"seven.csv", "0,0,0.3,1,0,0,7\n", "expected six numbers"},
          std::tuple{"pitch.csv", "0,0,0.3,1,0,95\n", "past straight up or down"},
          std::tuple{"backwards.csv", "1,0,0.3,1,0,0\n0,0,0.3,1,0,0\n", "times must increase"},
          std::tuple{"word.csv", "0,0,0.3,1,0,0\n1,0,up,1,0,0\n",
                     "word.csv:2: y 'up' is not a number"},
          std::tuple{"huge.csv", "0,0,0.3,1,0,1e39\n",
                     "pitch_deg '1e39' is out of a 32-bit float's range"},
          std::tuple{"far.csv", "0,0,1e30,1,0,0\n", "y 1e+30 m is farther from the origin"}}) {
        const RunResult result = run(name, text);
        EXPECT_EQ(result.exitCode, 1) << name << ": " << result.output;
        EXPECT_NE(result.output.find(says), std::string::npos) << name << ": " << result.output;
    }
    // As a spreadsheet saves it: a byte-order mark, a header, Windows line ends.
    const RunResult excel = run("excel.csv", "\xEF\xBB\xBFtime,x,y,z,yaw_deg,pitch_deg\r\n"
                                             "0,0,0.3,1,0,0\r\n+1,0.1,0.3,1,10,-5\r\n");
    ASSERT_EQ(excel.exitCode, 0) << excel.output;
    EXPECT_TRUE(readExr((dir / "excel.csv.exr").string()).rgba == good.rgba)
        << "not good.csv's path";
    const RunResult folder = runDemo("--scene cornell --headless --frames 1 --photons 0 --vlf off "
                                     "--camera-path " +
                                     dir.string());
    EXPECT_EQ(folder.exitCode, 1) << folder.output;
    EXPECT_NE(folder.output.find("is not a file"), std::string::npos) << folder.output;
}

TEST(DemoSmoke, SceneWithoutCameraGetsADefaultOne) {
    const fs::path triangle = fs::path(QGI_TEST_DATA_DIR) / "gltf" / "good" / "triangle.gltf";
    const std::string base = (scratchDir() / "triangle").string();
    const RunResult run = runDemo("--headless --frames 2 --width 64 --height 48 --photons 1000 "
                                  "--vlf off --scene " +
                                  triangle.string() + " --screenshot " + base);
    ASSERT_EQ(run.exitCode, 0) << run.output;
    EXPECT_NE(run.output.find("no camera"), std::string::npos) << run.output;
    EXPECT_EQ(readPng(base + ".png").width, 64);
    // A flat level (a lit floor, y = 0) is seen from above, not edge-on (a black frame): the
    // floor fills a band a few rows above and below the middle, where an edge-on view has
    // nothing.
    const fs::path floor =
        fs::path(QGI_TEST_DATA_DIR) / "gltf" / "unusual" / "flat_floor_no_camera.gltf";
    const std::string floorBase = (scratchDir() / "flat_floor").string();
    const RunResult flat = runDemo("--headless --frames 2 --width 64 --height 48 --photons 1000 "
                                   "--vlf off --scene " +
                                   floor.string() + " --screenshot " + floorBase);
    ASSERT_EQ(flat.exitCode, 0) << flat.output;
    const ImageF image = readExr(floorBase + ".exr");
    for (const int row : {image.height / 2 - 2, image.height / 2 + 2}) {
        const std::size_t pixel = (std::size_t(row) * image.width + image.width / 2) * 4;
        EXPECT_GT(image.rgba[pixel], 0.f) << "the floor is not in view at row " << row;
    }
}

TEST(DemoSmoke, MissingSceneFileIsNamedInTheError) {
    const RunResult run = runDemo("--headless --frames 1 --scene /nonexistent/level.gltf");
    EXPECT_EQ(run.exitCode, 1) << run.output;
    EXPECT_NE(run.output.find("/nonexistent/level.gltf"), std::string::npos) << run.output;
}

// --context egl needs no window system: with the display variables unset it still renders
// (headless, implied) and writes its outputs, and so does a plain headless run, which picks
// EGL itself there. The image equals the window's where both reach the same driver
// (GlPlatform.EglPbufferDrawsTheWindowsFrame).
TEST(DemoSmoke, EglContextRendersWithoutADisplay) {
    const fs::path dir = scratchDir();
    for (const char* context : {"--context egl", "--headless"}) {
        const std::string base = (dir / "egl").string();
        fs::remove(base + ".png");
        const RunResult run = runDemo(std::string(context) +
                                          " --scene cornell --frames 2 --width 64 --height 48 "
                                          "--photons 1000 --screenshot " +
                                          base,
                                      {"DISPLAY", "WAYLAND_DISPLAY"});
        ASSERT_EQ(run.exitCode, 0) << context << ": " << run.output;
        EXPECT_NE(run.output.find("(EGL)"), std::string::npos) << context << ": " << run.output;
        const Image8 png = readPng(base + ".png");
        EXPECT_EQ(png.width, 64);
        EXPECT_EQ(png.height, 48);
        EXPECT_TRUE(
            std::any_of(png.rgba.begin(), png.rgba.end(), [](std::uint8_t v) { return v > 0; }))
            << context << ": a black frame";
    }
}

TEST(DemoSmoke, TheOverlayDrawsInTheWindowButNeverInScreenshots) {
    const fs::path dir = scratchDir();
    const std::string a = (dir / "overlay_on").string(), b = (dir / "overlay_off").string();
    const std::string common =
        "--scene cornell --headless --frames 3 --width 96 --height 64 --photons 2000 --quiet ";
    const RunResult on = runDemo(common + "--overlay on --gl-debug --screenshot " + a);
    ASSERT_EQ(on.exitCode, 0) << on.output;
    EXPECT_EQ(on.output.find("--overlay on:"), std::string::npos) << "not drawn: " << on.output;
    EXPECT_EQ(on.output.find("error: GL "), std::string::npos) << on.output;
    EXPECT_EQ(on.output.find("warning: GL "), std::string::npos) << on.output;
    ASSERT_EQ(runDemo(common + "--overlay off --screenshot " + b).exitCode, 0);
    EXPECT_TRUE(readExr(a + ".exr").rgba == readExr(b + ".exr").rgba);
    EXPECT_TRUE(readPng(a + ".png").rgba == readPng(b + ".png").rgba);
}

TEST(DemoSmoke, SameSeedSameImage) {
    const fs::path dir = scratchDir();
    const std::string a = (dir / "det_a").string(), b = (dir / "det_b").string();
    const std::string common = "--scene cornell --headless --frames 3 --width 64 --height 48 --seed 7 --quiet ";
    ASSERT_EQ(runDemo(common + "--screenshot " + a).exitCode, 0);
    ASSERT_EQ(runDemo(common + "--screenshot " + b).exitCode, 0);
    const ImageF ia = readExr(a + ".exr"), ib = readExr(b + ".exr");
    ASSERT_EQ(ia.rgba.size(), ib.rgba.size());
    EXPECT_TRUE(ia.rgba == ib.rgba) << "two runs with the same seed rendered different images";
}

TEST(DemoSmoke, ThePointCacheIsBakedOnceThenLoadedAndShadesTheTaggedFloor) {
    // A floor tagged for the point cache under a blocker and an emissive panel (hybrid mode).
    const fs::path dir = scratchDir() / "point_cache";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path scene = fs::path(QGI_TEST_DATA_DIR) / "gltf" / "good" / "point_cache_room.gltf";
    const std::string common = "--scene " + scene.string() +
                               " --headless --frames 2 --photons 20000 --width 64 --height 64 ";
    const auto shot = [&](const std::string& name, const std::string& options) {
        const RunResult run =
            runDemo(common + options + " --screenshot " + (dir / name).string(), {}, dir);
        EXPECT_EQ(run.exitCode, 0) << options << run.output;
        return std::pair{run.output, readExr((dir / name).string() + ".exr")};
    };
    // First start: baked, and written beside the run as <scene>.pcache.
    const auto [baked, first] = shot("first", "--point-cache");
    EXPECT_NE(baked.find(" darts ("), std::string::npos) << baked; // the bake's summary
    EXPECT_TRUE(fs::exists(dir / "point_cache_room.pcache"));
    // Next start: loaded, and the same image.
    const auto [loaded, again] = shot("again", "--point-cache");
    EXPECT_NE(loaded.find("point cache: loaded"), std::string::npos) << loaded;
    EXPECT_EQ(loaded.find(" darts ("), std::string::npos) << loaded;
    EXPECT_TRUE(first.rgba == again.rgba) << "the loaded cache shades differently";
    // --point-cache-file none bakes again and writes nothing.
    fs::remove(dir / "point_cache_room.pcache");
    const auto [none, unused] = shot("none", "--point-cache --point-cache-file none");
    EXPECT_NE(none.find(" darts ("), std::string::npos) << none;
    EXPECT_FALSE(fs::exists(dir / "point_cache_room.pcache"));
    // The cache is what shades the floor: without it, and with the points drawn, the image
    // differs.
    const auto [plain, withoutCache] = shot("plain", "");
    EXPECT_EQ(plain.find("point cache"), std::string::npos) << plain;
    EXPECT_FALSE(first.rgba == withoutCache.rgba);
    const auto [dots, points] = shot("points", "--show-points");
    EXPECT_FALSE(first.rgba == points.rgba);
}

TEST(DemoSmoke, AVlfTooLargeForTheMachineOrTheGpuIsRefusedBeforeItsBakeInTheDemosOptions) {
    // Level 4 at 1024 lines on the glossy Cornell box: millions of tiles, an atlas beyond
    // any GL limit and tens of GB. Refused from the layout, before a bake of many minutes,
    // in the options the user typed.
    const RunResult run = runDemo("--scene cornell-glossy --headless --frames 1 --photons 0 "
                                  "--quiet --vlf on --vlf-cache none --vlf-level 4 "
                                  "--vlf-lines 1024");
    EXPECT_EQ(run.exitCode, 1) << run.output;
    EXPECT_TRUE(run.output.starts_with("qgi-demo: error: --vlf-level 4 --vlf-lines 1024: the VLF "
                                       "of this scene needs "))
        << run.output;
    EXPECT_NE(run.output.find("; lower --vlf-level or --vlf-lines"), std::string::npos)
        << run.output;
    EXPECT_EQ(run.output.find("VlfSettings"), std::string::npos) << run.output;
    EXPECT_EQ(std::count(run.output.begin(), run.output.end(), '\n'), 1) << run.output;
}

TEST(DemoSmoke, TheVlfIsBakedCachedAndDrawsTheGlossyCornellBox) {
    const fs::path dir = scratchDir() / "vlf";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string common = "--scene cornell-glossy --headless --frames 2 --width 48 "
                               "--height 48 --photons 2000 --vlf-level 2 --vlf-lines 16 ";
    const auto shot = [&](const std::string& name, const std::string& options) {
        const RunResult run = runDemo(common + options + " --screenshot " + (dir / name).string());
        EXPECT_EQ(run.exitCode, 0) << options << run.output;
        return std::pair{run.output, readExr((dir / name).string() + ".exr")};
    };
    const std::string cache = " --vlf-cache " + (dir / "glossy.vlf").string();
    // auto: the scene's glossy floor and mirror block turn it on.
    const auto [baked, first] = shot("baked", "--vlf auto" + cache);
    EXPECT_NE(baked.find("VLF: baked 12 faces"), std::string::npos) << baked;
    EXPECT_NE(baked.find("VLF: saved"), std::string::npos) << baked;
    const auto [loaded, again] = shot("loaded", "--vlf auto" + cache);
    EXPECT_NE(loaded.find("VLF: loaded"), std::string::npos) << loaded;
    EXPECT_EQ(loaded.find("VLF: baked"), std::string::npos) << loaded;
    EXPECT_TRUE(first.rgba == again.rgba) << "the loaded field draws differently";
    // Off: no field, and the reflections are gone from the image.
    const auto [off, plain] = shot("off", "--vlf off");
    EXPECT_EQ(off.find("VLF"), std::string::npos) << off;
    EXPECT_FALSE(first.rgba == plain.rgba);
}

} // namespace
} // namespace qgi
