// FrameSchedule as game code meets it: a scene built in code, a schedule rebuilt after meshes
// were added, meshes that change under a running schedule, the wrong registry.
#include "systems/frame/FrameSchedule.h"

#include "components/Avatar.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointLight.h"
#include "components/ShLighting.h"
#include "components/StaticMesh.h"
#include "components/Transform.h"
#include "components/VertexIrradiance.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/MeshProcessing.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonStore.h"

#include "test_meshes.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

namespace qgi {
namespace {

using ::testing::HasSubstr;

FrameSettings lightingOnly() {
    FrameSettings settings;
    settings.render.reset();
    settings.photons->photonCount = 20'000;
    return settings;
}

/// A mesh entity as game code makes one: Mesh (refined), Material, Transform and a mobility
/// tag; no WorldTransform.
Entity addMesh(Registry& registry, const Mesh& mesh, const glm::vec3& at, bool mobile) {
    const Entity e = registry.create();
    MeshProcessingOptions refine;
    refine.maxEdgeLength = 0.25f;
    registry.emplace<Mesh>(e, processMesh(mesh, refine));
    registry.emplace<Material>(e, Material{});
    registry.emplace<Transform>(e, Transform{at});
    if (mobile)
        registry.emplace<MobileMesh>(e);
    else
        registry.emplace<StaticMesh>(e);
    return e;
}

/// A 2 x 2 m floor under a lamp; the table, when asked for, stands on it under the lamp.
struct Room {
    Registry registry;
    Entity floor, lamp, table;

    Room() {
        floor = addMesh(registry,
                        test::gridMesh({-1.f, 0.f, -1.f}, {0.f, 0.f, 2.f}, {2.f, 0.f, 0.f}, 1),
                        glm::vec3(0.f), false);
        lamp = registry.create();
        registry.emplace<Transform>(lamp, Transform{{0.f, 1.5f, 0.f}});
        registry.emplace<PointLight>(lamp, PointLight{glm::vec3(1.f), 5.f});
    }
    void addTable() {
        table = addMesh(registry, test::boxMesh({0.3f, 0.02f, 0.3f}), {0.f, 0.5f, 0.f}, true);
    }
    const std::vector<glm::vec3>& floorLight() const {
        return registry.get<VertexIrradiance>(floor).irradiance;
    }
};

void runFrames(FrameSchedule& frame, Registry& registry, int frames) {
    for (int f = 0; f < frames; ++f) {
        frame.run(registry, FrameContext{std::uint64_t(f), f / 60.0, 1.f / 60.f, 0});
        registry.clearChanges();
    }
}

/// The warnings `frames` frames of `frame` write to stderr (information lines left out), after
/// `edit` ran before each.
template <typename Edit>
std::string warningsOf(FrameSchedule& frame, Registry& registry, int frames, Edit&& edit) {
    ::testing::internal::CaptureStderr();
    for (int f = 0; f < frames; ++f) {
        edit();
        runFrames(frame, registry, 1);
    }
    const std::string all = ::testing::internal::GetCapturedStderr();
    std::string warnings;
    for (std::size_t begin = 0; begin < all.size();) {
        const std::size_t end = std::min(all.find('\n', begin), all.size());
        const std::string line = all.substr(begin, end - begin);
        if (line.find("warning:") != std::string::npos) warnings += line + "\n";
        begin = end + 1;
    }
    return warnings;
}

/// `text` holds `what` exactly once.
::testing::AssertionResult once(const std::string& text, const std::string& what) {
    const std::size_t first = text.find(what);
    if (first == std::string::npos)
        return ::testing::AssertionFailure() << "no '" << what << "' in: " << text;
    if (text.find(what, first + 1) != std::string::npos)
        return ::testing::AssertionFailure() << "'" << what << "' more than once in: " << text;
    return ::testing::AssertionSuccess();
}

TEST(FrameSchedule, LightsASceneBuiltInCodeWithoutWorldTransformsOrSceneInfo) {
    Room room;
    room.addTable();
    const Entity avatar =
        addMesh(room.registry, test::boxMesh(glm::vec3(0.1f)), {0.6f, 0.1f, 0.f}, false);
    room.registry.remove<StaticMesh>(avatar);
    room.registry.emplace<Avatar>(avatar, Avatar{0.1f});
    FrameSchedule frame(room.registry, lightingOnly());
    runFrames(frame, room.registry, 2);

    const SceneInfo& info = room.registry.ctx().get<SceneInfo>();
    EXPECT_EQ(info.source, "code");
    EXPECT_FLOAT_EQ(info.bounds.min.x, -1.f);
    EXPECT_FLOAT_EQ(info.bounds.max.x, 1.f);
    EXPECT_LE(info.maxEdgeLength, 0.25f * 1.0001f);
    EXPECT_GT(info.maxEdgeLength, 0.f);
    // The floor is lit (finite, not negative), and so is the avatar.
    const auto& floor = room.floorLight();
    ASSERT_FALSE(floor.empty());
    for (const glm::vec3& e : floor)
        ASSERT_TRUE(std::isfinite(e.x) && e.x >= 0.f);
    float total = 0.f;
    for (const glm::vec3& e : floor)
        total += e.x;
    EXPECT_GT(total, 0.f);
    const ShLighting* sh = room.registry.tryGet<ShLighting>(avatar);
    ASSERT_NE(sh, nullptr);
    EXPECT_GT(sh->coefficients[0].x, 0.f);
}

TEST(FrameSchedule, ANewScheduleTracesMeshesAddedSinceTheLastOne) {
    // The table added after the first schedule shadows the floor once a new schedule is built,
    // exactly as in a room that had it from the start.
    Room grown;
    {
        FrameSchedule first(grown.registry, lightingOnly());
        runFrames(first, grown.registry, 1);
    }
    grown.addTable();
    FrameSchedule second(grown.registry, lightingOnly());
    runFrames(second, grown.registry, 1);

    Room fresh;
    fresh.addTable();
    FrameSchedule only(fresh.registry, lightingOnly());
    runFrames(only, fresh.registry, 1);

    ASSERT_EQ(grown.floorLight().size(), fresh.floorLight().size());
    EXPECT_EQ(std::memcmp(grown.floorLight().data(), fresh.floorLight().data(),
                          fresh.floorLight().size() * sizeof(glm::vec3)),
              0);
}

TEST(FrameSchedule, APooledMobileTakenOutAndPutBackIsFollowedWithoutANewSchedule) {
    // The table is a pooled object: MobileMesh::active takes it out of the light and puts it
    // back frame by frame, with no warning and no new schedule. (Exactness against full
    // recomputes is the systems' own tests; this is the schedule's wiring.)
    Room room;
    room.addTable();
    FrameSchedule frame(room.registry, lightingOnly());
    runFrames(frame, room.registry, 1);
    const std::vector<glm::vec3> shaded = room.floorLight();
    const auto tableDark = [&] {
        const auto& light = room.registry.get<VertexIrradiance>(room.table).irradiance;
        return std::all_of(light.begin(), light.end(),
                           [](const glm::vec3& e) { return e == glm::vec3(0.f); });
    };
    ASSERT_FALSE(tableDark());

    const std::string log = warningsOf(frame, room.registry, 1, [&] {
        room.registry.patch<MobileMesh>(room.table).active = false;
    });
    EXPECT_EQ(log, "");
    const PhotonDelta& delta = room.registry.ctx().get<PhotonDelta>();
    EXPECT_FALSE(delta.full);
    EXPECT_GT(delta.paths.size(), 0u);
    EXPECT_TRUE(tableDark());
    // Its shadow went: the floor under it (within 0.2 m of its centre) is brighter everywhere.
    const Mesh& floor = room.registry.get<Mesh>(room.floor);
    const std::vector<glm::vec3> open = room.floorLight();
    std::vector<std::size_t> under;
    for (std::size_t v = 0; v < floor.positions.size(); ++v)
        if (glm::length(glm::vec2(floor.positions[v].x, floor.positions[v].z)) < 0.2f) {
            under.push_back(v);
            EXPECT_GT(open[v].x, shaded[v].x) << "floor vertex " << v;
        }
    EXPECT_GT(under.size(), 2u);

    // Back in: the shadow is back. A shadow left out would differ by the whole contrast, so a
    // thousandth of it tells the two apart (that the incremental sums equal a full estimate
    // to their rounding is test_photon_update's and test_detp's).
    room.registry.patch<MobileMesh>(room.table).active = true;
    runFrames(frame, room.registry, 1);
    EXPECT_FALSE(tableDark());
    for (const std::size_t v : under)
        EXPECT_NEAR(room.floorLight()[v].x, shaded[v].x, 1e-3f * (open[v].x - shaded[v].x))
            << "floor vertex " << v;
}

TEST(FrameSchedule, ASwitchWrittenWithoutPatchIsFollowedAndNamedOnce) {
    Room room;
    room.addTable();
    FrameSchedule frame(room.registry, lightingOnly());
    runFrames(frame, room.registry, 1);
    const std::string log = warningsOf(frame, room.registry, 3, [&] {
        MobileMesh& table = room.registry.get<MobileMesh>(room.table); // a plain write
        table.active = !table.active;
    });
    EXPECT_TRUE(once(log, "written without patch"));
    // Three switches: the table is out, and the ray scene and the irradiance agree.
    EXPECT_FALSE(room.registry.ctx().get<RayScene>().mobileActive(room.table));
    const auto& light = room.registry.get<VertexIrradiance>(room.table).irradiance;
    EXPECT_TRUE(std::all_of(light.begin(), light.end(),
                            [](const glm::vec3& e) { return e == glm::vec3(0.f); }));
}

TEST(FrameSchedule, APooledMobileWaitingFarAwayIsNotPartOfTheScene) {
    Room room;
    room.addTable();
    room.registry.patch<Transform>(room.table).translation = {0.f, -500.f, 0.f};
    room.registry.get<MobileMesh>(room.table).active = false;
    FrameSchedule frame(room.registry, lightingOnly());
    const SceneInfo& info = room.registry.ctx().get<SceneInfo>();
    EXPECT_FLOAT_EQ(info.bounds.min.y, 0.f); // the floor's
    EXPECT_FLOAT_EQ(info.bounds.max.y, 0.f);
}

TEST(FrameSchedule, MeshesThatComeOrGoUnderARunningScheduleAreNamedOnce) {
    const auto nothing = [] {};
    Room room;
    room.addTable();
    FrameSchedule frame(room.registry, lightingOnly());
    EXPECT_EQ(warningsOf(frame, room.registry, 2, nothing), "");
    room.registry.destroy(room.table);
    const std::string log = warningsOf(frame, room.registry, 3, nothing);
    EXPECT_TRUE(once(log, "was destroyed"));
    EXPECT_THAT(log, HasSubstr("new FrameSchedule"));

    Room other;
    FrameSchedule added(other.registry, lightingOnly());
    other.addTable();
    EXPECT_TRUE(
        once(warningsOf(added, other.registry, 2, nothing), "1 mobile meshes where there were"));
}

TEST(FrameSchedule, MovingAStaticMeshOrEditingAMeshIsNamedOnce) {
    Room room;
    room.addTable();
    room.registry.emplace<Name>(room.floor, "floor");
    FrameSchedule frame(room.registry, lightingOnly());
    runFrames(frame, room.registry, 1);
    // Mobiles may move: no warning.
    EXPECT_EQ(warningsOf(frame, room.registry, 2,
                         [&] { room.registry.patch<Transform>(room.table).translation.x += 0.1f; }),
              "");
    const std::string log = warningsOf(frame, room.registry, 3, [&] {
        room.registry.patch<Transform>(room.floor).translation.y += 0.1f;
    });
    EXPECT_TRUE(once(log, "static mesh 'floor' moved"));
    EXPECT_THAT(log, HasSubstr("MobileMesh"));

    Room edited;
    edited.addTable();
    FrameSchedule other(edited.registry, lightingOnly());
    runFrames(other, edited.registry, 1);
    EXPECT_TRUE(
        once(warningsOf(other, edited.registry, 2,
                        [&] { edited.registry.patch<Mesh>(edited.table).positions[0].y += 0.01f; }),
             "the Mesh of entity"));
}

TEST(FrameSchedule, PhotonAndHybridModeSettingsMustAgree) {
    const FrameSettings defaults;
    EXPECT_FALSE(defaults.irradiance.hybrid);
    EXPECT_FALSE(defaults.probes->hybrid);
    EXPECT_EQ(defaults.render->mode, ShadingMode::Photon);

    Room room;
    ::testing::internal::CaptureStderr();
    { FrameSchedule agreeing(room.registry, lightingOnly()); }
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(log.find("hybrid is"), std::string::npos) << log;
    FrameSettings mixed = lightingOnly();
    mixed.irradiance.hybrid = true; // the probes still count direct light from photons
    ::testing::internal::CaptureStderr();
    { FrameSchedule disagreeing(room.registry, mixed); }
    EXPECT_TRUE(once(::testing::internal::GetCapturedStderr(), "irradiance.hybrid is on"));
}

TEST(FrameScheduleDeathTest, RunningAnotherRegistryNamesTheMistake) {
    Room room, other;
    FrameSchedule frame(room.registry, lightingOnly());
    EXPECT_DEATH(frame.run(other.registry, FrameContext{}), "other than the one it was built for");
}

} // namespace
} // namespace qgi
