#pragma once
/** Shared by the libFuzzer harnesses: each input is written to a file in a private folder
 *  under /dev/shm (the loaders read paths, as the demo does), and a loader may throw only
 *  qgi::Error, whose message must be one line. Anything else escapes and libFuzzer reports it. */

#include "runtime/core/Error.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

namespace qgi::fuzz {

/// A folder of this process's own, removed at exit. libFuzzer leaves some runs without exit
/// handlers (a crash, a timeout), so folders of processes that are gone are removed first.
inline const std::filesystem::path& folder() {
    // Never destroyed: the exit handler below runs after static destructors registered later.
    static const std::filesystem::path& path = *new std::filesystem::path([] {
        namespace fs = std::filesystem;
        const fs::path base =
            fs::exists("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
        constexpr std::string_view kPrefix = "qgi-fuzz-";
        std::error_code error;
        for (const auto& entry : fs::directory_iterator(base, error)) {
            const std::string name = entry.path().filename().string();
            if (!name.starts_with(kPrefix)) continue;
            const long pid = std::strtol(name.c_str() + kPrefix.size(), nullptr, 10);
            if (pid > 0 && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH)
                fs::remove_all(entry.path(), error);
        }
        fs::path made = base / (std::string(kPrefix) + std::to_string(::getpid()));
        fs::create_directories(made);
        std::atexit([] { std::filesystem::remove_all(folder()); });
        return made;
    }());
    return path;
}

/// Writes the input to `name` in the folder and returns its path.
inline std::filesystem::path writeInput(std::string_view name, const std::uint8_t* data,
                                        std::size_t size) {
    const std::filesystem::path path = folder() / name;
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
    return path;
}

/// A loader's error message must be one non-empty line without control characters.
inline void checkMessage(const Error& error) {
    const std::string_view what = error.what();
    bool printable = !what.empty();
    for (const char c : what)
        printable = printable && static_cast<unsigned char>(c) >= 0x20 && c != 0x7f;
    if (!printable) {
        std::fprintf(stderr, "qgi::Error message is not one printable line: '%s'\n", error.what());
        std::abort();
    }
}

} // namespace qgi::fuzz
