#include "runtime/ecs/Schedule.h"

#include "runtime/core/Error.h"
#include "runtime/profile/FrameProfiler.h"

#include <algorithm>

namespace qgi {

Schedule& Schedule::addPhase(std::string_view phase) {
    if (std::find(mPhases.begin(), mPhases.end(), phase) != mPhases.end())
        fail("schedule: duplicate phase '", phase, "'");
    mPhases.emplace_back(phase);
    mEntries.emplace_back();
    return *this;
}

Schedule& Schedule::add(std::string_view phase, std::string_view name, Function function) {
    const auto it = std::find(mPhases.begin(), mPhases.end(), phase);
    if (it == mPhases.end()) fail("schedule: unknown phase '", phase, "' for entry '", name, "'");
    const auto index = std::size_t(it - mPhases.begin());
    std::string fullName = name == phase ? std::string(phase) : str(phase, '.', name);
    for (const auto& entries : mEntries)
        for (const Entry& e : entries)
            if (e.name == fullName) fail("schedule: duplicate entry '", fullName, "'");
    if (!function) fail("schedule: entry '", fullName, "' has no function");
    mEntries[index].push_back(Entry{std::move(fullName), index, std::move(function), true});
    return *this;
}

bool Schedule::setEnabled(std::string_view fullName, bool enabled) {
    for (auto& entries : mEntries)
        for (Entry& e : entries)
            if (e.name == fullName) {
                e.enabled = enabled;
                return true;
            }
    return false;
}

std::vector<const Schedule::Entry*> Schedule::entries() const {
    std::vector<const Entry*> out;
    for (const auto& entries : mEntries)
        for (const Entry& e : entries) out.push_back(&e);
    return out;
}

void Schedule::run(Registry& registry, const FrameContext& frame) {
    FrameProfiler* profiler = registry.ctx().find<FrameProfiler>();
    if (profiler) profiler->beginFrame(frame.frameIndex);
    try {
        for (auto& entries : mEntries) {
            for (Entry& e : entries) {
                if (!e.enabled) continue;
                FrameProfiler::Scope scope(profiler, e.name);
                e.function(registry, frame);
            }
        }
    } catch (...) {
        // The frame ends with the error, and the schedule stays usable: the next run begins a
        // frame of its own. The changes stay marked, so the systems that did not run see them
        // next frame.
        if (profiler) profiler->endFrame();
        throw;
    }
    // What a frame changed has been seen by every system of that frame.
    registry.clearChanges();
    if (profiler) profiler->endFrame();
}

} // namespace qgi
