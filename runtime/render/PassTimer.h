#pragma once

#include "runtime/render/GlHandle.h"

#include <array>
#include <cstdint>
#include <string_view>
#include <vector>

namespace qgi {

class FrameProfiler;

/** Times render passes into the FrameProfiler world resource as samples named by the caller
 *  ("render/scene"). Two ways, chosen at construction:
 *  - GPU: a GL_TIME_ELAPSED query per pass, kept in a ring of kFramesInFlight frames and read
 *    at a later beginFrame once the GPU has finished it, never waiting (Track::Gpu). A frame
 *    still unfinished when its ring slot comes round again loses its samples.
 *  - CPU: glFinish before and after the pass, wall time in between (Track::Cpu). This costs the
 *    CPU/GPU overlap, but it is the only meaningful timing on llvmpipe, whose timer queries
 *    report times unrelated to the work (DEPENDENCY-FACTS.md).
 *  Without a profiler nothing is timed and nothing waits.                                  */
class PassTimer {
public:
    static constexpr std::size_t kFramesInFlight = 4;

    explicit PassTimer(bool cpuTimed) : mCpuTimed(cpuTimed) {}

    bool cpuTimed() const { return mCpuTimed; }

    /// Records the GPU results that have arrived, then starts timing frame `frameIndex`.
    void beginFrame(FrameProfiler* profiler, std::uint64_t frameIndex);

    /// `name` must outlive the timer (a string literal). Passes do not nest.
    void beginPass(std::string_view name);
    void endPass();

    /// Times one pass for the lifetime of the scope.
    class Scope {
    public:
        Scope(PassTimer& timer, std::string_view name) : mTimer(timer) { timer.beginPass(name); }
        ~Scope() { mTimer.endPass(); }
        Scope(const Scope&) = delete;
        Scope& operator=(const Scope&) = delete;

    private:
        PassTimer& mTimer;
    };

private:
    struct PendingPass {
        std::string_view name;
        GlQuery query;
    };
    struct FrameQueries {
        std::uint64_t frameIndex = 0;
        std::vector<PendingPass> passes; ///< grows to the most passes seen, then is reused
        std::size_t used = 0;            ///< passes issued this time round
    };

    void collect(FrameQueries& frame);

    bool mCpuTimed;
    FrameProfiler* mProfiler = nullptr;
    std::uint64_t mFrameIndex = 0;
    std::array<FrameQueries, kFramesInFlight> mRing;
    std::string_view mPassName;
    double mPassStartMs = 0.0;
};

} // namespace qgi
