#pragma once

#include <embree3/rtcore.h>

#include <cstddef>
#include <mutex>
#include <optional>
#include <string>

namespace qgi {

/// An error Embree reported through the device's error callback.
struct EmbreeError {
    RTCError code = RTC_ERROR_NONE;
    std::string message; ///< "<code name>: <Embree's text>"
};

/** One Embree device with an error callback that logs every error and records it, so set-up
 *  code can turn errors into a qgi::Error (takeError) and tests can observe them.
 *  Errors may be reported from any thread (Embree builds and traverses on many).
 *  Not movable: Embree keeps a pointer to it for the callback.                          */
class EmbreeDevice {
public:
    /// `config` is Embree's device configuration string ("" for the defaults, "threads=2", ...).
    /// Throws qgi::Error when Embree cannot create the device.
    explicit EmbreeDevice(const std::string& config = "");
    ~EmbreeDevice();
    EmbreeDevice(const EmbreeDevice&) = delete;
    EmbreeDevice& operator=(const EmbreeDevice&) = delete;

    RTCDevice handle() const { return mDevice; }

    /// Errors reported since the device was created.
    std::size_t errorCount() const;
    /// The first error reported since the last call, and forgets it; nullopt when there was none.
    std::optional<EmbreeError> takeError();

private:
    static void onError(void* self, RTCError code, const char* message);

    RTCDevice mDevice = nullptr;
    mutable std::mutex mMutex; // guards the two fields below
    std::size_t mErrorCount = 0;
    std::optional<EmbreeError> mPending;
};

} // namespace qgi
