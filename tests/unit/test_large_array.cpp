// LargeArray (runtime/core/LargeArray.h): a std::vector whose big blocks are 2 MiB aligned and
// advised for huge pages. It must behave as a vector on both sides of that threshold.
#include "runtime/core/LargeArray.h"
#include "runtime/core/SystemMemory.h"

#include "runtime/ecs/Entity.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <new>
#include <numeric>
#include <string>

namespace qgi {
namespace {

TEST(LargeArray, SmallAndLargeBlocksHoldTheirValuesThroughGrowth) {
    LargeArray<std::uint32_t> values;
    constexpr std::size_t kBig = (std::size_t(5) << 20) / sizeof(std::uint32_t); // 5 MiB
    for (std::uint32_t i = 0; i < 1000; ++i)                                     // small blocks
        values.push_back(i * 3u);
    values.resize(kBig); // crosses into huge-page blocks, copying the small one
    std::iota(values.begin() + 1000, values.end(), 3000u);
    for (std::size_t i = 0; i < values.size(); i += 997)
        ASSERT_EQ(values[i], i < 1000 ? std::uint32_t(i * 3) : std::uint32_t(3000 + i - 1000));
    const auto address = reinterpret_cast<std::uintptr_t>(values.data());
    EXPECT_EQ(address % LargeArrayAllocator<std::uint32_t>::kHugePage, 0u);

    LargeArray<std::uint32_t> copy = values; // copies allocate through the same allocator
    EXPECT_EQ(copy, values);
    values.clear();
    values.shrink_to_fit(); // back below the threshold: freed with the matching call
    values.push_back(7u);
    EXPECT_EQ(values.front(), 7u);
    EXPECT_EQ(copy[kBig - 1], std::uint32_t(3000 + kBig - 1 - 1000));
}

// Growing without a value default-initialises: a type with member initialisers still gets
// them (an Entity is null, not index 0), and a value given is copied into every new element.
TEST(LargeArray, GrowingKeepsConstructorsAndGivenValues) {
    LargeArray<Entity> entities;
    entities.resize(3);
    for (const Entity e : entities)
        EXPECT_TRUE(e.isNull());
    LargeArray<float> lengths(2, 1.5f);
    lengths.resize(5, -2.f);
    EXPECT_EQ(lengths[1], 1.5f);
    EXPECT_EQ(lengths[4], -2.f);
    lengths.emplace_back(4.f);
    EXPECT_EQ(lengths.back(), 4.f);
}

TEST(LargeArray, AnImpossibleSizeThrowsInsteadOfWrapping) {
    LargeArrayAllocator<std::uint64_t> allocator;
    EXPECT_THROW((void)allocator.allocate(std::size_t(-1) / 4), std::bad_array_new_length);
}

// The machine's figure: positive and no more than its memory and swap together.
TEST(SystemMemory, AvailableMemoryIsWhatTheMachineHas) {
    const std::optional<std::size_t> available = availableMemoryBytes();
    ASSERT_TRUE(available.has_value()) << "/proc/meminfo unreadable";
    std::ifstream in("/proc/meminfo");
    std::string key, unit;
    std::size_t kilobytes = 0, total = 0;
    while (in >> key >> kilobytes) {
        std::getline(in, unit);
        if (key == "MemTotal:" || key == "SwapTotal:") total += kilobytes * 1024;
    }
    EXPECT_GT(*available, std::size_t(0));
    EXPECT_LE(*available, total);
}

TEST(SystemMemory, ABlockOverWhatIsAvailableIsRefused) {
    EXPECT_THROW(checkMemoryFor(101, 100), std::bad_alloc);
    EXPECT_NO_THROW(checkMemoryFor(100, 100));
    EXPECT_NO_THROW(checkMemoryFor(std::size_t(1) << 60, std::nullopt)); // no figure: no check
    // Through the allocator: more than the machine has is a bad_alloc, not a grant the kernel
    // would have to take back by killing the process.
    LargeArray<std::uint8_t> huge;
    EXPECT_THROW(huge.reserve(*availableMemoryBytes() + (std::size_t(1) << 30)), std::bad_alloc);
}

} // namespace
} // namespace qgi
