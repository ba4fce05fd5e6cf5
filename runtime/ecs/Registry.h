#pragma once

#include "runtime/core/Error.h"
#include "runtime/core/TypeName.h"
#include "runtime/ecs/Context.h"
#include "runtime/ecs/Entity.h"
#include "runtime/ecs/Pool.h"
#include "runtime/ecs/TypeId.h"

#include <memory>
#include <span>
#include <tuple>
#include <type_traits>
#include <vector>

namespace qgi {

template <typename... Ts> class View;

/// Owns entities, their components (one sparse-set pool per type) and the world resources.
///
/// What may change while a view is being iterated (checked by assertions):
///  - component *values* of any type: yes (through the view or get/patch);
///  - creating entities, adding or removing components of types the view does not iterate: yes;
///  - adding or removing components of an iterated type, destroying an entity that has one:
///    no, it asserts. Collect the entities first and change them after the loop.
///
/// Change tracking: `emplace` and `patch` record the entity in that type's changed list, which
/// `clearChanges()` (called by the Schedule at the end of every frame) empties. A system asks
/// `changed<Transform>()` to learn which poses changed this frame. Writes through a plain
/// reference are not tracked: use `patch` when the change matters to other systems.
class Registry {
public:
    Registry() = default;
    Registry(const Registry&) = delete;
    Registry& operator=(const Registry&) = delete;

    // ---- entities ------------------------------------------------------------------------------
    Entity create() {
        if (!mFreeSlots.empty()) {
            const std::uint32_t index = mFreeSlots.back();
            mFreeSlots.pop_back();
            mAlive[index] = true;
            return Entity{index, mGenerations[index]};
        }
        QGI_ASSERT(mGenerations.size() < Entity::kInvalidIndex, "entity index space exhausted");
        mGenerations.push_back(0);
        mAlive.push_back(true);
        return Entity{std::uint32_t(mGenerations.size() - 1), 0};
    }

    /// Removes every component of `e` and retires its handle. Destroying a dead handle is a no-op.
    void destroy(Entity e) {
        if (!alive(e)) return;
        for (auto& pool : mPools)
            if (pool) pool->removeIfPresent(e);
        mAlive[e.index] = false;
        ++mGenerations[e.index]; // every outstanding handle to this slot is now stale
        mFreeSlots.push_back(e.index);
    }

    bool alive(Entity e) const {
        return e.index < mGenerations.size() && mAlive[e.index] &&
               mGenerations[e.index] == e.generation;
    }

    std::size_t aliveCount() const { return mGenerations.size() - mFreeSlots.size(); }

    // ---- components ----------------------------------------------------------------------------
    template <typename T, typename... Args> T& emplace(Entity e, Args&&... args) {
        QGI_ASSERT(alive(e), "emplace on a dead or stale entity");
        return pool<T>().emplace(e, std::forward<Args>(args)...);
    }

    template <typename T, typename... Args> T& emplaceOrReplace(Entity e, Args&&... args) {
        if (T* existing = tryGet<T>(e)) {
            *existing = T{std::forward<Args>(args)...};
            markChanged<T>(e);
            return *existing;
        }
        return emplace<T>(e, std::forward<Args>(args)...);
    }

    template <typename T> void remove(Entity e) {
        if (auto* p = findPool<T>()) p->removeIfPresent(e);
    }

    template <typename T> bool has(Entity e) const {
        const auto* p = findPool<T>();
        return p && p->contains(e);
    }

    template <typename T> T* tryGet(Entity e) {
        auto* p = findPool<T>();
        return p ? p->tryGet(e) : nullptr;
    }
    template <typename T> const T* tryGet(Entity e) const {
        const auto* p = findPool<T>();
        return p ? p->tryGet(e) : nullptr;
    }

    template <typename T> T& get(Entity e) {
        T* c = tryGet<T>(e);
        QGI_ASSERT(c, "entity ", e.index, ":", e.generation, " has no ", typeName<T>());
        return *c;
    }
    template <typename T> const T& get(Entity e) const {
        const T* c = tryGet<T>(e);
        QGI_ASSERT(c, "entity ", e.index, ":", e.generation, " has no ", typeName<T>());
        return *c;
    }

    /// Mutable access that records the change (see the class comment).
    template <typename T> T& patch(Entity e) {
        T& c = get<T>(e);
        markChanged<T>(e);
        return c;
    }
    template <typename T> void markChanged(Entity e) {
        if (auto* p = findPool<T>(); p && p->contains(e)) p->markChanged(e);
    }

    /// Entities whose T was added or patched since the last clearChanges(), in order of change.
    /// An entity destroyed (or whose T was removed) after its change may still be listed.
    template <typename T> std::span<const Entity> changed() const {
        const auto* p = findPool<T>();
        return p ? p->changed() : std::span<const Entity>{};
    }
    template <typename T> bool wasChanged(Entity e) const {
        const auto* p = findPool<T>();
        return p && p->wasChanged(e);
    }
    void clearChanges() {
        for (auto& p : mPools)
            if (p) p->clearChanged();
    }

    template <typename T> std::size_t count() const {
        const auto* p = findPool<T>();
        return p ? p->size() : 0;
    }

    /// All entities holding every Ts. `const T` gives read-only access to T.
    template <typename... Ts> View<Ts...> view() { return View<Ts...>(poolFor<Ts>()...); }
    template <typename... Ts> View<Ts...> view() const {
        static_assert((std::is_const_v<Ts> && ...), "a const registry only gives const views");
        return View<Ts...>(constPoolFor<Ts>()...);
    }

    // ---- world resources -------------------------------------------------------------------------
    Context& ctx() { return mContext; }
    const Context& ctx() const { return mContext; }

    template <typename T> Pool<std::remove_const_t<T>>* findPool() {
        const std::size_t id = typeId<T>();
        return id < mPools.size() ? static_cast<Pool<std::remove_const_t<T>>*>(mPools[id].get())
                                  : nullptr;
    }
    template <typename T> const Pool<std::remove_const_t<T>>* findPool() const {
        const std::size_t id = typeId<T>();
        return id < mPools.size()
                   ? static_cast<const Pool<std::remove_const_t<T>>*>(mPools[id].get())
                   : nullptr;
    }

private:
    template <typename T> Pool<std::remove_const_t<T>>& pool() {
        using Bare = std::remove_const_t<T>;
        const std::size_t id = typeId<Bare>();
        if (id >= mPools.size()) mPools.resize(id + 1);
        if (!mPools[id]) mPools[id] = std::make_unique<Pool<Bare>>();
        return static_cast<Pool<Bare>&>(*mPools[id]);
    }
    // A view over a type nobody has emplaced yet still needs a (empty) pool to point at.
    template <typename T> auto* poolFor() {
        if constexpr (std::is_const_v<T>)
            return static_cast<const Pool<std::remove_const_t<T>>*>(&pool<T>());
        else
            return &pool<T>();
    }
    // nullptr when no pool exists yet: the view is then empty.
    template <typename T> const Pool<std::remove_const_t<T>>* constPoolFor() const {
        return findPool<T>();
    }

    Context mContext; // declared first: destroyed after the pools
    std::vector<std::unique_ptr<PoolBase>> mPools; // indexed by typeId<T>()
    std::vector<std::uint32_t> mGenerations;
    std::vector<bool> mAlive;
    std::vector<std::uint32_t> mFreeSlots;
};

} // namespace qgi

#include "runtime/ecs/View.h"
