#include "runtime/io/AtomicFile.h"

#include "runtime/core/Error.h"

#include <cerrno>
#include <cstring>
#include <random>
#include <string>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace qgi {
namespace {

/// Most symbolic links followed before giving up (the kernel's own limit for a path).
constexpr int kMaxLinkHops = 40;

} // namespace

std::filesystem::path writeTarget(const std::filesystem::path& path) {
    namespace fs = std::filesystem;
    std::error_code error;
    // From the working folder: a bare name ("shot.png") then has a folder, the working one.
    fs::path target = fs::absolute(path, error);
    if (error) target = path;
    for (int hops = 0; hops < kMaxLinkHops && fs::is_symlink(fs::symlink_status(target, error));
         ++hops) {
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
    const auto failWith = [&](const std::string& why) {
        fail("cannot write ", what, " '", path.string(), "': ", why);
    };
    const fs::path target = writeTarget(path);
    std::error_code error;
    if (fs::is_symlink(fs::symlink_status(target, error)))
        failWith("too many levels of symbolic links");
    // The file keeps its permissions when it is replaced; a new one gets rw-r--r--.
    struct stat existing {};
    const mode_t mode = ::stat(target.c_str(), &existing) == 0 ? existing.st_mode & 07777 : 0644;

    // A temporary file of a name nobody can guess, created anew (never an existing file or a
    // link planted under that name), in the target's folder so that the rename is atomic.
    std::random_device entropy;
    fs::path temp;
    int fd = -1;
    for (int attempt = 0; attempt < 16 && fd < 0; ++attempt) {
        std::string name = ".";
        name += target.filename().string();
        name += ".qgi-tmp-";
        name += std::to_string(::getpid());
        name += '-';
        name += std::to_string(entropy());
        temp = target.parent_path() / name;
        fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
        if (fd < 0 && errno != EEXIST) failWith(std::strerror(errno));
    }
    if (fd < 0) failWith("no free temporary file name beside it");
    const auto failAndRemove = [&](int code) {
        ::close(fd);
        ::unlink(temp.c_str());
        failWith(std::strerror(code));
    };
    for (std::size_t done = 0; done < bytes.size();) {
        const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) failAndRemove(n < 0 ? errno : EIO);
        done += std::size_t(n);
    }
    // On the disk before it replaces the file: some file systems report a full disk or quota
    // only here, and a crash after the rename must not leave an empty file.
    if (::fchmod(fd, mode) != 0 || ::fsync(fd) != 0) failAndRemove(errno);
    if (::close(fd) != 0) {
        const int code = errno;
        ::unlink(temp.c_str());
        failWith(std::strerror(code));
    }
    if (::rename(temp.c_str(), target.c_str()) != 0) {
        const int code = errno;
        ::unlink(temp.c_str());
        failWith(std::strerror(code));
    }
}

} // namespace qgi
