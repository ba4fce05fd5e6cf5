#pragma once

#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"

#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace qgi {

/** The frame as an ordered list of named phases, each holding named entries.
 *  `run` executes phases in declaration order and, within a phase, entries in the order they
 *  were added: no hidden reordering, so the frame reads top to bottom where it is built.
 *  Every entry is timed by the registry's FrameProfiler resource when one is present, under
 *  the name "<phase>.<entry>" (or just the phase name when the entry has the same name).
 *  Change lists (`registry.changed<T>()`) are cleared at the end of `run`: a system sees what
 *  changed earlier in this frame and since the previous frame ended (loading, input).      */
class Schedule {
public:
    using Function = std::function<void(Registry&, const FrameContext&)>;

    struct Entry {
        std::string name;      ///< full name, "<phase>.<entry>"
        std::size_t phase = 0; ///< index into phases()
        Function function;
        bool enabled = true;
    };

    /// Appends a phase; phases run in the order they are added. Names must be unique.
    Schedule& addPhase(std::string_view phase);

    /// Appends an entry at the end of `phase`. Throws qgi::Error for an unknown phase or a
    /// duplicate entry name (a schedule is built at set-up time).
    Schedule& add(std::string_view phase, std::string_view name, Function function);

    /// Turns an entry on or off by full name; returns false if there is no such entry.
    bool setEnabled(std::string_view fullName, bool enabled);

    /// Runs every enabled entry in order, timed by the context's FrameProfiler when there is
    /// one, then clears the registry's changes. An exception from an entry ends the frame
    /// (its profile included) and propagates; the changes stay marked, and the next run is a
    /// frame like any other.
    void run(Registry& registry, const FrameContext& frame);

    const std::vector<std::string>& phases() const { return mPhases; }
    /// Entries in execution order.
    std::vector<const Entry*> entries() const;

private:
    std::vector<std::string> mPhases;
    std::vector<std::vector<Entry>> mEntries; ///< per phase, in insertion order
};

} // namespace qgi
