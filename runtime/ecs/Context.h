#pragma once

#include "runtime/core/Error.h"
#include "runtime/core/TypeName.h"
#include "runtime/ecs/TypeId.h"

#include <memory>
#include <typeinfo>
#include <vector>

namespace qgi {

/// World resources: at most one object of each type per registry (the ray scene, the photon
/// store, the profiler, ...). This replaces singletons: two registries never share state.
class Context {
public:
    Context() = default;
    Context(const Context&) = delete;
    Context& operator=(const Context&) = delete;
    ~Context() {
        // Destroy in reverse order of creation: later resources may refer to earlier ones.
        for (auto it = mOrder.rbegin(); it != mOrder.rend(); ++it) mSlots[*it].reset();
    }

    template <typename T, typename... Args> T& emplace(Args&&... args) {
        const std::size_t id = typeId<T>();
        if (id >= mSlots.size()) mSlots.resize(id + 1);
        QGI_ASSERT(!mSlots[id], "context already holds a ", typeName<T>());
        auto holder = std::make_shared<T>(std::forward<Args>(args)...);
        T& ref = *holder;
        mSlots[id] = std::move(holder);
        mOrder.push_back(id);
        return ref;
    }

    /// Replaces any existing resource of type T.
    template <typename T, typename... Args> T& emplaceOrReplace(Args&&... args) {
        erase<T>();
        return emplace<T>(std::forward<Args>(args)...);
    }

    template <typename T> void erase() {
        const std::size_t id = typeId<T>();
        if (id < mSlots.size() && mSlots[id]) {
            mSlots[id].reset();
            std::erase(mOrder, id);
        }
    }

    /// Removes the resource of type T and hands it over (null when there is none), so that it
    /// can be put back with adopt(): a system can then be run as if the resource were absent.
    template <typename T> std::shared_ptr<T> take() {
        const std::size_t id = typeId<T>();
        if (id >= mSlots.size() || !mSlots[id]) return nullptr;
        std::shared_ptr<T> taken = std::static_pointer_cast<T>(std::move(mSlots[id]));
        mSlots[id].reset();
        std::erase(mOrder, id);
        return taken;
    }

    /// Holds `resource` (not null) as the resource of type T; there must be none yet.
    template <typename T> T& adopt(std::shared_ptr<T> resource) {
        QGI_ASSERT(resource, "context: adopting no ", typeName<T>());
        const std::size_t id = typeId<T>();
        if (id >= mSlots.size()) mSlots.resize(id + 1);
        QGI_ASSERT(!mSlots[id], "context already holds a ", typeName<T>());
        T& ref = *resource;
        mSlots[id] = std::move(resource);
        mOrder.push_back(id);
        return ref;
    }

    template <typename T> bool contains() const { return find<T>() != nullptr; }

    template <typename T> T* find() {
        const std::size_t id = typeId<T>();
        return id < mSlots.size() ? static_cast<T*>(mSlots[id].get()) : nullptr;
    }
    template <typename T> const T* find() const {
        const std::size_t id = typeId<T>();
        return id < mSlots.size() ? static_cast<const T*>(mSlots[id].get()) : nullptr;
    }

    template <typename T> T& get() {
        T* p = find<T>();
        QGI_ASSERT(p, "context has no ", typeName<T>());
        return *p;
    }
    template <typename T> const T& get() const {
        const T* p = find<T>();
        QGI_ASSERT(p, "context has no ", typeName<T>());
        return *p;
    }

private:
    std::vector<std::shared_ptr<void>> mSlots; // indexed by typeId<T>()
    std::vector<std::size_t> mOrder;           // creation order, for orderly destruction
};

} // namespace qgi
