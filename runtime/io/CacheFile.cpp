#include "runtime/io/CacheFile.h"

#include "runtime/core/Error.h"

#include <fstream>
#include <string>

namespace qgi {

bool mayReplaceWithCache(const std::filesystem::path& path, std::string_view magic) {
    std::error_code error;
    if (!std::filesystem::exists(path, error) && !error) return true;
    if (!std::filesystem::is_regular_file(path, error)) return false;
    std::ifstream in(path, std::ios::binary);
    std::string head(magic.size(), '\0');
    in.read(head.data(), std::streamsize(head.size()));
    // An empty file holds nothing to lose.
    if (in.gcount() == 0 && std::filesystem::file_size(path, error) == 0 && !error) return true;
    return in.gcount() == std::streamsize(magic.size()) && head == magic;
}

void checkCacheTarget(const std::filesystem::path& path, std::string_view magic,
                      std::string_view what) {
    if (!mayReplaceWithCache(path, magic))
        fail(path.string(), " exists and is not a ", what, "; not overwritten");
}

} // namespace qgi
