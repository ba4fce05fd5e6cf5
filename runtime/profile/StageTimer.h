#pragma once

#include "runtime/profile/FrameProfiler.h"

#include <chrono>
#include <string_view>

namespace qgi {

/// Times one stage of a system's update: on destruction adds the stage's wall-clock
/// milliseconds to `ms` (the system's frame statistics, read by benchmarks and tests) and,
/// when a profiler is given, closes a nested profiler scope of that name, so the demo's
/// profile shows the stage under its schedule entry ("photon.update/trace").
class StageTimer {
public:
    StageTimer(FrameProfiler* profiler, std::string_view name, double& ms)
        : mScope(profiler, name), mMs(ms), mStart(std::chrono::steady_clock::now()) {}
    ~StageTimer() {
        mMs += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - mStart)
                   .count();
    }
    StageTimer(const StageTimer&) = delete;
    StageTimer& operator=(const StageTimer&) = delete;

private:
    FrameProfiler::Scope mScope;
    double& mMs;
    std::chrono::steady_clock::time_point mStart;
};

} // namespace qgi
