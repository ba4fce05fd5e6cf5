#include "runtime/io/AtomicFile.h"

#include "runtime/core/Error.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include <unistd.h>

namespace qgi {

std::filesystem::path writeTarget(const std::filesystem::path& path) {
    namespace fs = std::filesystem;
    std::error_code error;
    fs::path target = path;
    // A loop of links (or a very long chain) stops here; opening it then fails with its own
    // error.
    for (int hops = 0; hops < 40 && fs::is_symlink(fs::symlink_status(target, error)); ++hops) {
        const fs::path link = fs::read_symlink(target, error);
        if (error) break;
        target = link.is_absolute() ? link : target.parent_path() / link;
    }
    const fs::path resolved = fs::weakly_canonical(target, error);
    return error ? fs::absolute(target, error).lexically_normal() : resolved;
}

void writeFileAtomically(const std::filesystem::path& path, std::string_view bytes,
                         std::string_view what) {
    namespace fs = std::filesystem;
    const fs::path target = writeTarget(path);
    std::string name = ".";
    name += target.filename().string();
    name += ".qgi-tmp-";
    name += std::to_string(::getpid());
    const fs::path temp = target.parent_path() / name;
    const auto failed = [&](const std::string& why) {
        std::error_code ignored;
        fs::remove(temp, ignored);
        fail("cannot write ", what, " '", path.string(), "': ", why);
    };
    std::FILE* file = std::fopen(temp.c_str(), "wb");
    if (!file) failed(std::strerror(errno));
    const bool written = bytes.empty() || std::fwrite(bytes.data(), 1, bytes.size(), file) ==
                                               bytes.size();
    const int writeErrno = errno;
    // fclose flushes what the buffer holds: a full disk may show only there.
    const bool closed = std::fclose(file) == 0;
    if (!written) failed(std::strerror(writeErrno));
    if (!closed) failed(std::strerror(errno));
    std::error_code error;
    fs::rename(temp, target, error);
    if (error) failed(error.message());
}

} // namespace qgi
