#pragma once

#include "runtime/core/SystemMemory.h"

#include <cstddef>
#include <cstdlib>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace qgi {

/** An allocator for arrays of hundreds of megabytes that are read at random (the photon store,
 *  its paths, the path grid): a block of 2 MiB or more is aligned to 2 MiB and, on Linux,
 *  advised to use transparent huge pages, so a random read costs one TLB entry per 2 MiB
 *  instead of one per 4 KiB. Where the kernel offers no huge pages the advice is ignored and
 *  nothing changes. Smaller blocks come from operator new as usual.
 *
 *  Growing without a value (`resize(n)`) default-initialises, as `new T[n]` does: elements of
 *  a type without a constructor (floats, glm vectors, integers) are left unwritten, not zeroed.
 *  Every user writes what it grows before reading it (the tracer's output, re-traced paths,
 *  compaction, the grid's id lists), and zeroing 100 MiB it is about to overwrite cost the
 *  tracer about 2 % of its time.
 *
 *  A block of 64 MiB or more that exceeds the memory available (availableMemoryBytes) throws
 *  std::bad_alloc at once. */
template <typename T> struct LargeArrayAllocator {
    using value_type = T;
    static constexpr std::size_t kHugePage = std::size_t(2) << 20;
    /// Blocks from this size on are checked against the memory available (a file read).
    static constexpr std::size_t kCheckedBytes = std::size_t(64) << 20;

    LargeArrayAllocator() noexcept = default;
    template <typename U> LargeArrayAllocator(const LargeArrayAllocator<U>&) noexcept {}

    T* allocate(std::size_t n) {
        if (n > std::size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
        const std::size_t bytes = n * sizeof(T);
        if (bytes < kHugePage) return static_cast<T*>(::operator new(bytes));
        // Linux grants more than it has and kills the process when the pages are written: a
        // block the machine cannot hold is refused here (std::bad_alloc), where the caller can
        // say what to lower.
        if (bytes >= kCheckedBytes) checkMemoryFor(bytes, availableMemoryBytes());
        const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
        void* p = std::aligned_alloc(kHugePage, rounded);
        if (!p) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
        madvise(p, rounded, MADV_HUGEPAGE); // advice only: a refusal changes nothing
#endif
        return static_cast<T*>(p);
    }
    /// Default-initialises (see the class comment); with arguments, constructs from them.
    template <typename U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
        ::new (static_cast<void*>(p)) U;
    }
    template <typename U, typename... Args> void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
    void deallocate(T* p, std::size_t n) noexcept {
        if (n * sizeof(T) < kHugePage)
            ::operator delete(p);
        else
            std::free(p);
    }
};

template <typename T, typename U>
bool operator==(const LargeArrayAllocator<T>&, const LargeArrayAllocator<U>&) noexcept {
    return true;
}

/// A std::vector in LargeArrayAllocator memory.
template <typename T> using LargeArray = std::vector<T, LargeArrayAllocator<T>>;

} // namespace qgi
