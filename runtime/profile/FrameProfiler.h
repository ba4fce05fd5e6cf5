#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace qgi {

/// Summary of one named entry over all recorded frames, milliseconds.
struct ProfileStats {
    std::string name;
    std::size_t count = 0; ///< frames in which the entry ran
    double mean = 0, p50 = 0, p95 = 0, p99 = 0, max = 0;
};

/** World resource that records named, timed scopes per frame.
 *  The Schedule times every entry automatically (CPU track). Render passes add GPU samples
 *  read back from timer queries a few frames later with recordSample(..., Track::Gpu).
 *  Outputs: Chrome trace-event JSON (Perfetto, chrome://tracing), a CSV with one row per frame
 *  and one column per entry, and a summary table (mean, p50, p95, p99, max).
 *  Single-threaded: call from the thread that runs the schedule.                           */
class FrameProfiler {
public:
    enum class Track : std::uint8_t { Cpu = 0, Gpu = 1 };
    using Clock = std::chrono::steady_clock;

    FrameProfiler();

    void beginFrame(std::uint64_t frameIndex);
    void endFrame();
    std::uint64_t currentFrame() const { return mFrame; }

    /// Nested CPU scopes; the name of a nested scope is recorded as "outer/inner".
    void beginScope(std::string_view name);
    void endScope();

    /// RAII CPU scope.
    class Scope {
    public:
        Scope(FrameProfiler* profiler, std::string_view name) : mProfiler(profiler) {
            if (mProfiler) mProfiler->beginScope(name);
        }
        ~Scope() {
            if (mProfiler) mProfiler->endScope();
        }
        Scope(const Scope&) = delete;
        Scope& operator=(const Scope&) = delete;

    private:
        FrameProfiler* mProfiler;
    };

    /// Adds a sample measured elsewhere (a GPU timer query, a CPU time around glFinish) to frame
    /// `frameIndex`, which may be an earlier frame. startMs is relative to the profiler's epoch;
    /// pass a negative start to place it at the end of that frame's CPU samples.
    void recordSample(std::string_view name, std::uint64_t frameIndex, double startMs,
                      double durationMs, Track track);

    /// Milliseconds since the profiler was created.
    double nowMs() const;

    // ---- results -----------------------------------------------------------------------------
    std::vector<ProfileStats> statistics() const; ///< in order of first appearance
    std::string summaryTable() const;             ///< fixed-width text table
    std::size_t frameCount() const { return mFrames.size(); }
    /// Duration of `name` in a recorded frame (ms), or a negative value if it did not run.
    double sampleMs(std::size_t frameSlot, std::string_view name) const;
    /// Every entry that ran in a recorded frame with its total duration there (ms), in the
    /// order each first ran; empty for a slot not recorded. Cheap: for a live display.
    std::vector<std::pair<std::string_view, double>> frameSamples(std::size_t frameSlot) const;
    /// Wall time of a recorded frame (ms), or a negative value.
    double frameMs(std::size_t frameSlot) const;

    void writeChromeTrace(const std::filesystem::path& path) const; ///< throws qgi::Error
    void writeCsv(const std::filesystem::path& path) const;         ///< throws qgi::Error

private:
    struct Sample {
        std::uint32_t entry; ///< index into mNames
        Track track;
        double startMs;
        double durationMs;
    };
    struct Frame {
        std::uint64_t index = 0;
        double startMs = 0, endMs = 0;
        std::vector<Sample> samples;
    };
    std::uint32_t intern(std::string_view name);
    Frame* findFrame(std::uint64_t frameIndex);

    Clock::time_point mEpoch;
    std::vector<std::string> mNames;
    std::unordered_map<std::string, std::uint32_t> mIds;
    std::vector<Frame> mFrames;
    std::vector<std::pair<std::string, double>> mOpen; ///< open CPU scopes: full name, start
    std::uint64_t mFrame = 0;
    bool mInFrame = false;
};

} // namespace qgi
