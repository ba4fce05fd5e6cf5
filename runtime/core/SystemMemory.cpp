#include "runtime/core/SystemMemory.h"

#include <algorithm>
#include <fstream>
#include <new>
#include <sstream>
#include <string>

namespace qgi {
namespace {

/// The value of `key` (in kB) in /proc/meminfo, in bytes.
std::optional<std::size_t> meminfoBytes(const std::string& key) {
    std::ifstream in("/proc/meminfo");
    std::string name;
    std::size_t kilobytes = 0;
    std::string unit;
    while (in >> name >> kilobytes) {
        std::getline(in, unit);
        if (name == key + ":") return kilobytes * 1024;
    }
    return std::nullopt;
}

/// The process's cgroup v2 folder ("0::/path" in /proc/self/cgroup), or nothing.
std::optional<std::string> cgroupV2Folder() {
    std::ifstream in("/proc/self/cgroup");
    std::string line;
    while (std::getline(in, line))
        if (line.starts_with("0::")) return "/sys/fs/cgroup" + line.substr(3);
    return std::nullopt;
}

/// What the cgroup v2 limit leaves: memory.max less the anonymous memory charged (memory.stat
/// "anon"); nothing without a limit.
std::optional<std::size_t> cgroupHeadroom() {
    const std::optional<std::string> folder = cgroupV2Folder();
    if (!folder) return std::nullopt;
    std::ifstream maxFile(*folder + "/memory.max");
    std::string max;
    if (!(maxFile >> max) || max == "max") return std::nullopt;
    std::size_t limit = 0;
    std::istringstream(max) >> limit;
    if (limit == 0) return std::nullopt;
    std::ifstream stat(*folder + "/memory.stat");
    std::string key;
    std::size_t value = 0, anon = 0;
    while (stat >> key >> value)
        if (key == "anon") anon = value;
    return limit > anon ? limit - anon : 0;
}

} // namespace

std::optional<std::size_t> availableMemoryBytes() {
    const std::optional<std::size_t> available = meminfoBytes("MemAvailable");
    if (!available) return std::nullopt;
    std::size_t bytes = *available + meminfoBytes("SwapFree").value_or(0);
    if (const std::optional<std::size_t> headroom = cgroupHeadroom())
        bytes = std::min(bytes, *headroom);
    return bytes;
}

void checkMemoryFor(std::size_t bytes, std::optional<std::size_t> available) {
    if (available && bytes > *available) throw std::bad_alloc();
}

} // namespace qgi
