#pragma once

#include "runtime/ecs/Pool.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <span>
#include <tuple>
#include <type_traits>

namespace qgi {

/// Entities that have every component in Ts. Iterates the smallest pool and probes the others.
/// `View<const Transform, VertexIrradiance>` gives `const Transform&` and `VertexIrradiance&`.
/// While `each` runs, the pools of Ts are locked against structural change (see Registry).
template <typename... Ts> class View {
    static_assert(sizeof...(Ts) > 0, "a view needs at least one component type");
    template <typename T>
    using PoolPtr = std::conditional_t<std::is_const_v<T>, const Pool<std::remove_const_t<T>>*,
                                       Pool<std::remove_const_t<T>>*>;

public:
    explicit View(PoolPtr<Ts>... pools) : mPools(pools...) {}

    /// Calls fn(Entity, Ts&...) or fn(Ts&...) for every matching entity.
    template <typename Fn> void each(Fn&& fn) const {
        if (empty()) return;
        const PoolBase& lead = leadPool();
        Lock lock(*this);
        const auto entities = lead.entities();
        const std::size_t n = entities.size();
        std::size_t i = 0;
        // Pools filled in the same entity order line up block by block: such a block is walked
        // like plain arrays, with no per-entity lookup.
        for (; i + kBlock <= n; i += kBlock) {
            if (alignedBlock(entities, i)) {
                for (std::size_t j = i; j < i + kBlock; ++j)
                    invokeAt(fn, entities[j], j, std::index_sequence_for<Ts...>{});
                continue;
            }
            for (std::size_t j = i; j < i + kBlock; ++j) visit(fn, lead, entities, j);
        }
        for (; i < n; ++i) visit(fn, lead, entities, i);
    }

    /// The matching entities, in iteration order (a snapshot: safe to change structure after).
    std::vector<Entity> entities() const {
        std::vector<Entity> out;
        each([&](Entity e, Ts&...) { out.push_back(e); });
        return out;
    }

    /// Upper bound on the number of matches (the size of the smallest pool).
    std::size_t sizeHint() const { return empty() ? 0 : leadPool().size(); }

    bool contains(Entity e) const {
        if (empty()) return false;
        std::array<std::uint32_t, sizeof...(Ts)> slots;
        return findAll(e, nullptr, PoolBase::kAbsent, slots);
    }

    template <typename T> T& get(Entity e) const {
        constexpr std::size_t k = indexOf<T>();
        auto* pool = std::get<k>(mPools);
        const std::uint32_t slot = pool ? pool->find(e) : PoolBase::kAbsent;
        QGI_ASSERT(slot != PoolBase::kAbsent, "entity not in view");
        return pool->atSlot(slot);
    }

private:
    static constexpr std::size_t kBlock = 64;

    template <typename Fn>
    void visit(Fn& fn, const PoolBase& lead, std::span<const Entity> entities, std::size_t i) const {
        std::array<std::uint32_t, sizeof...(Ts)> slots;
        if (findAll(entities[i], &lead, i, slots))
            invoke(fn, entities[i], slots, std::index_sequence_for<Ts...>{});
    }

    bool alignedBlock(std::span<const Entity> lead, std::size_t begin) const {
        return std::apply(
            [&](auto*... p) {
                return ((p->size() >= begin + kBlock &&
                         std::memcmp(p->entities().data() + begin, lead.data() + begin,
                                     kBlock * sizeof(Entity)) == 0) &&
                        ...);
            },
            mPools);
    }

    template <typename Fn, std::size_t... I>
    void invokeAt(Fn& fn, Entity e, std::size_t slot, std::index_sequence<I...>) const {
        if constexpr (std::is_invocable_v<Fn&, Entity, Ts&...>)
            fn(e, std::get<I>(mPools)->atSlot(std::uint32_t(slot))...);
        else
            fn(std::get<I>(mPools)->atSlot(std::uint32_t(slot))...);
    }

    struct Lock {
        const View& view;
        explicit Lock(const View& v) : view(v) {
            std::apply([](auto*... p) { (p->lockIteration(), ...); }, view.mPools);
        }
        ~Lock() {
            std::apply([](auto*... p) { (p->unlockIteration(), ...); }, view.mPools);
        }
    };

    bool empty() const {
        return std::apply([](auto*... p) { return ((p == nullptr) || ...); }, mPools);
    }

    const PoolBase& leadPool() const {
        const PoolBase* best = nullptr;
        std::apply(
            [&](auto*... p) {
                ((best = (!best || p->size() < best->size()) ? p : best), ...);
            },
            mPools);
        return *best;
    }

    // `lead`: the pool being walked (nullptr: none), where e sits at `hint`.
    bool findAll(Entity e, const PoolBase* lead, std::size_t hint,
                 std::array<std::uint32_t, sizeof...(Ts)>& slots) const {
        return findAllImpl(e, lead, hint, slots, std::index_sequence_for<Ts...>{});
    }
    template <std::size_t... I>
    bool findAllImpl(Entity e, const PoolBase* lead, std::size_t hint,
                     std::array<std::uint32_t, sizeof...(Ts)>& slots,
                     std::index_sequence<I...>) const {
        return ((slots[I] = static_cast<const PoolBase*>(std::get<I>(mPools)) == lead
                                ? std::uint32_t(hint)
                                : std::get<I>(mPools)->findWithHint(e, hint),
                 slots[I] != PoolBase::kAbsent) &&
                ...);
    }

    template <typename Fn, std::size_t... I>
    void invoke(Fn& fn, Entity e, const std::array<std::uint32_t, sizeof...(Ts)>& slots,
                std::index_sequence<I...>) const {
        if constexpr (std::is_invocable_v<Fn&, Entity, Ts&...>)
            fn(e, std::get<I>(mPools)->atSlot(slots[I])...);
        else
            fn(std::get<I>(mPools)->atSlot(slots[I])...);
    }

    template <typename T, std::size_t I = 0> static constexpr std::size_t indexOf() {
        using Tuple = std::tuple<Ts...>;
        if constexpr (I == sizeof...(Ts)) {
            static_assert(I < sizeof...(Ts), "type is not part of this view");
            return I;
        } else if constexpr (std::is_same_v<std::remove_const_t<std::tuple_element_t<I, Tuple>>,
                                            std::remove_const_t<T>>) {
            static_assert(std::is_const_v<T> || !std::is_const_v<std::tuple_element_t<I, Tuple>>,
                          "this view gives only const access to the type");
            return I;
        } else {
            return indexOf<T, I + 1>();
        }
    }

    std::tuple<PoolPtr<Ts>...> mPools;
};

} // namespace qgi
