#pragma once
// Minimal levelled logging to stderr. Thread safe (one line is written atomically).

#include "runtime/core/Error.h"

namespace qgi {

enum class LogLevel { Debug, Info, Warning, Error, Quiet };

void setLogLevel(LogLevel level);
LogLevel logLevel();
void logMessage(LogLevel level, const std::string& message);

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
