#pragma once
// Minimal levelled logging to stderr. Thread safe (one line is written atomically).

#include "runtime/core/Error.h"

#include <cstddef>
#include <string>
#include <string_view>

namespace qgi {

enum class LogLevel { Debug, Info, Warning, Error, Quiet };

void setLogLevel(LogLevel level);
LogLevel logLevel();
void logMessage(LogLevel level, const std::string& message);

/// Sets the log level for a scope and puts the previous one back when it ends (also when an
/// exception or a failed test assertion leaves the scope early).
class ScopedLogLevel {
public:
    explicit ScopedLogLevel(LogLevel level) : mPrevious(logLevel()) { setLogLevel(level); }
    ~ScopedLogLevel() { setLogLevel(mPrevious); }
    ScopedLogLevel(const ScopedLogLevel&) = delete;
    ScopedLogLevel& operator=(const ScopedLogLevel&) = delete;

private:
    LogLevel mPrevious;
};

/// `text` safe to print on a terminal: control characters (escape sequences in a hostile
/// file's names, a stray carriage return) become \xNN, so a message cannot move the cursor,
/// retitle the window or forge another line. logMessage applies it to every message.
std::string printable(std::string_view text);
/// printable() of at most the first `maxLength` bytes, with "..." when cut: for quoting a
/// file's text in a message. The cut comes before the escaping, so it never splits an escape.
std::string printableExcerpt(std::string_view text, std::size_t maxLength);

template <typename... Args> void logDebug(Args&&... args) {
    if (logLevel() <= LogLevel::Debug) logMessage(LogLevel::Debug, str(std::forward<Args>(args)...));
}
template <typename... Args> void logInfo(Args&&... args) {
    if (logLevel() <= LogLevel::Info) logMessage(LogLevel::Info, str(std::forward<Args>(args)...));
}
template <typename... Args> void logWarning(Args&&... args) {
    if (logLevel() <= LogLevel::Warning)
        logMessage(LogLevel::Warning, str(std::forward<Args>(args)...));
}
template <typename... Args> void logError(Args&&... args) {
    if (logLevel() <= LogLevel::Error) logMessage(LogLevel::Error, str(std::forward<Args>(args)...));
}

} // namespace qgi
