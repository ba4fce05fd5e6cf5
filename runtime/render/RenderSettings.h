#pragma once

namespace qgi {

/// Where the light on static and mobile meshes comes from (docs: "Who lights what").
enum class ShadingMode {
    Photon, ///< everything from per-vertex irradiance: albedo / pi * E + emission
    Hybrid, ///< per-vertex irradiance plus direct light of punctual lights with shadow maps
};

/// How render passes are timed for the profiler (see PassTimer).
enum class PassTiming {
    Auto, ///< CPU around glFinish on llvmpipe (its timer queries are meaningless), else GPU
    Gpu,  ///< timer queries, read back a few frames later, never stalling
    Cpu,  ///< wall time around glFinish
};

struct RenderSettings {
    int width = 1280; ///< pixels of the HDR and tonemapped targets
    int height = 720; ///< pixels
    ShadingMode mode = ShadingMode::Hybrid;
    /// Linear multiplier on radiance, W/(m^2 sr), before the tonemap. 1 maps a radiance of 1
    /// to the filmic curve's 0.80 (sRGB 0.91); each doubling is one photographic stop.
    float exposure = 1.f;
    int shadowMapSize = 1024; ///< texels per side of every shadow map (and cube face)
    PassTiming passTiming = PassTiming::Auto;
};

} // namespace qgi
