#pragma once

#include <cstdint>

namespace qgi {

/// Everything a system may know about "now". Passed explicitly to every schedule entry; no
/// system reads a clock or a global random state.
struct FrameContext {
    std::uint64_t frameIndex = 0; ///< 0 for the first frame
    double time = 0.0;            ///< seconds of simulated time at the start of this frame
    float dt = 0.f;               ///< seconds since the previous frame (0 on the first)
    std::uint64_t seed = 0;       ///< run seed: every random choice derives from it
};

} // namespace qgi
