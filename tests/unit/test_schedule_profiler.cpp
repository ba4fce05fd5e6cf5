#include "runtime/core/Error.h"
#include "runtime/ecs/Schedule.h"
#include "runtime/profile/FrameProfiler.h"

#include "components/PathFollower.h"
#include "components/Transform.h"
#include "components/WorldTransform.h"
#include "systems/animation/AnimationSystem.h"
#include "systems/transform/TransformSystem.h"

#include <glm/gtc/quaternion.hpp>
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <thread>

namespace qgi {
namespace {

std::filesystem::path scratch(const std::string& name) {
    const auto dir = std::filesystem::temp_directory_path() / "qgi_test_schedule";
    std::filesystem::create_directories(dir);
    return dir / name;
}

TEST(Schedule, RunsPhasesThenEntriesInDeclaredOrder) {
    Schedule s;
    std::vector<std::string> log;
    // Phases are declared first; entries are added out of phase order on purpose.
    s.addPhase("input").addPhase("transform").addPhase("render");
    s.add("render", "draw", [&](Registry&, const FrameContext&) { log.push_back("draw"); });
    s.add("input", "keys", [&](Registry&, const FrameContext&) { log.push_back("keys"); });
    s.add("transform", "transform", [&](Registry&, const FrameContext&) { log.push_back("transform"); });
    s.add("input", "mouse", [&](Registry&, const FrameContext&) { log.push_back("mouse"); });
    Registry r;
    s.run(r, FrameContext{});
    EXPECT_EQ(log, (std::vector<std::string>{"keys", "mouse", "transform", "draw"}));
    std::vector<std::string> names;
    for (const auto* e : s.entries()) names.push_back(e->name);
    EXPECT_EQ(names, (std::vector<std::string>{"input.keys", "input.mouse", "transform", "render.draw"}));
}

TEST(Schedule, PassesTheFrameContextThrough) {
    Schedule s;
    s.addPhase("p");
    FrameContext seen;
    s.add("p", "e", [&](Registry&, const FrameContext& f) { seen = f; });
    Registry r;
    s.run(r, FrameContext{41, 2.5, 0.25f, 1234});
    EXPECT_EQ(seen.frameIndex, 41u);
    EXPECT_DOUBLE_EQ(seen.time, 2.5);
    EXPECT_FLOAT_EQ(seen.dt, 0.25f);
    EXPECT_EQ(seen.seed, 1234u);
}

TEST(Schedule, RejectsUnknownPhasesAndDuplicates) {
    Schedule s;
    s.addPhase("a");
    auto noop = [](Registry&, const FrameContext&) {};
    EXPECT_THROW(s.add("b", "x", noop), Error);
    s.add("a", "x", noop);
    EXPECT_THROW(s.add("a", "x", noop), Error);
    EXPECT_THROW(s.addPhase("a"), Error);
}

TEST(Schedule, DisabledEntriesDoNotRun) {
    Schedule s;
    s.addPhase("a");
    int runs = 0;
    s.add("a", "x", [&](Registry&, const FrameContext&) { ++runs; });
    EXPECT_TRUE(s.setEnabled("a.x", false));
    EXPECT_FALSE(s.setEnabled("a.nope", false));
    Registry r;
    s.run(r, FrameContext{});
    EXPECT_EQ(runs, 0);
}

TEST(Schedule, AFrameThatThrowsEndsAndTheNextRuns) {
    // An entry throws: the error reaches the caller, the profiled frame is ended (the next
    // run used to abort on "beginFrame without endFrame"), and what the frame changed stays
    // marked for the entries that did not run.
    Registry r;
    r.ctx().emplace<FrameProfiler>();
    const Entity e = r.create();
    r.emplace<Transform>(e);
    Schedule s;
    s.addPhase("work").addPhase("late");
    bool fail = true;
    std::size_t changesSeenLate = 0;
    s.add("work", "mover", [&](Registry& reg, const FrameContext&) {
        reg.patch<Transform>(e);
        if (fail) throw Error("boom");
    });
    s.add("late", "watcher", [&](Registry& reg, const FrameContext&) {
        changesSeenLate = reg.changed<Transform>().size();
    });
    EXPECT_THROW(s.run(r, FrameContext{0, 0.0, 0.f, 0}), Error);
    EXPECT_EQ(r.changed<Transform>().size(), 1u);
    fail = false;
    EXPECT_NO_THROW(s.run(r, FrameContext{1, 0.0, 0.f, 0}));
    EXPECT_EQ(changesSeenLate, 1u);
    EXPECT_TRUE(r.changed<Transform>().empty());
}

TEST(Schedule, ChangesAreVisibleLaterInTheFrameAndClearedAfter) {
    Registry r;
    const Entity e = r.create();
    r.emplace<Transform>(e);
    r.emplace<PathFollower>(e, PathFollower{{{0.f, glm::vec3(0.f)}, {1.f, glm::vec3(1.f, 0.f, 0.f)}}, false});
    Schedule s;
    s.addPhase("animation").addPhase("transform").addPhase("check");
    AnimationSystem animation;
    TransformSystem transforms;
    s.add("animation", "animation", [&](Registry& reg, const FrameContext& f) { animation.update(reg, f); });
    s.add("transform", "transform", [&](Registry& reg, const FrameContext& f) { transforms.update(reg, f); });
    std::size_t movedSeen = 0;
    s.add("check", "check", [&](Registry& reg, const FrameContext&) { movedSeen = reg.changed<WorldTransform>().size(); });

    s.run(r, FrameContext{0, 0.5, 0.5f, 0});
    EXPECT_EQ(movedSeen, 1u);
    EXPECT_FLOAT_EQ(r.get<WorldTransform>(e).matrix[3].x, 0.5f);
    EXPECT_TRUE(r.changed<Transform>().empty()); // cleared at the end of the frame

    // Past the end of a non-looping path the pose holds: nothing moves any more.
    s.run(r, FrameContext{1, 2.0, 1.5f, 0});
    EXPECT_EQ(movedSeen, 1u);
    s.run(r, FrameContext{2, 3.0, 1.0f, 0});
    EXPECT_EQ(movedSeen, 0u);
    EXPECT_FLOAT_EQ(r.get<WorldTransform>(e).matrix[3].x, 1.f);
}

TEST(Transform, ChildFollowsItsParent) {
    Registry r;
    const Entity parent = r.create();
    const Entity child = r.create();
    r.emplace<Transform>(parent, Transform{glm::vec3(1.f, 0.f, 0.f)});
    Transform local;
    local.translation = glm::vec3(0.f, 2.f, 0.f);
    local.parent = parent;
    r.emplace<Transform>(child, local);
    TransformSystem system;
    system.update(r, FrameContext{});
    EXPECT_EQ(glm::vec3(r.get<WorldTransform>(child).matrix[3]), glm::vec3(1.f, 2.f, 0.f));
    r.clearChanges();
    // Rotating the parent by 90 degrees about Z carries the child to (-2 + 1, 0, 0).
    r.patch<Transform>(parent).rotation = glm::angleAxis(glm::half_pi<float>(), glm::vec3(0, 0, 1));
    system.update(r, FrameContext{});
    const glm::vec3 p = r.get<WorldTransform>(child).matrix[3];
    EXPECT_NEAR(p.x, -1.f, 1e-6f);
    EXPECT_NEAR(p.y, 0.f, 1e-6f);
    EXPECT_TRUE(r.wasChanged<WorldTransform>(child));
}

TEST(Animation, LoopingPathWrapsAndOffsetShiftsIt) {
    // Keys at 1, 2 and 3 s: x goes 0 -> 2 -> 4. A loop spans [1, 3), 2 s.
    PathFollower path{
        {{1.f, glm::vec3(0.f)}, {2.f, glm::vec3(2.f, 0.f, 0.f)}, {3.f, glm::vec3(4.f, 0.f, 0.f)}},
        true};
    const auto xAt = [&](double t) {
        Transform pose;
        samplePath(path, t, pose);
        return pose.translation.x;
    };
    EXPECT_FLOAT_EQ(xAt(1.5), 1.f);
    EXPECT_FLOAT_EQ(xAt(2.5), 3.f);
    EXPECT_FLOAT_EQ(xAt(3.5), 1.f);   // 3.5 wraps to 1.5
    EXPECT_FLOAT_EQ(xAt(8.25), 2.5f); // 8.25 = 1 + 3 loops + 1.25
    EXPECT_FLOAT_EQ(xAt(0.5), 3.f);   // before the first key: 0.5 wraps back to 2.5
    path.timeOffset = 0.5f;
    EXPECT_FLOAT_EQ(xAt(1.5), 2.f); // samples 2.0
    EXPECT_FLOAT_EQ(xAt(3.0), 1.f); // samples 3.5, which wraps to 1.5
    // Without the loop the ends hold.
    path.loop = false;
    path.timeOffset = 0.f;
    EXPECT_FLOAT_EQ(xAt(0.f), 0.f);
    EXPECT_FLOAT_EQ(xAt(9.f), 4.f);
}

TEST(Animation, TimesThatAreNoNumberLeaveThePoseAndKeysOutOfOrderAreNotReadPast) {
    // NaN (a game's bad clock), or infinity on a loop (fmod gives NaN): the pose stays as it
    // was; before, the key search read past the last key.
    PathFollower path{
        {{1.f, glm::vec3(0.f)}, {2.f, glm::vec3(2.f, 0.f, 0.f)}, {3.f, glm::vec3(4.f, 0.f, 0.f)}},
        true};
    const glm::vec3 before(7.f, 8.f, 9.f);
    for (const double t :
         {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
        Transform pose;
        pose.translation = before;
        samplePath(path, t, pose);
        EXPECT_EQ(pose.translation, before) << t;
    }
    // Without the loop an infinite time holds the last key.
    path.loop = false;
    Transform pose;
    samplePath(path, std::numeric_limits<double>::infinity(), pose);
    EXPECT_EQ(pose.translation, glm::vec3(4.f, 0.f, 0.f));
    // Keys a game wrote out of order, or with a NaN time: a pose between two of its keys.
    path.keys[1].time = 5.f;
    path.keys[2].time = std::numeric_limits<float>::quiet_NaN();
    for (const double t : {1.5, 2.5, 4.0, 6.0}) {
        samplePath(path, t, pose);
        EXPECT_GE(pose.translation.x, 0.f) << t;
        EXPECT_LE(pose.translation.x, 4.f) << t;
    }
}

TEST(Animation, RotationIsSlerpedAtConstantAngularSpeed) {
    // Identity to 120 degrees about y over 1 s: at 0.25 s, 30 degrees about y (a linear blend
    // of the quaternions would give about 26 degrees).
    const glm::vec3 y(0.f, 1.f, 0.f);
    const PathFollower path{{{0.f, glm::vec3(0.f), glm::quat(1.f, 0.f, 0.f, 0.f)},
                             {1.f, glm::vec3(0.f), glm::angleAxis(glm::radians(120.f), y)}},
                            false};
    Transform pose;
    samplePath(path, 0.25, pose);
    EXPECT_NEAR(glm::degrees(glm::angle(pose.rotation)), 30.f, 1e-3f);
    EXPECT_NEAR(glm::dot(glm::axis(pose.rotation), y), 1.f, 1e-5f);
    EXPECT_NEAR(glm::length(pose.rotation), 1.f, 1e-6f);
}

TEST(Transform, ParentScaleAndMissingParentsAndCycles) {
    Registry r;
    // The parent's scale stretches the child's offset.
    const Entity parent = r.create();
    Transform parentPose;
    parentPose.scale = glm::vec3(2.f, 3.f, 4.f);
    r.emplace<Transform>(parent, parentPose);
    const Entity child = r.create();
    Transform childPose;
    childPose.translation = glm::vec3(1.f, 1.f, 1.f);
    childPose.parent = parent;
    r.emplace<Transform>(child, childPose);
    // A parent without a Transform (or one destroyed) leaves the child at its own pose.
    const Entity bare = r.create();
    const Entity orphan = r.create();
    Transform orphanPose;
    orphanPose.translation = glm::vec3(5.f, 0.f, 0.f);
    orphanPose.parent = bare;
    r.emplace<Transform>(orphan, orphanPose);
    // A cycle (which the importer refuses) must not hang the frame: its members are placed as
    // roots, and the loop is named once.
    const Entity a = r.create(), b = r.create();
    Transform cyclic;
    cyclic.translation = glm::vec3(0.f, 1.f, 0.f);
    cyclic.parent = b;
    r.emplace<Transform>(a, cyclic);
    cyclic.parent = a;
    r.emplace<Transform>(b, cyclic);

    TransformSystem system;
    ::testing::internal::CaptureStderr();
    system.update(r, FrameContext{});
    r.patch<Transform>(a).translation.y = 2.f;
    system.update(r, FrameContext{});
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(glm::vec3(r.get<WorldTransform>(child).matrix[3]), glm::vec3(2.f, 3.f, 4.f));
    EXPECT_EQ(glm::vec3(r.get<WorldTransform>(orphan).matrix[3]), glm::vec3(5.f, 0.f, 0.f));
    EXPECT_EQ(glm::vec3(r.get<WorldTransform>(a).matrix[3]), glm::vec3(0.f, 2.f, 0.f));
    EXPECT_EQ(glm::vec3(r.get<WorldTransform>(b).matrix[3]), glm::vec3(0.f, 1.f, 0.f));
    EXPECT_NE(log.find("loops"), std::string::npos) << log;
    EXPECT_EQ(log.find("loops"), log.rfind("loops")) << log;
}

TEST(Profiler, TimesEveryScheduleEntry) {
    Registry r;
    auto& profiler = r.ctx().emplace<FrameProfiler>();
    Schedule s;
    s.addPhase("work");
    s.add("work", "sleep", [](Registry&, const FrameContext&) {
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    });
    s.add("work", "nothing", [](Registry&, const FrameContext&) {});
    for (std::uint64_t f = 0; f < 5; ++f) s.run(r, FrameContext{f, 0.0, 0.f, 0});
    ASSERT_EQ(profiler.frameCount(), 5u);
    for (std::size_t f = 0; f < 5; ++f) {
        // A sleep lasts at least what was asked; the entry's time cannot be shorter.
        EXPECT_GE(profiler.sampleMs(f, "work.sleep"), 2.0);
        EXPECT_GE(profiler.sampleMs(f, "work.nothing"), 0.0);
        EXPECT_LT(profiler.sampleMs(f, "work.nothing"), profiler.sampleMs(f, "work.sleep"));
    }
    const auto stats = profiler.statistics();
    ASSERT_EQ(stats.size(), 3u); // frame, work.sleep, work.nothing
    EXPECT_EQ(stats[0].name, "frame");
    EXPECT_EQ(stats[1].name, "work.sleep");
    EXPECT_EQ(stats[1].count, 5u);
    EXPECT_GE(stats[1].mean, 2.0);
    EXPECT_LE(stats[1].p50, stats[1].p95);
    EXPECT_LE(stats[1].p95, stats[1].p99);
    EXPECT_LE(stats[1].p99, stats[1].max);
    EXPECT_GE(stats[0].mean, stats[1].mean); // a frame contains its entries
}

TEST(Profiler, PercentilesUseNearestRank) {
    FrameProfiler p;
    for (std::uint64_t f = 0; f < 100; ++f) {
        p.beginFrame(f);
        p.recordSample("x", f, -1.0, double(f + 1), FrameProfiler::Track::Gpu); // 1..100 ms
        p.endFrame();
    }
    const auto stats = p.statistics();
    const auto& x = stats[1];
    EXPECT_EQ(x.name, "x");
    EXPECT_DOUBLE_EQ(x.mean, 50.5);
    EXPECT_DOUBLE_EQ(x.p50, 50.0);
    EXPECT_DOUBLE_EQ(x.p95, 95.0);
    EXPECT_DOUBLE_EQ(x.p99, 99.0);
    EXPECT_DOUBLE_EQ(x.max, 100.0);
}

TEST(Profiler, LateGpuSamplesLandInTheirFrame) {
    FrameProfiler p;
    for (std::uint64_t f = 0; f < 4; ++f) {
        p.beginFrame(f);
        p.endFrame();
    }
    p.recordSample("gpu.draw", 1, -1.0, 3.0, FrameProfiler::Track::Gpu);
    EXPECT_DOUBLE_EQ(p.sampleMs(1, "gpu.draw"), 3.0);
    EXPECT_LT(p.sampleMs(2, "gpu.draw"), 0.0);
    p.recordSample("gpu.draw", 99, -1.0, 3.0, FrameProfiler::Track::Gpu); // unknown frame: dropped
    EXPECT_EQ(p.statistics()[1].count, 1u);
}

TEST(Profiler, AFramesSamplesComeInTheOrderTheyFirstRanSummedPerEntry) {
    FrameProfiler p;
    p.beginFrame(0);
    p.endFrame();
    p.recordSample("photons", 0, -1.0, 2.0, FrameProfiler::Track::Cpu);
    p.recordSample("render", 0, -1.0, 5.0, FrameProfiler::Track::Gpu);
    p.recordSample("photons", 0, -1.0, 0.5, FrameProfiler::Track::Cpu); // ran twice
    const auto samples = p.frameSamples(0);
    ASSERT_EQ(samples.size(), 2u);
    EXPECT_EQ(samples[0].first, "photons");
    EXPECT_DOUBLE_EQ(samples[0].second, 2.5);
    EXPECT_EQ(samples[1].first, "render");
    EXPECT_DOUBLE_EQ(samples[1].second, 5.0);
    EXPECT_TRUE(p.frameSamples(1).empty());
    EXPECT_GE(p.frameMs(0), 0.0);
    EXPECT_LT(p.frameMs(1), 0.0);
}

TEST(Profiler, NestedScopesGetQualifiedNames) {
    FrameProfiler p;
    p.beginFrame(0);
    {
        FrameProfiler::Scope outer(&p, "render");
        FrameProfiler::Scope inner(&p, "shadows");
    }
    p.endFrame();
    EXPECT_GE(p.sampleMs(0, "render/shadows"), 0.0);
    EXPECT_GE(p.sampleMs(0, "render"), p.sampleMs(0, "render/shadows"));
}

TEST(Profiler, ChromeTraceIsValidJsonWithOneEventPerSample) {
    FrameProfiler p;
    for (std::uint64_t f = 0; f < 3; ++f) {
        p.beginFrame(f);
        { FrameProfiler::Scope s(&p, "a \"quoted\" name"); }
        p.recordSample("gpu", f, -1.0, 1.0, FrameProfiler::Track::Gpu);
        p.endFrame();
    }
    const auto path = scratch("trace.json");
    p.writeChromeTrace(path);
    std::ifstream in(path);
    const auto json = nlohmann::json::parse(in); // throws on invalid JSON
    const auto& events = json.at("traceEvents");
    int complete = 0, gpu = 0;
    for (const auto& e : events) {
        if (e.at("ph") == "X") {
            ++complete;
            EXPECT_GE(e.at("dur").get<double>(), 0.0);
            EXPECT_TRUE(e.contains("ts"));
            if (e.at("tid") == 2) ++gpu;
        }
    }
    EXPECT_EQ(complete, 3 * 3); // per frame: the frame itself, the CPU scope, the GPU sample
    EXPECT_EQ(gpu, 3);
}

TEST(Profiler, CsvHasOneRowPerFrameAndOneColumnPerEntry) {
    FrameProfiler p;
    for (std::uint64_t f = 0; f < 4; ++f) {
        p.beginFrame(f);
        { FrameProfiler::Scope s(&p, "always"); }
        if (f % 2 == 0) {
            FrameProfiler::Scope s(&p, "sometimes");
        }
        p.endFrame();
    }
    const auto path = scratch("profile.csv");
    p.writeCsv(path);
    std::ifstream in(path);
    std::string line;
    std::getline(in, line);
    EXPECT_EQ(line, "frame,frame_ms,always_ms,sometimes_ms");
    int rows = 0;
    while (std::getline(in, line)) {
        std::vector<std::string> cells;
        std::stringstream ss(line);
        std::string cell;
        while (std::getline(ss, cell, ',')) cells.push_back(cell);
        if (line.back() == ',') cells.emplace_back();
        ASSERT_EQ(cells.size(), 4u) << line;
        EXPECT_EQ(std::stoi(cells[0]), rows);
        EXPECT_GE(std::stod(cells[1]), std::stod(cells[2]));
        EXPECT_EQ(cells[3].empty(), rows % 2 == 1); // empty where the entry did not run
        ++rows;
    }
    EXPECT_EQ(rows, 4);
}

TEST(Profiler, SummaryTableListsEveryEntry) {
    FrameProfiler p;
    p.beginFrame(0);
    { FrameProfiler::Scope s(&p, "photon.update"); }
    p.endFrame();
    const std::string table = p.summaryTable();
    EXPECT_NE(table.find("p95 ms"), std::string::npos);
    EXPECT_NE(table.find("photon.update"), std::string::npos);
    EXPECT_NE(table.find("frame"), std::string::npos);
}

TEST(Profiler, UnwritablePathThrows) {
    FrameProfiler p;
    EXPECT_THROW(p.writeCsv("/nonexistent-dir/x.csv"), Error);
    EXPECT_THROW(p.writeChromeTrace("/nonexistent-dir/x.json"), Error);
}

} // namespace
} // namespace qgi
