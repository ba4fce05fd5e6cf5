#pragma once

#include <filesystem>
#include <string_view>

namespace qgi {

/// Whether a cache file of the kind that starts with `magic` may be written at `path`: nothing
/// is there yet, or what is there starts with the same magic (an older or stale cache of that
/// kind). Anything else is somebody's file and must not be replaced by a cache.
bool mayReplaceWithCache(const std::filesystem::path& path, std::string_view magic);

/// Throws qgi::Error ("PATH exists and is not a WHAT; not overwritten") unless
/// mayReplaceWithCache(path, magic).
void checkCacheTarget(const std::filesystem::path& path, std::string_view magic,
                      std::string_view what);

} // namespace qgi
