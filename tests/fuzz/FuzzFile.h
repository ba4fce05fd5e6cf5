#pragma once
/** Shared by the libFuzzer harnesses: each input is written to a file in a private folder
 *  under /dev/shm (the loaders read paths, as the demo does), and a loader may throw only
 *  qgi::Error, whose message must be one line. Anything else escapes and libFuzzer reports it. */

#include "runtime/core/Error.h"

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

namespace qgi::fuzz {

/// A folder of this process's own, removed at exit.
inline const std::filesystem::path& folder() {
    static const std::filesystem::path path = [] {
        const std::filesystem::path base = std::filesystem::exists("/dev/shm")
                                               ? std::filesystem::path("/dev/shm")
                                               : std::filesystem::temp_directory_path();
        std::filesystem::path made = base / ("qgi-fuzz-" + std::to_string(::getpid()));
        std::filesystem::create_directories(made);
        std::atexit([] { std::filesystem::remove_all(folder()); });
        return made;
    }();
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
