#include "runtime/ecs/Registry.h"

#include <gtest/gtest.h>

namespace qgi {
namespace {
struct Position { float x = 0.f; };
struct Velocity { float v = 0.f; };
} // namespace

TEST(Ecs, StaleHandleIsDetected) {
    Registry r;
    const Entity a = r.create();
    r.destroy(a);
    const Entity b = r.create();
    EXPECT_EQ(a.index, b.index);
    EXPECT_FALSE(r.alive(a));
    EXPECT_TRUE(r.alive(b));
}
} // namespace qgi
