#include "runtime/ecs/Registry.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <type_traits>

namespace qgi {
namespace {

struct Position {
    float x = 0.f;
};
struct Velocity {
    float v = 0.f;
};
struct Tag {};

struct Counter { // a world resource
    int value = 0;
};

TEST(Ecs, StaleHandleIsDetectedAndNeverAliased) {
    Registry r;
    const Entity a = r.create();
    r.emplace<Position>(a, 1.f);
    r.destroy(a);
    const Entity b = r.create(); // reuses the slot
    EXPECT_EQ(a.index, b.index);
    EXPECT_NE(a.generation, b.generation);
    EXPECT_FALSE(r.alive(a));
    EXPECT_TRUE(r.alive(b));
    // The old handle sees nothing of the new occupant.
    r.emplace<Position>(b, 2.f);
    EXPECT_FALSE(r.has<Position>(a));
    EXPECT_EQ(r.tryGet<Position>(a), nullptr);
    EXPECT_FLOAT_EQ(r.get<Position>(b).x, 2.f);
    // Destroying through a stale handle is a no-op.
    r.destroy(a);
    EXPECT_TRUE(r.alive(b));
    EXPECT_TRUE(r.has<Position>(b));
}

TEST(Ecs, DestroyRemovesEveryComponent) {
    Registry r;
    const Entity a = r.create();
    r.emplace<Position>(a);
    r.emplace<Velocity>(a);
    r.destroy(a);
    EXPECT_EQ(r.count<Position>(), 0u);
    EXPECT_EQ(r.count<Velocity>(), 0u);
    EXPECT_EQ(r.aliveCount(), 0u);
}

TEST(Ecs, RemoveKeepsOtherEntitiesIntact) {
    Registry r;
    std::vector<Entity> es;
    for (int i = 0; i < 10; ++i) {
        es.push_back(r.create());
        r.emplace<Position>(es.back(), float(i));
    }
    r.remove<Position>(es[3]); // swap-with-last inside the pool
    r.remove<Position>(es[0]);
    for (int i = 0; i < 10; ++i) {
        if (i == 0 || i == 3) {
            EXPECT_FALSE(r.has<Position>(es[i]));
        } else {
            ASSERT_TRUE(r.has<Position>(es[i]));
            EXPECT_FLOAT_EQ(r.get<Position>(es[i]).x, float(i));
        }
    }
}

TEST(Ecs, ViewVisitsExactlyTheIntersection) {
    Registry r;
    std::set<std::uint32_t> expected;
    for (int i = 0; i < 100; ++i) {
        const Entity e = r.create();
        if (i % 2 == 0) r.emplace<Position>(e, float(i));
        if (i % 3 == 0) r.emplace<Velocity>(e, float(i));
        if (i % 6 == 0) expected.insert(e.index);
    }
    std::set<std::uint32_t> seen;
    r.view<const Position, const Velocity>().each([&](Entity e, const Position& p, const Velocity& v) {
        EXPECT_FLOAT_EQ(p.x, v.v); // both were set from the same i
        EXPECT_TRUE(seen.insert(e.index).second) << "visited twice";
    });
    EXPECT_EQ(seen, expected);
}

TEST(Ecs, ViewOverAlignedAndMisalignedPoolsVisitsEachMatchOnce) {
    // Pools filled in the same order are walked block-wise; removals break the alignment of
    // some blocks, which then fall back to per-entity lookups. Both must agree.
    Registry r;
    std::vector<Entity> es;
    for (int i = 0; i < 1000; ++i) {
        es.push_back(r.create());
        r.emplace<Position>(es.back(), float(i));
        r.emplace<Velocity>(es.back(), float(i));
    }
    for (int i = 100; i < 1000; i += 7) r.remove<Velocity>(es[std::size_t(i)]);
    std::vector<int> visits(1000, 0);
    r.view<const Position, const Velocity>().each([&](Entity e, const Position& p, const Velocity& v) {
        EXPECT_FLOAT_EQ(p.x, v.v);
        ++visits[e.index];
    });
    for (int i = 0; i < 1000; ++i) {
        const bool removed = i >= 100 && (i - 100) % 7 == 0;
        EXPECT_EQ(visits[std::size_t(i)], removed ? 0 : 1) << i;
    }
}

TEST(Ecs, ViewWritesThroughMutableComponents) {
    Registry r;
    for (int i = 0; i < 5; ++i) {
        const Entity e = r.create();
        r.emplace<Position>(e, float(i));
        r.emplace<Velocity>(e, 1.f);
    }
    r.view<Position, const Velocity>().each([](Position& p, const Velocity& v) { p.x += v.v; });
    float sum = 0.f;
    r.view<const Position>().each([&](const Position& p) { sum += p.x; });
    EXPECT_FLOAT_EQ(sum, 0 + 1 + 2 + 3 + 4 + 5.f);
}

TEST(Ecs, ConstComponentsAreReadOnly) {
    // A `const T` in a view yields `const T&`; a const registry only hands out const views.
    using V = View<const Position, Velocity>;
    static_assert(std::is_same_v<decltype(std::declval<V>().get<const Position>(Entity{})), const Position&>);
    static_assert(std::is_same_v<decltype(std::declval<V>().get<Velocity>(Entity{})), Velocity&>);
    Registry r;
    const Entity e = r.create();
    r.emplace<Position>(e, 3.f);
    const Registry& cr = r;
    int visits = 0;
    cr.view<const Position>().each([&](const Position& p) {
        EXPECT_FLOAT_EQ(p.x, 3.f);
        ++visits;
    });
    EXPECT_EQ(visits, 1);
    // A const view over a type nobody has created is simply empty.
    cr.view<const Tag>().each([&](const Tag&) { ++visits; });
    EXPECT_EQ(visits, 1);
}

TEST(Ecs, ChangeTrackingListsPatchedEntitiesOnce) {
    Registry r;
    const Entity a = r.create();
    const Entity b = r.create();
    const Entity c = r.create();
    for (Entity e : {a, b, c}) r.emplace<Position>(e);
    // Creation counts as a change.
    EXPECT_EQ(r.changed<Position>().size(), 3u);
    r.clearChanges();
    EXPECT_TRUE(r.changed<Position>().empty());
    EXPECT_FALSE(r.wasChanged<Position>(a));

    r.patch<Position>(b).x = 5.f;
    r.patch<Position>(b).x = 6.f; // listed once
    r.get<Position>(c).x = 1.f;   // a plain write is not tracked
    ASSERT_EQ(r.changed<Position>().size(), 1u);
    EXPECT_EQ(r.changed<Position>()[0], b);
    EXPECT_TRUE(r.wasChanged<Position>(b));
    EXPECT_FALSE(r.wasChanged<Position>(a));
    EXPECT_FALSE(r.wasChanged<Position>(c));
    // Other types are tracked separately.
    EXPECT_TRUE(r.changed<Velocity>().empty());
}

TEST(Ecs, ChangeOfDestroyedEntityIsNotReportedForItsSuccessor) {
    Registry r;
    const Entity a = r.create();
    r.emplace<Position>(a);
    r.clearChanges();
    r.patch<Position>(a);
    r.destroy(a);
    const Entity b = r.create();
    r.emplace<Position>(b);
    r.clearChanges();
    EXPECT_FALSE(r.wasChanged<Position>(b)); // same slot, new epoch: not changed
}

TEST(Ecs, ContextHoldsOneResourcePerTypePerRegistry) {
    Registry r1, r2;
    r1.ctx().emplace<Counter>(Counter{7});
    EXPECT_TRUE(r1.ctx().contains<Counter>());
    EXPECT_FALSE(r2.ctx().contains<Counter>()); // no sharing between worlds
    EXPECT_EQ(r1.ctx().get<Counter>().value, 7);
    r1.ctx().get<Counter>().value = 8;
    EXPECT_EQ(r1.ctx().find<Counter>()->value, 8);
    r1.ctx().emplaceOrReplace<Counter>(Counter{1});
    EXPECT_EQ(r1.ctx().get<Counter>().value, 1);
    r1.ctx().erase<Counter>();
    EXPECT_EQ(r1.ctx().find<Counter>(), nullptr);
}

TEST(Ecs, ContextResourceTakenOutAndAdoptedBackIsTheSameObject) {
    Registry r;
    EXPECT_EQ(r.ctx().take<Counter>(), nullptr); // nothing to take
    Counter& held = r.ctx().emplace<Counter>(Counter{3});
    const std::shared_ptr<Counter> taken = r.ctx().take<Counter>();
    ASSERT_NE(taken, nullptr);
    EXPECT_EQ(taken.get(), &held);
    EXPECT_FALSE(r.ctx().contains<Counter>());
    r.ctx().emplace<Counter>(Counter{4}); // the slot is free for another while it is out
    r.ctx().erase<Counter>();
    EXPECT_EQ(&r.ctx().adopt(taken), &held);
    EXPECT_EQ(r.ctx().get<Counter>().value, 3);
}

TEST(Ecs, ViewEntitiesSnapshotAllowsStructuralChangeAfterwards) {
    Registry r;
    for (int i = 0; i < 20; ++i) r.emplace<Position>(r.create(), float(i));
    for (Entity e : r.view<const Position>().entities())
        if (r.get<Position>(e).x >= 10.f) r.destroy(e);
    EXPECT_EQ(r.count<Position>(), 10u);
}

TEST(EcsDeathTest, StructuralChangeDuringIterationAsserts) {
    GTEST_FLAG_SET(death_test_style, "threadsafe");
    Registry r;
    for (int i = 0; i < 3; ++i) r.emplace<Position>(r.create());
    EXPECT_DEATH(r.view<Position>().each([&](Entity e, Position&) { r.destroy(e); }),
                 "being iterated");
    // Changing another pool during iteration is allowed.
    r.view<const Position>().each([&](Entity e, const Position&) { r.emplace<Velocity>(e); });
    EXPECT_EQ(r.count<Velocity>(), 3u);
}

} // namespace
} // namespace qgi
