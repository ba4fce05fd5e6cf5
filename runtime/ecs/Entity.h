#pragma once

#include <cstdint>
#include <functional>

namespace qgi {

/// A handle to an entity: a slot index plus the generation of that slot. Destroying an entity
/// bumps its slot's generation, so an old handle never aliases the slot's next occupant.
struct Entity {
    static constexpr std::uint32_t kInvalidIndex = 0xffffffffu;

    std::uint32_t index = kInvalidIndex;
    std::uint32_t generation = 0;

    constexpr bool isNull() const { return index == kInvalidIndex; }
    constexpr explicit operator bool() const { return !isNull(); }
    friend constexpr bool operator==(Entity, Entity) = default;
    friend constexpr auto operator<=>(Entity, Entity) = default;
};

inline constexpr Entity kNullEntity{};

} // namespace qgi

template <> struct std::hash<qgi::Entity> {
    std::size_t operator()(qgi::Entity e) const noexcept {
        return std::hash<std::uint64_t>{}((std::uint64_t(e.generation) << 32) | e.index);
    }
};
