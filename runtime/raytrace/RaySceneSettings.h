#pragma once

#include <embree3/rtcore.h>

#include <string>

namespace qgi {

/// How the RayScene builds its Embree scenes. The defaults were chosen by measurement on the
/// built-in scenes (tests/bench/bench_raytrace, incoherent rays, one core).
struct RaySceneSettings {
    /// BVH quality of the static world and of each mobile's object-space scene, built once at
    /// load (moves only rebuild the small top level). Measured on the built-in scenes, HIGH
    /// (spatial splits) traces no faster than MEDIUM and, with robust off, builds 3x slower.
    RTCBuildQuality buildQuality = RTC_BUILD_QUALITY_MEDIUM;
    /// Embree's robust mode: watertight triangle tests. Without it, rays aimed at the edges and
    /// corners of a closed room slip between triangles (about 1% of edge rays, 7% of corner
    /// rays), which lets photons leak out of rooms. Costs 20-25% of incoherent throughput.
    bool robust = true;
    /// Embree device configuration string ("threads=2", "verbose=1", ...); "" for defaults.
    std::string deviceConfig;
};

} // namespace qgi
