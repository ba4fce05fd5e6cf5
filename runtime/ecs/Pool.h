#pragma once

#include "runtime/core/Error.h"
#include "runtime/ecs/Entity.h"

#include <atomic>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace qgi {

/// Type-erased part of a component pool: what the registry needs without knowing T.
class PoolBase {
public:
    static constexpr std::uint32_t kAbsent = 0xffffffffu;

    virtual ~PoolBase() = default;
    virtual void removeIfPresent(Entity e) = 0;

    std::size_t size() const { return mDense.size(); }
    std::span<const Entity> entities() const { return mDense; }

    bool contains(Entity e) const {
        return e.index < mSparse.size() && mSparse[e.index] != kAbsent &&
               mDense[mSparse[e.index]] == e;
    }
    /// Dense position of `e`, or kAbsent.
    std::uint32_t find(Entity e) const {
        if (e.index >= mSparse.size()) return kAbsent;
        const std::uint32_t slot = mSparse[e.index];
        return (slot != kAbsent && mDense[slot] == e) ? slot : kAbsent;
    }

    /// Like find, but first tries `hint`: pools filled in the same entity order line up, and
    /// a view walking one of them then finds the others' slots without a sparse lookup.
    std::uint32_t findWithHint(Entity e, std::size_t hint) const {
        if (hint < mDense.size() && mDense[hint] == e) return std::uint32_t(hint);
        return find(e);
    }

    // ---- change tracking ---------------------------------------------------------------------
    /// Entities whose component was added or patched since the last clearChanged().
    std::span<const Entity> changed() const { return mChanged; }
    bool wasChanged(Entity e) const {
        return e.index < mChangedStamp.size() && mChangedStamp[e.index] == mChangeEpoch &&
               contains(e);
    }
    void markChanged(Entity e) {
        if (e.index >= mChangedStamp.size()) mChangedStamp.resize(e.index + 1, 0);
        if (mChangedStamp[e.index] != mChangeEpoch) {
            mChangedStamp[e.index] = mChangeEpoch;
            mChanged.push_back(e);
        }
    }
    void clearChanged() {
        mChanged.clear();
        ++mChangeEpoch; // stamps of the previous epoch no longer match
    }

    // ---- iteration guard: structural changes to a pool under iteration are bugs -------------
    void lockIteration() const { mIterationLocks.fetch_add(1, std::memory_order_relaxed); }
    void unlockIteration() const { mIterationLocks.fetch_sub(1, std::memory_order_relaxed); }
    bool iterating() const { return mIterationLocks.load(std::memory_order_relaxed) > 0; }

protected:
    std::vector<std::uint32_t> mSparse; // entity index -> dense slot
    std::vector<Entity> mDense;         // dense slot -> entity
    std::vector<Entity> mChanged;
    std::vector<std::uint32_t> mChangedStamp; // entity index -> epoch of its last change
    std::uint32_t mChangeEpoch = 1;
    mutable std::atomic<int> mIterationLocks{0}; // views under iteration (several threads may read)
};

/// Sparse-set pool of T: O(1) add, remove (swap with last), lookup; dense, cache-friendly data.
/// References to components stay valid until a component of the same type is added or removed.
template <typename T> class Pool final : public PoolBase {
public:
    template <typename... Args> T& emplace(Entity e, Args&&... args) {
        QGI_ASSERT(!iterating(), "adding a component to a pool that is being iterated");
        QGI_ASSERT(!contains(e), "entity already has this component");
        if (e.index >= mSparse.size()) mSparse.resize(std::size_t(e.index) + 1, kAbsent);
        mSparse[e.index] = std::uint32_t(mDense.size());
        mDense.push_back(e);
        if constexpr (std::is_aggregate_v<T>)
            mData.push_back(T{std::forward<Args>(args)...});
        else
            mData.emplace_back(std::forward<Args>(args)...);
        markChanged(e);
        return mData.back();
    }

    void remove(Entity e) {
        QGI_ASSERT(!iterating(), "removing a component from a pool that is being iterated");
        const std::uint32_t slot = find(e);
        QGI_ASSERT(slot != kAbsent, "entity has no such component");
        const std::uint32_t last = std::uint32_t(mDense.size() - 1);
        if (slot != last) {
            mDense[slot] = mDense[last];
            mData[slot] = std::move(mData[last]);
            mSparse[mDense[slot].index] = slot;
        }
        mDense.pop_back();
        mData.pop_back();
        mSparse[e.index] = kAbsent;
    }

    void removeIfPresent(Entity e) override {
        if (contains(e)) remove(e);
    }

    T* tryGet(Entity e) {
        const std::uint32_t slot = find(e);
        return slot == kAbsent ? nullptr : &mData[slot];
    }
    const T* tryGet(Entity e) const {
        const std::uint32_t slot = find(e);
        return slot == kAbsent ? nullptr : &mData[slot];
    }
    T& atSlot(std::uint32_t slot) { return mData[slot]; }
    const T& atSlot(std::uint32_t slot) const { return mData[slot]; }
    std::span<T> data() { return mData; }
    std::span<const T> data() const { return mData; }

private:
    std::vector<T> mData;
};

} // namespace qgi
