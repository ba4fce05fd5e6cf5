#pragma once

#include <cstddef>
#include <optional>

namespace qgi {

/// Bytes this process may still take without the kernel having to reclaim them by force: the
/// machine's MemAvailable plus free swap (/proc/meminfo), capped, inside a cgroup v2 container
/// with a memory limit, by that limit less the container's anonymous memory (page cache does
/// not count: the kernel drops it first). Nothing where the figures cannot be read.
std::optional<std::size_t> availableMemoryBytes();

/// Throws std::bad_alloc when `bytes` exceeds `available`: an array the machine cannot hold is
/// refused when it is asked for, instead of being granted by overcommit and the process killed
/// once it is written. Nothing is checked without a figure.
void checkMemoryFor(std::size_t bytes, std::optional<std::size_t> available);

} // namespace qgi
