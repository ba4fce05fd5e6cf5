#include "demo/DemoOptions.h"

#include "runtime/core/Log.h"
#include "runtime/scene/BuiltinScenes.h"
#include "systems/photon_update/PhotonSettings.h"

#include <CLI/CLI.hpp>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

namespace qgi::demo {

namespace {

std::string builtinList() {
    std::string list;
    for (const auto& name : builtinSceneNames()) list += (list.empty() ? "" : ", ") + name;
    return list;
}

/// For integer options: digits, or a whole number written any way strtod reads ("1e6" for a
/// million). Anything else is "not a whole number" rather than CLI11's "not in range".
CLI::Validator wholeNumber() {
    return CLI::Validator(
        [](std::string& value) -> std::string {
            const bool digits =
                !value.empty() &&
                value.find_first_not_of("0123456789", value[0] == '-') == std::string::npos &&
                value != "-";
            if (digits) { // decimal, unless it overflows 64 bits (CLI11 reads 010 as octal)
                errno = 0;
                (void)std::strtoull(value.c_str() + (value[0] == '-'), nullptr, 10);
                if (errno == ERANGE) return "'" + value + "' is too large";
                const std::size_t sign = value[0] == '-' ? 1 : 0;
                const std::size_t first = value.find_first_not_of('0', sign);
                value.erase(sign, (first == std::string::npos ? value.size() - 1 : first) - sign);
                return {};
            }
            // strtod also reads hexadecimal ("0x10"), which the help does not offer.
            if (value.find_first_of("xX") != std::string::npos)
                return "'" + value + "' is not a whole number (write it in decimal)";
            char* end = nullptr;
            errno = 0;
            const double v = std::strtod(value.c_str(), &end);
            const bool whole = !value.empty() && end == value.c_str() + value.size();
            if (whole && std::isinf(v) && errno == ERANGE) return "'" + value + "' is too large";
            if (!whole || !std::isfinite(v) || v != std::floor(v))
                return "'" + value + "' is not a whole number";
            if (!(std::abs(v) < 9e15)) return "'" + value + "' is too large";
            value = std::to_string(static_cast<long long>(v)); // exact below 2^53
            return {};
        },
        "");
}

/// For real options: a finite number (CLI11's range check lets NaN through).
CLI::Validator finiteNumber() {
    return CLI::Validator(
        [](std::string& value) -> std::string {
            char* end = nullptr;
            errno = 0;
            const double v = std::strtod(value.c_str(), &end);
            if (value.empty() || end != value.c_str() + value.size() || !std::isfinite(v))
                return "'" + value + "' is not a finite number";
            // 1e-400 would read as 0, which means the scene's default to most options.
            if (errno == ERANGE || (v != 0.0 && float(v) == 0.f))
                return "'" + value + "' is too small to hold (not 0)";
            return {};
        },
        "");
}

/// CLI::Range with its bounds written as the help writes them (CLI11's own message gives
/// floats six decimals: "0.000000 to 100.000000"). Runs after wholeNumber or finiteNumber.
template <typename T> CLI::Validator within(T min, T max) {
    std::ostringstream bounds;
    bounds << min << " to " << max;
    std::ostringstream help;
    help << "in [" << min << " - " << max << "]";
    return CLI::Validator(
        [min, max, bounds = bounds.str()](std::string& value) -> std::string {
            char* end = nullptr;
            const double v = std::strtod(value.c_str(), &end);
            if (value.empty() || end != value.c_str() + value.size())
                return "'" + value + "' is not a number";
            if (!(v >= double(min) && v <= double(max)))
                return value + " is not in the range " + bounds;
            return {};
        },
        help.str());
}

/// For options that name a file: an empty name is a mistake on the command line.
CLI::Validator nonEmptyPath() {
    return CLI::Validator(
        [](std::string& value) { return value.empty() ? "the path is empty" : std::string{}; }, "");
}

/// --export-scene: the format comes from the extension, so it must be one qgi writes.
CLI::Validator gltfExtension() {
    return CLI::Validator(
        [](std::string& value) {
            std::string extension = std::filesystem::path(value).extension().string();
            for (char& c : extension)
                c = char(std::tolower(static_cast<unsigned char>(c)));
            return extension == ".gltf" || extension == ".glb"
                       ? std::string{}
                       : "'" + value + "' does not end in .gltf or .glb";
        },
        "");
}

} // namespace

ParseResult parseDemoOptions(int argc, char** argv) {
    ParseResult result;
    DemoOptions& o = result.options;
    CLI::App app{"qgi-demo: walkthrough of a quasi-static scene lit by the qgi runtime.\n"
                 "Interactive: WASD + right mouse drag to fly, Q/E down/up, Shift faster,\n"
                 "Tab selects the next mobile, arrow keys and PageUp/PageDown move it,\n"
                 "H takes it out of the world and puts it back, L switches the lamps off and on,\n"
                 "C hands the camera back to the scripted path, P toggles the point-set view,\n"
                 "F12 takes a screenshot, Esc quits.",
                 "qgi-demo"};
    app.option_defaults()->always_capture_default();
    // An option given twice takes its last value, as in most tools (and wrapper scripts that
    // append to defaults).
    app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
    app.add_option("--scene", o.scene,
                   "Built-in scene (" + builtinList() + ") or a .gltf/.glb file")
        ->check(nonEmptyPath());
    app.add_flag("--headless", o.headless,
                 "Render offscreen (hidden window), follow the scripted camera path with a fixed time step");
    app.add_option("--context", o.context,
                   "Where the OpenGL context comes from: window (a GLFW window; headless runs "
                   "need an X server such as Xvfb), egl (an offscreen pbuffer on the first GPU "
                   "through EGL, for machines without X; implies --headless), or auto (egl for "
                   "a headless run without a display, else window)")
        ->check(CLI::IsMember({"auto", "window", "egl"}));
    app.add_flag("--gl-debug", o.glDebug,
                 "OpenGL debug context: the driver's errors and warnings go to the log (on in "
                 "debug builds)");
    app.add_option("--frames", o.frames,
                   "Frames to run; 0 runs until the window closes (headless: 240)")
        ->transform(wholeNumber())
        ->check(within(0, 10'000'000));
    app.add_option("--width", o.width, "Framebuffer width in pixels")
        ->transform(wholeNumber())
        ->check(within(16, 8192));
    app.add_option("--height", o.height, "Framebuffer height in pixels")
        ->transform(wholeNumber())
        ->check(within(16, 8192));
    app.add_option("--camera-path", o.cameraPath,
                   "'scene' (the scene's own path), 'none' (stay at the start), or a CSV file with "
                   "rows time,x,y,z,yaw_deg,pitch_deg")
        ->check(nonEmptyPath());
    app.add_option("--mode", o.mode, "Lighting mode: photon (all light from photons) or hybrid "
                                     "(direct light from punctual lights in the shader)")
        ->check(CLI::IsMember({"photon", "hybrid"}));
    app.add_option("--photons", o.photons,
                   "Photon paths in the stored ray set (0: no global illumination); with their "
                   "path grid about 400 bytes each on the Cornell box, 170 on the atrium")
        ->transform(wholeNumber())
        ->check(within(0u, std::uint32_t(maxPhotonCount(PhotonSettings{}.maxBounces))));
    app.add_option("--estimator", o.estimator,
                   "Per-vertex irradiance estimator: detp (density estimation on the tangent "
                   "plane), impact (impact count) or photonmap (k-nearest photon map)")
        ->check(CLI::IsMember({"detp", "impact", "photonmap"}));
    app.add_option("--disc-radius", o.discRadius,
                   "DETP disc radius in metres (0: the scene default, half its mesh edge bound, "
                   "widened where photons are scarce for the scene's area)")
        ->transform(finiteNumber())
        ->check(within(0.f, 100.f));
    app.add_flag("--full-recompute", o.fullRecompute,
                 "Re-shoot every photon and re-estimate every vertex each frame (the baseline "
                 "the incremental update is measured against)");
    app.add_option("--exposure", o.exposure,
                   "Multiplier on HDR radiance before the tonemap (0: the scene's suggestion)")
        ->transform(finiteNumber())
        ->check(within(0.f, 1e6f));
    app.add_option("--max-edge", o.maxEdgeLength,
                   "Mesh refinement bound in metres (0: the scene's default)")
        ->transform(finiteNumber())
        ->check(within(0.f, 1000.f));
    app.add_option("--dt", o.dt, "Seconds per frame in headless runs")
        ->transform(finiteNumber())
        ->check(within(1e-4, 1.0));
    app.add_option("--seed", o.seed, "Seed for every random choice")
        ->transform(wholeNumber())
        ->check([](const std::string& value) {
            return value.starts_with('-') ? "a seed cannot be negative" : std::string{};
        });
    // A base path given with one of its files' extensions means the base: shot.png is shot.
    const auto baseOf = [](std::vector<std::string> extensions) {
        return CLI::Validator(
            [extensions = std::move(extensions)](std::string& value) {
                for (const std::string& extension : extensions)
                    if (value.size() > extension.size() && value.ends_with(extension)) {
                        value.resize(value.size() - extension.size());
                        break; // one extension: a.png.exr is the base a.png
                    }
                return std::string{};
            },
            "", "base path");
    };
    app.add_option("--screenshot", o.screenshot,
                   "Base path: writes BASE.exr (linear HDR) and BASE.png (tonemapped) after the "
                   "last frame (shot.png or shot.exr also name the base shot)")
        ->check(nonEmptyPath())
        ->transform(baseOf({".png", ".exr"}));
    app.add_option("--profile", o.profile,
                   "Base path: writes BASE.json (Chrome trace, opens in Perfetto) and BASE.csv "
                   "(per-frame, per-entry times)")
        ->check(nonEmptyPath())
        ->transform(baseOf({".json", ".csv"}));
    app.add_option("--export-scene", o.exportScene,
                   "Writes the loaded scene as glTF (.gltf or .glb) with qgi's conventions")
        ->check(nonEmptyPath())
        ->check(gltfExtension());
    app.add_option(
           "--export-irradiance", o.exportIrradiance,
           "Writes per-vertex irradiance after the last frame as binary little-endian PLY: "
           "x y z nx ny nz, "
           "er eg eb (W/m^2) and a mobile flag per vertex. In hybrid mode it leaves out "
           "the direct light the renderer draws (of point, spot and directional lights, "
           "and of emissive surfaces with a light stand-in); "
           "--mode photon exports all light. An existing file that is not an earlier export "
           "is not overwritten")
        ->check(nonEmptyPath());
    app.add_option("--vlf", o.vlf,
                   "Virtual Light Field for glossy and mirror surfaces: on, off, or auto (on when "
                   "the static scene has 1 to 256 glossy or mirror faces)")
        ->check(CLI::IsMember({"on", "off", "auto"}));
    app.add_option("--vlf-level", o.vlfLevel,
                   "VLF direction level: 2*4^L+1 directions (3: 129, 4: 513)")
        ->transform(wholeNumber())
        ->check(within(1, 6));
    app.add_option("--vlf-lines", o.vlfLines, "VLF lines per subfield side (a multiple of 8)")
        ->transform(wholeNumber())
        ->check(within(8, 1024))
        ->check([](const std::string& value) {
            return std::stoi(value) % 8 == 0 ? std::string{} : value + " is not a multiple of 8";
        });
    app.add_option(
           "--vlf-cache", o.vlfCache,
           "VLF cache file (auto: <scene>.vlf in the working folder; none: bake every start)")
        ->check(nonEmptyPath());
    app.add_option(
           "--export-avatars", o.exportAvatars,
           "Writes each avatar's SH lighting after the last frame as CSV: avatar,x,y,z, then "
           "the 27 radiance coefficients L00_r..L22_b (W/(m^2 sr), Ramamoorthi-Hanrahan "
           "real basis over world x, y, z). In hybrid mode, as the probes shade, it leaves "
           "out the direct light the renderer draws. An existing file that is not an earlier "
           "export is not overwritten")
        ->check(nonEmptyPath());
    app.add_flag("--quiet", o.quiet, "Only warnings and errors");
    app.add_option("--overlay", o.overlay,
                   "Frame-time overlay (F1 hides it): auto (in an interactive window), on (in a "
                   "headless window too; never in screenshots), off")
        ->check(CLI::IsMember({"auto", "on", "off"}));
    app.add_flag("--point-cache", o.pointCache,
                 "Build the point cache (soft shadows of area lights and indirect light per "
                 "fragment on the surfaces tagged for it; hybrid mode)");
    app.add_option("--point-cache-file", o.pointCacheFile,
                   "Point cache file (auto: <scene>.pcache in the working folder; none: bake "
                   "every start): loaded when it matches the scene and settings, else rebaked "
                   "and written. A file name implies --point-cache")
        ->check(nonEmptyPath());
    app.add_flag("--show-points", o.showPoints,
                 "Start with the point-set view on (key P toggles it; implies --point-cache)");

    // Help wins over the rest of the line: `--help --photons -1` asks for help, not an error.
    for (int i = 1; i < argc; ++i)
        if (std::string_view(argv[i]) == "--help" || std::string_view(argv[i]) == "-h") {
            result.exitCode = app.exit(CLI::CallForHelp());
            return result;
        }
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        result.exitCode = app.exit(e);
        return result;
    } catch (const CLI::ParseError& e) {
        std::cerr << "qgi-demo: error: " << printable(e.what()) << " (see --help)\n";
        result.exitCode = 2;
        return result;
    }
    if (o.context == "egl") o.headless = true;
    if (o.headless && o.frames == 0) o.frames = 240;
    return result;
}

} // namespace qgi::demo
