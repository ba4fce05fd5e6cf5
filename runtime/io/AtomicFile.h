#pragma once

#include <filesystem>
#include <string_view>

namespace qgi {

/// `path` with every symbolic link along the final component followed (a dangling link gives
/// the file it would create), made absolute and normal: the file a write to `path` changes.
std::filesystem::path writeTarget(const std::filesystem::path& path);

/// Writes `bytes` as the whole of the file `path` so that a failure loses nothing: into a new
/// temporary file beside it (a name nobody can guess, never an existing file or link), which
/// replaces the file only once written, synced to disk and closed without error (a full disk
/// is caught there, not left as a cut-off file). Writing through a symbolic link replaces the
/// file it points to. The file keeps its permissions; being replaced, it leaves its hard links
/// (they keep the old contents). Throws qgi::Error naming `what` and the path (a loop of links
/// too); the temporary file is removed and an earlier file of that name is untouched.
void writeFileAtomically(const std::filesystem::path& path, std::string_view bytes,
                         std::string_view what);

} // namespace qgi
