#pragma once

#include "systems/vlf/Vlf.h"

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace qgi::vlf {

struct VlfBakeStats;

/** The VLF cache file: a versioned binary image of a baked Vlf, keyed by vlfKey(scene,
 *  settings). Layout (little endian, as written by this machine):
 *    8 bytes magic "QGIVLF\r\n", u32 format version, u64 key, u64 payload size,
 *    u64 FNV-1a hash of the payload, payload (settings, frame, faces, maps, tiles).
 *  load() rejects, with a qgi::Error naming the file and the reason, a file that is missing,
 *  truncated, of another version, of another key, settings or faces than the scene's (stale:
 *  the scene or settings changed), whose payload hash or internal sizes do not match, or that
 *  holds values a lookup could not use (corrupt). The hash proves the bytes are as written,
 *  not that this scene's bake wrote them: the faces, which lookups and the renderer index by
 *  the scene's own face numbers, are compared with the scene's.                          */
class VlfCache {
public:
    /// 2: texel coverage is exact (clipped triangle area), no longer 4 x 4 samples.
    /// 3: the cells are packed (half floats and a scale, packCells), no longer RGBA floats.
    static constexpr std::uint32_t kVersion = 3;
    /// The first bytes of every VLF cache file.
    static constexpr std::string_view kMagic{"QGIVLF\r\n", 8};

    /// Writes atomically (a temporary file renamed over the target). Throws qgi::Error when
    /// the file cannot be written, or when something other than a VLF cache is at `path`.
    static void save(const Vlf& vlf, const std::filesystem::path& path);
    /// Reads a file written by save() for `scene` baked with `settings`. Throws qgi::Error as
    /// described.
    static Vlf load(const std::filesystem::path& path, const VlfScene& scene,
                    const VlfSettings& settings);

    /// Loads `path` when it holds this scene and settings; otherwise (missing, stale or
    /// corrupt: the reason is logged as a warning) bakes and saves. `baked` tells which
    /// happened. An empty path bakes without a cache.
    static Vlf loadOrBake(const VlfScene& scene, const VlfSettings& settings,
                          const std::filesystem::path& path, bool* baked = nullptr,
                          VlfBakeStats* stats = nullptr);
};

} // namespace qgi::vlf
