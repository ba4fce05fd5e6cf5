#include "runtime/raytrace/EmbreeDevice.h"

#include "runtime/core/Log.h"

namespace qgi {
namespace {

const char* errorName(RTCError code) {
    switch (code) {
    case RTC_ERROR_NONE:
        return "RTC_ERROR_NONE";
    case RTC_ERROR_UNKNOWN:
        return "RTC_ERROR_UNKNOWN";
    case RTC_ERROR_INVALID_ARGUMENT:
        return "RTC_ERROR_INVALID_ARGUMENT";
    case RTC_ERROR_INVALID_OPERATION:
        return "RTC_ERROR_INVALID_OPERATION";
    case RTC_ERROR_OUT_OF_MEMORY:
        return "RTC_ERROR_OUT_OF_MEMORY";
    case RTC_ERROR_UNSUPPORTED_CPU:
        return "RTC_ERROR_UNSUPPORTED_CPU";
    case RTC_ERROR_CANCELLED:
        return "RTC_ERROR_CANCELLED";
    }
    return "RTC_ERROR_?";
}

} // namespace

EmbreeDevice::EmbreeDevice(const std::string& config) {
    mDevice = rtcNewDevice(config.c_str());
    if (!mDevice)
        fail("Embree: cannot create a device with config '", config,
             "': ", errorName(rtcGetDeviceError(nullptr)));
    rtcSetDeviceErrorFunction(mDevice, &EmbreeDevice::onError, this);
}

EmbreeDevice::~EmbreeDevice() {
    rtcReleaseDevice(mDevice);
}

std::size_t EmbreeDevice::errorCount() const {
    std::lock_guard lock(mMutex);
    return mErrorCount;
}

std::optional<EmbreeError> EmbreeDevice::takeError() {
    std::lock_guard lock(mMutex);
    return std::exchange(mPending, std::nullopt);
}

void EmbreeDevice::onError(void* self, RTCError code, const char* message) {
    auto& device = *static_cast<EmbreeDevice*>(self);
    EmbreeError error{code, str(errorName(code), ": ", message ? message : "(no message)")};
    logError("Embree: ", error.message);
    std::lock_guard lock(device.mMutex);
    ++device.mErrorCount;
    if (!device.mPending) device.mPending = std::move(error);
}

} // namespace qgi
