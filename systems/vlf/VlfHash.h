#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace qgi::vlf {

/// FNV-1a, 64 bit, over the bytes of trivially copyable values (cache keys and checksums).
class Hasher {
public:
    void addBytes(const void* data, std::size_t size) {
        const auto* p = static_cast<const unsigned char*>(data);
        for (std::size_t i = 0; i < size; ++i) {
            mValue ^= p[i];
            mValue *= 0x100000001b3ull;
        }
    }
    template <typename T> void add(const T& value) {
        static_assert(std::is_trivially_copyable_v<T>);
        addBytes(&value, sizeof(T));
    }
    std::uint64_t value() const { return mValue; }

private:
    std::uint64_t mValue = 0xcbf29ce484222325ull;
};

} // namespace qgi::vlf
