#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace qgi::demo {

/// Everything the command line sets. Defaults are what a first run should show.
struct DemoOptions {
    std::string scene = "atrium"; ///< built-in name or .gltf/.glb path
    bool headless = false;        ///< hidden window, scripted camera, fixed time step
    bool glDebug = false;         ///< GL debug context: the driver's messages go to the log
    /// "window" (GLFW), "egl" (pbuffer, no X; implies headless) or "auto" (egl when headless
    /// without a display, else window)
    std::string context = "auto";
    int frames = 0;               ///< frames to run; 0: until the window closes (headless: 240)
    int width = 1280;
    int height = 720;
    std::string cameraPath = "scene"; ///< "scene" (the scene's own path), "none", or a CSV file
    std::string mode = "hybrid";      ///< "photon" or "hybrid"
    std::uint32_t photons = 1'000'000; ///< photon paths in the stored ray set; 0: no photons
    std::string estimator = "detp";   ///< "detp", "impact" or "photonmap"
    float discRadius = 0.f;           ///< DETP disc radius in metres; 0: the scene's default
    bool fullRecompute = false;       ///< re-shoot and re-estimate everything every frame
    float exposure = 0.f;             ///< multiplier on HDR radiance; 0: the scene's suggestion
    float maxEdgeLength = 0.f;        ///< mesh refinement bound in metres; 0: scene default
    double dt = 1.0 / 30.0;           ///< seconds per frame in headless runs
    std::uint64_t seed = 1;
    std::optional<std::string> screenshot; ///< base path: writes .exr and .png after the last frame
    std::optional<std::string> profile;    ///< base path: writes .json (trace) and .csv
    std::optional<std::string> exportScene; ///< .gltf or .glb path, written after loading
    std::optional<std::string> exportIrradiance; ///< .ply path, written after the last frame
    std::string vlf = "auto"; ///< "on", "off", or "auto" (on with 1..256 glossy or mirror faces)
    int vlfLevel = 4;              ///< VLF directions: 2 * 4^level + 1 (4: 513)
    int vlfLines = 64;             ///< VLF lines per subfield side
    std::string vlfCache = "auto"; ///< VLF cache file; "auto": <scene>.vlf in the working folder, "none": no file
    std::optional<std::string> exportAvatars;    ///< .csv path: avatars' SH after the last frame
    bool quiet = false;
    bool pointCache = false;       ///< build (or load) the point cache; shade PointCacheShaded
    /// Its cache file; "auto": <scene>.pcache in the working folder, "none": build every start.
    std::string pointCacheFile = "auto";
    bool showPoints = false;       ///< start with the point-set view on (key P toggles it)
    /// The ImGui overlay: "auto" in an interactive window, "on" in a headless one too (drawn into
    /// the hidden window, never into screenshots), "off".
    std::string overlay = "auto";
};

/// Parses argv. Returns the options, or an exit code when the program should stop now
/// (`--help` gives 0, a bad option 2 with a one-line message on stderr).
struct ParseResult {
    DemoOptions options;
    std::optional<int> exitCode;
};
ParseResult parseDemoOptions(int argc, char** argv);

} // namespace qgi::demo
