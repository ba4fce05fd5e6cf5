#include "runtime/core/Log.h"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <mutex>

namespace qgi {

namespace {
std::atomic<LogLevel> gLevel{LogLevel::Info}; // process-wide output filter, not engine state
std::mutex gWriteMutex;

const char* prefix(LogLevel level) {
    switch (level) {
    case LogLevel::Debug: return "qgi: debug: ";
    case LogLevel::Info: return "qgi: ";
    case LogLevel::Warning: return "qgi: warning: ";
    case LogLevel::Error: return "qgi: error: ";
    case LogLevel::Quiet: break;
    }
    return "qgi: ";
}
} // namespace

void setLogLevel(LogLevel level) { gLevel.store(level); }
LogLevel logLevel() { return gLevel.load(std::memory_order_relaxed); }

std::string printable(std::string_view text) {
    std::string out;
    out.reserve(text.size());
    static constexpr char kHex[] = "0123456789abcdef";
    const auto escape = [&](unsigned char byte) {
        out += "\\x";
        out += kHex[byte >> 4];
        out += kHex[byte & 15];
    };
    for (std::size_t i = 0; i < text.size(); ++i) {
        const auto byte = static_cast<unsigned char>(text[i]);
        const unsigned char next =
            i + 1 < text.size() ? static_cast<unsigned char>(text[i + 1]) : 0;
        if (byte < 0x20 || byte == 0x7f) {
            escape(byte);
        } else if (byte == 0xc2 && next >= 0x80 && next <= 0x9f) { // C1 controls in UTF-8
            escape(byte);
            escape(next);
            ++i;
        } else {
            out += text[i];
        }
    }
    return out;
}

std::string printableExcerpt(std::string_view text, std::size_t maxLength) {
    return printable(text.substr(0, maxLength)) + (text.size() > maxLength ? "..." : "");
}

void logMessage(LogLevel level, const std::string& message) {
    if (level < logLevel()) return;
    const std::string line = printable(message);
    std::lock_guard lock(gWriteMutex);
    std::fprintf(stderr, "%s%s\n", prefix(level), line.c_str());
    std::fflush(stderr);
}

[[noreturn]] void assertFailed(const char* expression, const char* file, int line,
                               const std::string& message) {
    std::fprintf(stderr, "qgi: assertion failed: %s at %s:%d%s%s\n", expression, file, line,
                 message.empty() ? "" : ": ", message.c_str());
    std::fflush(stderr);
    std::abort();
}

} // namespace qgi
