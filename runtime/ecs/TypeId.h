#pragma once

#include <atomic>
#include <cstddef>

namespace qgi {

namespace detail {
inline std::size_t nextTypeId() {
    static std::atomic<std::size_t> counter{0};
    return counter.fetch_add(1, std::memory_order_relaxed);
}
} // namespace detail

/// A small dense integer per type, used to index component pools and context resources.
/// Const-ness is stripped: `const T` and `T` share one id.
template <typename T> std::size_t typeId() {
    using Bare = std::remove_cv_t<std::remove_reference_t<T>>;
    static const std::size_t id = detail::nextTypeId();
    if constexpr (!std::is_same_v<Bare, T>)
        return typeId<Bare>();
    else
        return id;
}

} // namespace qgi
