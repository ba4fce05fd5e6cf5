#include "runtime/profile/FrameProfiler.h"

#include "runtime/core/Error.h"
#include "runtime/io/AtomicFile.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <sstream>

namespace qgi {

namespace {

// Nearest-rank percentile of sorted values, p in [0, 100].
double percentile(const std::vector<double>& sorted, double p) {
    if (sorted.empty()) return 0.0;
    const double rank = std::ceil(p / 100.0 * double(sorted.size()));
    const std::size_t index = std::size_t(std::clamp(rank, 1.0, double(sorted.size()))) - 1;
    return sorted[index];
}

void writeJsonString(std::ostream& out, std::string_view s) {
    out << '"';
    for (const char c : s) {
        switch (c) {
        case '"': out << "\\\""; break;
        case '\\': out << "\\\\"; break;
        case '\n': out << "\\n"; break;
        case '\t': out << "\\t"; break;
        default:
            if (static_cast<unsigned char>(c) < 0x20) {
                char buffer[8];
                std::snprintf(buffer, sizeof buffer, "\\u%04x", static_cast<unsigned>(c));
                out << buffer;
            } else {
                out << c;
            }
        }
    }
    out << '"';
}

} // namespace

FrameProfiler::FrameProfiler() : mEpoch(Clock::now()) {}

double FrameProfiler::nowMs() const {
    return std::chrono::duration<double, std::milli>(Clock::now() - mEpoch).count();
}

std::uint32_t FrameProfiler::intern(std::string_view name) {
    const auto it = mIds.find(std::string(name));
    if (it != mIds.end()) return it->second;
    const auto id = std::uint32_t(mNames.size());
    mNames.emplace_back(name);
    mIds.emplace(mNames.back(), id);
    return id;
}

FrameProfiler::Frame* FrameProfiler::findFrame(std::uint64_t frameIndex) {
    // Samples arrive for the current frame or a few frames back: search from the end.
    for (auto it = mFrames.rbegin(); it != mFrames.rend(); ++it)
        if (it->index == frameIndex) return &*it;
    return nullptr;
}

void FrameProfiler::beginFrame(std::uint64_t frameIndex) {
    QGI_ASSERT(!mInFrame, "beginFrame without endFrame");
    mInFrame = true;
    mFrame = frameIndex;
    Frame& frame = mFrames.emplace_back();
    frame.index = frameIndex;
    frame.startMs = nowMs();
}

void FrameProfiler::endFrame() {
    QGI_ASSERT(mInFrame, "endFrame without beginFrame");
    QGI_ASSERT(mOpen.empty(), "endFrame with open scope ", mOpen.back().first);
    mFrames.back().endMs = nowMs();
    mInFrame = false;
}

void FrameProfiler::beginScope(std::string_view name) {
    std::string full = mOpen.empty() ? std::string(name) : mOpen.back().first + "/" + std::string(name);
    mOpen.emplace_back(std::move(full), nowMs());
}

void FrameProfiler::endScope() {
    QGI_ASSERT(!mOpen.empty(), "endScope without beginScope");
    const double end = nowMs();
    auto [name, start] = std::move(mOpen.back());
    mOpen.pop_back();
    if (!mInFrame) return; // scopes outside a frame (loading) are not part of frame statistics
    mFrames.back().samples.push_back(Sample{intern(name), Track::Cpu, start, end - start});
}

void FrameProfiler::recordSample(std::string_view name, std::uint64_t frameIndex, double startMs,
                                 double durationMs, Track track) {
    Frame* frame = findFrame(frameIndex);
    if (!frame) return; // the frame was never recorded (profiling started later)
    if (startMs < 0) {
        startMs = frame->startMs;
        for (const Sample& s : frame->samples)
            if (s.track == track) startMs = std::max(startMs, s.startMs + s.durationMs);
    }
    frame->samples.push_back(Sample{intern(name), track, startMs, durationMs});
}

double FrameProfiler::sampleMs(std::size_t frameSlot, std::string_view name) const {
    if (frameSlot >= mFrames.size()) return -1.0;
    const auto it = mIds.find(std::string(name));
    if (it == mIds.end()) return -1.0;
    double total = -1.0;
    for (const Sample& s : mFrames[frameSlot].samples)
        if (s.entry == it->second) total = std::max(total, 0.0) + s.durationMs;
    return total;
}

std::vector<std::pair<std::string_view, double>>
FrameProfiler::frameSamples(std::size_t frameSlot) const {
    std::vector<std::pair<std::string_view, double>> out;
    if (frameSlot >= mFrames.size()) return out;
    std::vector<std::uint32_t> seen; // entry -> position in out, + 1
    for (const Sample& s : mFrames[frameSlot].samples) {
        if (s.entry >= seen.size()) seen.resize(s.entry + 1, 0);
        if (seen[s.entry] == 0) {
            out.emplace_back(mNames[s.entry], 0.0);
            seen[s.entry] = std::uint32_t(out.size());
        }
        out[seen[s.entry] - 1].second += s.durationMs;
    }
    return out;
}

double FrameProfiler::frameMs(std::size_t frameSlot) const {
    if (frameSlot >= mFrames.size()) return -1.0;
    const Frame& f = mFrames[frameSlot];
    return f.endMs >= f.startMs ? f.endMs - f.startMs : -1.0; // an open frame ends at 0
}

std::vector<ProfileStats> FrameProfiler::statistics() const {
    // Per entry, the total time it took in each frame it ran in (an entry may run twice).
    std::vector<std::vector<double>> perEntry(mNames.size() + 1);
    std::vector<double> frameTotals;
    for (const Frame& frame : mFrames) {
        std::vector<double> sums(mNames.size(), -1.0);
        for (const Sample& s : frame.samples) sums[s.entry] = std::max(sums[s.entry], 0.0) + s.durationMs;
        for (std::size_t i = 0; i < sums.size(); ++i)
            if (sums[i] >= 0) perEntry[i].push_back(sums[i]);
        if (frame.endMs > frame.startMs) frameTotals.push_back(frame.endMs - frame.startMs);
    }
    auto summarize = [](std::string name, std::vector<double> values) {
        ProfileStats stats;
        stats.name = std::move(name);
        stats.count = values.size();
        if (values.empty()) return stats;
        std::sort(values.begin(), values.end());
        double sum = 0;
        for (double v : values) sum += v;
        stats.mean = sum / double(values.size());
        stats.p50 = percentile(values, 50);
        stats.p95 = percentile(values, 95);
        stats.p99 = percentile(values, 99);
        stats.max = values.back();
        return stats;
    };
    std::vector<ProfileStats> out;
    out.push_back(summarize("frame", std::move(frameTotals)));
    for (std::size_t i = 0; i < mNames.size(); ++i) out.push_back(summarize(mNames[i], std::move(perEntry[i])));
    return out;
}

std::string FrameProfiler::summaryTable() const {
    const auto stats = statistics();
    std::size_t width = 5;
    for (const auto& s : stats) width = std::max(width, s.name.size());
    std::ostringstream out;
    out << std::left << std::setw(int(width)) << "entry" << std::right;
    for (const char* h : {"frames", "mean ms", "p50 ms", "p95 ms", "p99 ms", "max ms"}) out << std::setw(10) << h;
    out << '\n' << std::fixed << std::setprecision(3);
    for (const auto& s : stats) {
        out << std::left << std::setw(int(width)) << s.name << std::right << std::setw(10) << s.count
            << std::setw(10) << s.mean << std::setw(10) << s.p50 << std::setw(10) << s.p95
            << std::setw(10) << s.p99 << std::setw(10) << s.max << '\n';
    }
    return out.str();
}

void FrameProfiler::writeChromeTrace(const std::filesystem::path& path) const {
    std::ostringstream out;
    out << std::fixed << std::setprecision(3);
    out << "{\"displayTimeUnit\":\"ms\",\"traceEvents\":[\n";
    out << R"({"name":"thread_name","ph":"M","pid":1,"tid":1,"args":{"name":"CPU"}},)" << '\n';
    out << R"({"name":"thread_name","ph":"M","pid":1,"tid":2,"args":{"name":"GPU"}})";
    for (const Frame& frame : mFrames) {
        // Trace-event times are microseconds.
        out << ",\n{\"name\":\"frame " << frame.index << "\",\"cat\":\"frame\",\"ph\":\"X\",\"pid\":1,\"tid\":1"
            << ",\"ts\":" << frame.startMs * 1000.0 << ",\"dur\":" << std::max(0.0, frame.endMs - frame.startMs) * 1000.0
            << "}";
        for (const Sample& s : frame.samples) {
            out << ",\n{\"name\":";
            writeJsonString(out, mNames[s.entry]);
            out << ",\"cat\":\"" << (s.track == Track::Gpu ? "gpu" : "cpu") << "\",\"ph\":\"X\",\"pid\":1,\"tid\":"
                << (s.track == Track::Gpu ? 2 : 1) << ",\"ts\":" << s.startMs * 1000.0
                << ",\"dur\":" << s.durationMs * 1000.0 << ",\"args\":{\"frame\":" << frame.index << "}}";
        }
    }
    out << "\n]}\n";
    writeFileAtomically(path, out.view(), "the profile trace");
}

void FrameProfiler::writeCsv(const std::filesystem::path& path) const {
    std::ostringstream out;
    out << "frame,frame_ms";
    for (const std::string& name : mNames) out << ',' << name << "_ms";
    out << '\n' << std::fixed << std::setprecision(4);
    for (const Frame& frame : mFrames) {
        std::vector<double> sums(mNames.size(), -1.0);
        for (const Sample& s : frame.samples) sums[s.entry] = std::max(sums[s.entry], 0.0) + s.durationMs;
        out << frame.index << ',' << (frame.endMs - frame.startMs);
        for (const double v : sums) {
            out << ',';
            if (v >= 0) out << v; // empty cell: the entry did not run in this frame
        }
        out << '\n';
    }
    writeFileAtomically(path, out.view(), "the profile CSV");
}

} // namespace qgi
