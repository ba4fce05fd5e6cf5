#pragma once
// Three levels of failure (docs/ARCHITECTURE.md, "Errors"):
//  - QGI_ASSERT: a programmer bug; aborts with file and line in every build type.
//  - qgi::Error: bad input found at load or set-up time (missing file, malformed glTF, absurd
//    option). Thrown, caught at the top (demo main, test), printed as one line.
//  - std::optional / bool returns where failure is an expected outcome (a ray that misses).
// The per-frame path never throws.

#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace qgi {

/// Bad input detected at load or set-up time. `what()` is a complete one-line message that
/// names the file and the offending field where there is one.
class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// Concatenates anything that streams into one string: `str("bad accessor ", i, " in ", path)`.
template <typename... Args>
std::string str(Args&&... args) {
    std::ostringstream out;
    (out << ... << std::forward<Args>(args));
    return out.str();
}

/// Throws qgi::Error with the concatenated message.
template <typename... Args>
[[noreturn]] void fail(Args&&... args) {
    throw Error(str(std::forward<Args>(args)...));
}

[[noreturn]] void assertFailed(const char* expression, const char* file, int line,
                               const std::string& message);

} // namespace qgi

#define QGI_ASSERT(cond, ...)                                                                      \
    do {                                                                                           \
        if (!(cond)) [[unlikely]]                                                                  \
            ::qgi::assertFailed(#cond, __FILE__, __LINE__, ::qgi::str("" __VA_OPT__(, ) __VA_ARGS__)); \
    } while (false)
