#pragma once

#include <embree3/rtcore.h>

#include <utility>

namespace qgi {

/// Owns one reference to an Embree object (RTCScene, RTCGeometry) and releases it on
/// destruction. Move-only; a default-constructed handle holds nothing.
template <typename Handle, void (*Release)(Handle)> class EmbreeHandle {
public:
    EmbreeHandle() = default;
    /// Takes over the reference the caller holds (as returned by rtcNewScene, rtcNewGeometry).
    explicit EmbreeHandle(Handle handle) : mHandle(handle) {}
    EmbreeHandle(EmbreeHandle&& other) noexcept : mHandle(std::exchange(other.mHandle, nullptr)) {}
    EmbreeHandle& operator=(EmbreeHandle&& other) noexcept {
        std::swap(mHandle, other.mHandle);
        return *this;
    }
    EmbreeHandle(const EmbreeHandle&) = delete;
    EmbreeHandle& operator=(const EmbreeHandle&) = delete;
    ~EmbreeHandle() {
        if (mHandle) Release(mHandle);
    }

    Handle get() const { return mHandle; }

private:
    Handle mHandle = nullptr;
};

using SceneHandle = EmbreeHandle<RTCScene, rtcReleaseScene>;
using GeometryHandle = EmbreeHandle<RTCGeometry, rtcReleaseGeometry>;

} // namespace qgi
