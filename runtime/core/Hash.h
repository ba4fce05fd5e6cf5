#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <type_traits>

namespace qgi {

/// FNV-1a, 64 bit, over raw bytes: the one hasher for cache keys and file checksums.
/// Values are hashed as their in-memory bytes (host byte order, padding included), so a key is
/// only comparable between builds on machines of the same byte order; cache files record theirs.
class Fnv1aHasher {
public:
    static constexpr std::uint64_t kOffsetBasis = 0xcbf29ce484222325ull;
    static constexpr std::uint64_t kPrime = 0x100000001b3ull;

    /// Folds `size` bytes starting at `data` into the hash.
    void addBytes(const void* data, std::size_t size) {
        const auto* p = static_cast<const unsigned char*>(data);
        for (std::size_t i = 0; i < size; ++i) {
            mValue ^= p[i];
            mValue *= kPrime;
        }
    }
    /// Folds the bytes of one trivially copyable value.
    template <typename T> void add(const T& value) {
        static_assert(std::is_trivially_copyable_v<T>);
        addBytes(&value, sizeof(T));
    }
    /// Folds an array: its element count as a u64, then the bytes of its elements. Takes a
    /// std::vector, std::array, std::span or any other contiguous range.
    template <typename Range> void addArray(const Range& values) {
        const std::span elements(values);
        static_assert(std::is_trivially_copyable_v<typename decltype(elements)::element_type>);
        add(std::uint64_t(elements.size()));
        if (!elements.empty()) addBytes(elements.data(), elements.size_bytes());
    }
    std::uint64_t value() const { return mValue; }

private:
    std::uint64_t mValue = kOffsetBasis;
};

} // namespace qgi
