#pragma once

#include <filesystem>
#include <string_view>

namespace qgi {

/// `path` with every symbolic link along the final component followed (a dangling link gives
/// the file it would create), made absolute and normal: the file a write to `path` changes.
std::filesystem::path writeTarget(const std::filesystem::path& path);

/// Writes `bytes` as the whole of the file `path` so that a failure loses nothing: into a
/// temporary file beside it, which replaces the file only once written, flushed and closed
/// without error (a full disk is caught there, not left as a cut-off file). Writing through a
/// symbolic link replaces the file it points to. Throws qgi::Error naming `what` and the path;
/// the temporary file is removed and an earlier file of that name is untouched.
void writeFileAtomically(const std::filesystem::path& path, std::string_view bytes,
                         std::string_view what);

} // namespace qgi
