#include "runtime/math/Pose.h"
#include "runtime/raytrace/RayScene.h"

#include "components/Avatar.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/EmbreeDevice.h"

#include <gmock/gmock.h>
#include "test_meshes.h"

#include <gtest/gtest.h>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/mat4x4.hpp>

#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <set>
#include <vector>

namespace qgi {
namespace {

using ::testing::HasSubstr;

constexpr float kInf = std::numeric_limits<float>::infinity();
const glm::mat4 kIdentity{1.f};

glm::mat4 translation(float x, float y, float z) {
    return glm::translate(kIdentity, glm::vec3(x, y, z));
}

/// Two triangles over [x0, x1] x [y0, y1] at z = 0, facing +z: {0,1,2} below the diagonal
/// (0,0)-(1,1) corner to corner, {0,2,3} above it.
Mesh quad(float x0, float y0, float x1, float y1) {
    Mesh mesh;
    mesh.positions = {{x0, y0, 0.f}, {x1, y0, 0.f}, {x1, y1, 0.f}, {x0, y1, 0.f}};
    mesh.indices = {0, 1, 2, 0, 2, 3};
    return mesh;
}

enum class Mobility { Static, Mobile };

Entity addMesh(Registry& registry, Mesh mesh, const glm::mat4& world, Mobility mobility,
               const char* name = "mesh") {
    const Entity e = registry.create();
    registry.emplace<Name>(e, name);
    registry.emplace<Mesh>(e, std::move(mesh));
    registry.emplace<WorldTransform>(e, world);
    if (mobility == Mobility::Static)
        registry.emplace<StaticMesh>(e);
    else
        registry.emplace<MobileMesh>(e);
    return e;
}

/// Moves a mobile the way the transform system does: a patch recorded in the change list.
void moveTo(Registry& registry, Entity e, const glm::mat4& world) {
    registry.patch<WorldTransform>(e).matrix = world;
}

Ray ray(glm::vec3 origin, glm::vec3 direction, float tfar = kInf, float tnear = 0.f) {
    return Ray{origin, tnear, direction, tfar};
}

// ---- an independent reference: every triangle in world space, tested in double precision ----

struct WorldTriangle {
    Entity entity;
    std::uint32_t primitive;
    glm::dvec3 p0, p1, p2;
};

std::vector<WorldTriangle> worldTriangles(const Registry& registry) {
    std::vector<WorldTriangle> out;
    const auto add = [&](Entity e) {
        const Mesh& mesh = registry.get<Mesh>(e);
        const glm::dmat4 world(registry.get<WorldTransform>(e).matrix);
        const auto at = [&](std::uint32_t i) {
            return glm::dvec3(world * glm::dvec4(glm::dvec3(mesh.positions[i]), 1.0));
        };
        for (std::uint32_t p = 0; p < mesh.indices.size() / 3; ++p)
            out.push_back({e, p, at(mesh.indices[3 * p]), at(mesh.indices[3 * p + 1]),
                           at(mesh.indices[3 * p + 2])});
    };
    registry.view<const StaticMesh>().each([&](Entity e, const StaticMesh&) { add(e); });
    registry.view<const MobileMesh>().each([&](Entity e, const MobileMesh&) { add(e); });
    return out;
}

struct ReferenceHit {
    double t;
    Entity entity;
    std::uint32_t primitive;
};

/// Möller-Trumbore against every triangle: the closest hit with tnear <= t <= tfar.
std::optional<ReferenceHit> bruteForce(const std::vector<WorldTriangle>& triangles, const Ray& r) {
    const glm::dvec3 o(r.origin), d(r.direction);
    std::optional<ReferenceHit> best;
    for (const WorldTriangle& tri : triangles) {
        const glm::dvec3 e1 = tri.p1 - tri.p0, e2 = tri.p2 - tri.p0;
        const glm::dvec3 p = glm::cross(d, e2);
        const double det = glm::dot(e1, p);
        if (std::abs(det) < 1e-300) continue;
        const glm::dvec3 s = o - tri.p0;
        const double u = glm::dot(s, p) / det;
        const glm::dvec3 q = glm::cross(s, e1);
        const double v = glm::dot(d, q) / det;
        const double t = glm::dot(e2, q) / det;
        if (u < 0 || v < 0 || u + v > 1 || t < r.tnear || t > r.tfar) continue;
        if (!best || t < best->t) best = ReferenceHit{t, tri.entity, tri.primitive};
    }
    return best;
}

/// A closed room with static furniture and two rotated, scaled mobiles.
struct Clutter {
    Registry registry;
    Entity room, table, pillar, crate, door;

    Clutter() {
        room = addMesh(registry, test::boxMesh({5.f, 5.f, 5.f}, true), kIdentity, Mobility::Static, "room");
        table = addMesh(registry, test::boxMesh({1.5f, 0.1f, 1.f}), translation(1.f, -1.f, 0.5f),
                        Mobility::Static, "table");
        pillar = addMesh(registry, test::boxMesh({0.3f, 5.f, 0.3f}), translation(-3.f, 0.f, 2.f),
                         Mobility::Static, "pillar");
        crate = addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}),
                        glm::rotate(translation(-1.f, -4.f, -2.f), 0.6f, glm::vec3(0, 1, 0)),
                        Mobility::Mobile, "crate");
        door = addMesh(registry, test::boxMesh({1.f, 2.f, 0.05f}),
                       glm::scale(glm::rotate(translation(3.f, -2.f, -3.f), 1.1f,
                                              glm::normalize(glm::vec3(0.2f, 1.f, 0.1f))),
                                  glm::vec3(1.f, 1.2f, 0.8f)),
                       Mobility::Mobile, "door");
    }
};

/// Random rays: origins in [-7, 7]^3 (some outside the room, so some miss), uniform
/// directions, every third ray limited to a random tfar, every fifth one starting at tnear > 0.
std::vector<Ray> randomRays(std::size_t count, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> position(-7.f, 7.f), unit(0.f, 1.f);
    std::normal_distribution<float> gauss;
    std::vector<Ray> rays(count);
    for (std::size_t i = 0; i < count; ++i) {
        Ray& r = rays[i];
        r.origin = {position(rng), position(rng), position(rng)};
        do
            r.direction = {gauss(rng), gauss(rng), gauss(rng)};
        while (glm::length(r.direction) < 1e-3f);
        r.direction = glm::normalize(r.direction);
        if (i % 3 == 0) r.tfar = 4.f * unit(rng);
        if (i % 5 == 0) r.tnear = 0.5f * unit(rng);
    }
    return rays;
}

// ---- closest hit on geometry computed by hand ----------------------------------------------

TEST(RayScene, ClosestHitMatchesHandComputation) {
    Registry registry;
    // Quad [0,2]^2 moved to z = -3, x and y shifted by 1.
    const Entity wall =
        addMesh(registry, quad(0.f, 0.f, 2.f, 2.f), translation(1.f, 1.f, -3.f), Mobility::Static);
    RayScene scene;
    scene.build(registry);
    EXPECT_EQ(scene.staticTriangleCount(), 2u);

    // World point (1.5, 2.5, -3) is object point (0.5, 1.5, 0): above the diagonal, triangle 1
    // = corners (0,0), (2,2), (0,2), so (0.5, 1.5) = u (2,2) + v (0,2): u = 0.25, v = 0.5.
    // A direction of length 2 halves the ray parameter: t = 5 / 2.
    const std::optional<Hit> hit = scene.intersect(ray({1.5f, 2.5f, 2.f}, {0.f, 0.f, -2.f}));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->entity, wall);
    EXPECT_EQ(hit->primitive, 1u);
    EXPECT_NEAR(hit->t, 2.5f, 1e-6f);
    EXPECT_NEAR(hit->barycentrics.x, 0.25f, 1e-6f);
    EXPECT_NEAR(hit->barycentrics.y, 0.5f, 1e-6f);
    // Counter-clockwise seen from +z: the normal is +z, whichever side the ray comes from.
    EXPECT_NEAR(hit->normal.x, 0.f, 1e-6f);
    EXPECT_NEAR(hit->normal.y, 0.f, 1e-6f);
    EXPECT_NEAR(hit->normal.z, 1.f, 1e-6f);
    const std::optional<Hit> fromBehind = scene.intersect(ray({1.5f, 2.5f, -9.f}, {0, 0, 1}));
    ASSERT_TRUE(fromBehind);
    EXPECT_NEAR(fromBehind->t, 6.f, 1e-5f);
    EXPECT_NEAR(fromBehind->normal.z, 1.f, 1e-6f);
}

TEST(RayScene, MobileHitIsInWorldSpaceWithInverseTransposeNormal) {
    Registry registry;
    // Object triangle with normal (1, 0, 1) / sqrt 2, stretched x2 along x and moved to z = -4.
    // World corners (0,0,-4), (2,0,-5), (0,1,-4): plane x + 2 (z + 4) = 0, normal (1,0,2)/sqrt 5.
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, -1}, {0, 1, 0}};
    mesh.indices = {0, 1, 2};
    const glm::mat4 pose = glm::scale(translation(0, 0, -4), glm::vec3(2.f, 1.f, 1.f));
    const Entity wedge = addMesh(registry, mesh, pose, Mobility::Mobile);
    RayScene scene;
    scene.build(registry);
    ASSERT_TRUE(scene.isMobile(wedge));

    // Down the z axis at (0.5, 0.25): z = -4 - 0.25, t = 9.25; object point (0.25, 0.25, -0.25)
    // = u (1,0,-1) + v (0,1,0): u = v = 0.25.
    const std::optional<Hit> hit = scene.intersect(ray({0.5f, 0.25f, 5.f}, {0, 0, -1}));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->entity, wedge);
    EXPECT_EQ(hit->primitive, 0u);
    EXPECT_NEAR(hit->t, 9.25f, 1e-5f);
    EXPECT_NEAR(hit->barycentrics.x, 0.25f, 1e-6f);
    EXPECT_NEAR(hit->barycentrics.y, 0.25f, 1e-6f);
    const glm::vec3 expected = glm::vec3(1, 0, 2) / std::sqrt(5.f);
    EXPECT_NEAR(hit->normal.x, expected.x, 1e-6f);
    EXPECT_NEAR(hit->normal.y, expected.y, 1e-6f);
    EXPECT_NEAR(hit->normal.z, expected.z, 1e-6f);
}

TEST(RayScene, MirroredMeshesKeepTheirFrontSide) {
    // A mirroring matrix reverses the world winding; the object's front (+z) must stay +z.
    Registry registry;
    const glm::mat4 mirror = glm::scale(kIdentity, glm::vec3(-1.f, 1.f, 1.f));
    const Entity still = addMesh(registry, quad(0, 0, 1, 1), mirror, Mobility::Static);
    const Entity moving =
        addMesh(registry, quad(0, 0, 1, 1), translation(5, 0, 0) * mirror, Mobility::Mobile);
    RayScene scene;
    scene.build(registry);
    for (const auto& [entity, x] : {std::pair{still, -0.3f}, std::pair{moving, 4.7f}}) {
        const std::optional<Hit> hit = scene.intersect(ray({x, 0.6f, 1.f}, {0, 0, -1}));
        ASSERT_TRUE(hit);
        EXPECT_EQ(hit->entity, entity);
        EXPECT_NEAR(hit->normal.z, 1.f, 1e-6f);
    }
}

TEST(RayScene, OcclusionRespectsTheSegment) {
    Registry registry;
    addMesh(registry, quad(-1, -1, 1, 1), kIdentity, Mobility::Static); // at z = 0
    RayScene scene;
    scene.build(registry);
    const glm::vec3 origin(0.2f, 0.1f, 2.f), down(0, 0, -1);
    EXPECT_TRUE(scene.occluded(ray(origin, down)));
    EXPECT_TRUE(scene.occluded(ray(origin, down, 2.01f)));
    EXPECT_FALSE(scene.occluded(ray(origin, down, 1.99f)));       // ends before the quad
    EXPECT_FALSE(scene.occluded(ray(origin, down, kInf, 2.01f))); // starts past it
    EXPECT_FALSE(scene.intersect(ray(origin, down, 1.99f)));
    EXPECT_FALSE(scene.intersect(ray(origin, down, kInf, 2.01f)));
}

TEST(RayScene, RaysThatMissReturnNothing) {
    Registry registry;
    addMesh(registry, quad(-1, -1, 1, 1), kIdentity, Mobility::Static);
    addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(0, 3, 0), Mobility::Mobile);
    RayScene scene;
    scene.build(registry);
    const Ray away = ray({0, 0, 1}, {0, 0, 1});
    const Ray beside = ray({1.5f, 0, 1}, {0, 0, -1});
    EXPECT_FALSE(scene.intersect(away));
    EXPECT_FALSE(scene.intersect(beside));
    EXPECT_FALSE(scene.occluded(away));
    EXPECT_FALSE(scene.occluded(beside));
}

TEST(RayScene, AvatarsAndUntaggedMeshesAreNotInTheScene) {
    Registry registry;
    const Entity avatar = registry.create();
    registry.emplace<Mesh>(avatar, test::boxMesh({1, 1, 1}));
    registry.emplace<WorldTransform>(avatar, kIdentity);
    registry.emplace<Avatar>(avatar);
    RayScene scene;
    scene.build(registry);
    EXPECT_FALSE(scene.intersect(ray({0, 0, 5}, {0, 0, -1})));
    EXPECT_FALSE(scene.isMobile(avatar));
}

// ---- against a brute-force reference, single and batched ------------------------------------

TEST(RayScene, ClosestHitsMatchBruteForceReference) {
    Clutter world;
    RayScene scene;
    scene.build(world.registry);
    const std::vector<WorldTriangle> triangles = worldTriangles(world.registry);
    const std::vector<Ray> rays = randomRays(3000, 7);
    std::size_t hits = 0;
    for (const Ray& r : rays) {
        const std::optional<ReferenceHit> expected = bruteForce(triangles, r);
        const std::optional<Hit> actual = scene.intersect(r);
        ASSERT_EQ(actual.has_value(), expected.has_value());
        EXPECT_EQ(scene.occluded(r), expected.has_value());
        if (!expected) continue;
        ++hits;
        // Single-precision intersection of coordinates up to ~10 m: a few ulps of 10.
        EXPECT_NEAR(actual->t, expected->t, 1e-5 * (1.0 + expected->t));
        EXPECT_EQ(actual->entity, expected->entity);
        EXPECT_EQ(actual->primitive, expected->primitive);
        // The reported barycentrics reproduce the hit point on the reported triangle.
        const Mesh& mesh = world.registry.get<Mesh>(actual->entity);
        const glm::mat4& m = world.registry.get<WorldTransform>(actual->entity).matrix;
        const auto corner = [&](int k) {
            return glm::vec3(
                m * glm::vec4(mesh.positions[mesh.indices[3 * actual->primitive + k]], 1.f));
        };
        const glm::vec2 b = actual->barycentrics;
        const glm::vec3 onTriangle =
            (1 - b.x - b.y) * corner(0) + b.x * corner(1) + b.y * corner(2);
        EXPECT_LT(glm::distance(onTriangle, r.origin + actual->t * r.direction), 1e-4f);
        const glm::vec3 n =
            glm::normalize(glm::cross(corner(1) - corner(0), corner(2) - corner(0)));
        // Mirror-free scene: the world winding gives the normal.
        EXPECT_GT(glm::dot(actual->normal, n), 1.f - 1e-5f);
    }
    // The ray set exercises both outcomes in earnest.
    EXPECT_GT(hits, rays.size() / 3);
    EXPECT_GT(rays.size() - hits, rays.size() / 10);
}

TEST(RayScene, BatchedQueriesEqualSingleRayQueries) {
    Clutter world;
    RayScene scene;
    scene.build(world.registry);
    const std::vector<Ray> rays = randomRays(1003, 11); // not a multiple of the packet width
    std::vector<std::optional<Hit>> hits(rays.size());
    std::vector<std::uint8_t> blocked(rays.size(), 2);
    scene.intersect(rays, hits);
    scene.occluded(rays, blocked);
    std::size_t misses = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
        const std::optional<Hit> single = scene.intersect(rays[i]);
        ASSERT_EQ(hits[i].has_value(), single.has_value()) << "ray " << i;
        EXPECT_EQ(blocked[i], scene.occluded(rays[i]) ? 1 : 0) << "ray " << i;
        if (!single) {
            ++misses;
            continue;
        }
        // Packet and single-ray kernels may round differently: a few ulps of t.
        EXPECT_NEAR(hits[i]->t, single->t, 1e-5f * (1.f + single->t));
        EXPECT_EQ(hits[i]->entity, single->entity);
        EXPECT_EQ(hits[i]->primitive, single->primitive);
        EXPECT_NEAR(hits[i]->barycentrics.x, single->barycentrics.x, 1e-4f);
        EXPECT_NEAR(hits[i]->barycentrics.y, single->barycentrics.y, 1e-4f);
        EXPECT_GT(glm::dot(hits[i]->normal, single->normal), 1.f - 1e-5f);
    }
    EXPECT_GT(misses, 50u);
    EXPECT_LT(misses, rays.size() - 300);
}

TEST(RayScene, ClosedRoomDoesNotLeakThroughEdgesOrCorners) {
    // Rays from inside a closed box aimed exactly at its corners, its edges and the diagonals
    // inside its walls, where triangles meet: every one must hit a wall. (Without Embree's
    // robust mode about 1% of the edge rays and 7% of the corner rays slip through.)
    const glm::vec3 half(2.f, 1.5f, 3.f), centre(0.3f, 0.1f, -0.2f);
    Registry registry;
    addMesh(registry, test::boxMesh(half, true), translation(centre.x, centre.y, centre.z), Mobility::Static);
    RayScene scene;
    scene.build(registry);
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> inside(-0.9f, 0.9f), along(-1.f, 1.f);
    const auto sign = [](float x) { return x < 0.f ? -1.f : 1.f; };
    std::size_t leaks = 0;
    const int count = 30000;
    for (int i = 0; i < count; ++i) {
        const glm::vec3 origin = centre + half * glm::vec3(inside(rng), inside(rng), inside(rng));
        // The target in box coordinates [-1, 1]^3.
        glm::vec3 target(along(rng), along(rng), along(rng));
        const int a = i % 3, b = (i + 1) % 3, c = (i + 2) % 3;
        switch (i % 3) {
        case 0:
            target = glm::vec3(sign(target.x), sign(target.y), sign(target.z));
            break;
        case 1:
            target[a] = sign(target[a]), target[b] = sign(target[b]);
            break; // an edge
        case 2:
            target[a] = sign(target[a]), target[b] = std::copysign(target[c], target[b]);
        }
        if (!scene.occluded(ray(origin, centre + half * target - origin))) ++leaks;
    }
    EXPECT_EQ(leaks, 0u) << "of " << count;
}

// ---- moving mobiles ---------------------------------------------------------------------------

TEST(RayScene, MovedMobileIsHitAtItsNewPoseAndMissedAtItsOld) {
    Registry registry;
    addMesh(registry, quad(-10, -10, 10, 10), translation(0, 0, -5), Mobility::Static); // floor
    const Entity crate =
        addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(0, 0, 0), Mobility::Mobile);
    RayScene scene;
    scene.build(registry);
    const Ray atOld = ray({0.1f, 0.2f, 3}, {0, 0, -1});
    const Ray atNew = ray({4.1f, 1.2f, 3}, {0, 0, -1});
    ASSERT_EQ(scene.intersect(atOld)->entity, crate);
    EXPECT_NEAR(scene.intersect(atOld)->t, 2.5f, 1e-5f);

    registry.clearChanges();
    moveTo(registry, crate, translation(4, 1, 1));
    EXPECT_EQ(scene.syncMoved(registry), 1u);
    const std::optional<Hit> old = scene.intersect(atOld);
    ASSERT_TRUE(old);
    EXPECT_NE(old->entity, crate); // the floor behind it
    EXPECT_NEAR(old->t, 8.f, 1e-5f);
    const std::optional<Hit> now = scene.intersect(atNew);
    ASSERT_TRUE(now);
    EXPECT_EQ(now->entity, crate);
    EXPECT_NEAR(now->t, 1.5f, 1e-5f);
    EXPECT_NEAR(now->normal.z, 1.f, 1e-6f);
    EXPECT_EQ(scene.mobilePose(crate), translation(4, 1, 1));

    // Nothing changed since: nothing to do.
    registry.clearChanges();
    EXPECT_EQ(scene.syncMoved(registry), 0u);
    EXPECT_EQ(scene.intersect(atNew)->entity, crate);
}

TEST(RayScene, TwoMobilesMoveInOneFrame) {
    Registry registry;
    const Entity a =
        addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(-3, 0, 0), Mobility::Mobile, "a");
    const Entity b =
        addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(3, 0, 0), Mobility::Mobile, "b");
    RayScene scene;
    scene.build(registry);
    registry.clearChanges();
    // They swap places, and b turns 45 degrees about z: a diamond |dx| + |dy| <= sqrt .5 in xy,
    // entered at dx = -(sqrt .5 - 0.1) by a ray along +x at y = 0.1.
    moveTo(registry, a, translation(3, 0, 0));
    moveTo(registry, b, glm::rotate(translation(-3, 0, 0), glm::radians(45.f), glm::vec3(0, 0, 1)));
    EXPECT_EQ(scene.syncMoved(registry), 2u);
    const std::optional<Hit> right = scene.intersect(ray({3.1f, 0.2f, 5}, {0, 0, -1}));
    const std::optional<Hit> left = scene.intersect(ray({-6, 0.1f, 0.2f}, {1, 0, 0}));
    ASSERT_TRUE(right && left);
    EXPECT_EQ(right->entity, a);
    EXPECT_NEAR(right->t, 4.5f, 1e-5f);
    EXPECT_EQ(left->entity, b);
    EXPECT_NEAR(left->t, 3.1f - std::sqrt(0.5f), 1e-5f);
}

TEST(RayScene, AnInactiveMobileIsMissedUntilPutBack) {
    Registry registry;
    const Entity wall = addMesh(registry, quad(-1, -1, 1, 1), kIdentity, Mobility::Static);
    const Entity crate = addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(0, 0, 2),
                                 Mobility::Mobile);
    const Entity pooled = addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(0, 0, 4),
                                  Mobility::Mobile);
    registry.get<MobileMesh>(pooled).active = false; // built inactive
    RayScene scene;
    scene.build(registry);
    const Ray down = ray({0, 0, 5}, {0, 0, -1});
    EXPECT_FALSE(scene.mobileActive(pooled));
    EXPECT_EQ(scene.intersect(down)->entity, crate);
    EXPECT_TRUE(scene.occluded(down));

    // Out: the ray reaches the wall; in: the pooled box, moved while inactive, is hit where
    // it stands now. Unchanged flags cost nothing.
    registry.clearChanges();
    registry.patch<MobileMesh>(crate).active = false;
    EXPECT_EQ(scene.syncMoved(registry), 1u);
    EXPECT_EQ(scene.intersect(down)->entity, wall);
    EXPECT_NEAR(scene.intersect(down)->t, 5.f, 1e-5f);
    registry.clearChanges();
    moveTo(registry, pooled, translation(0, 0, 3));
    registry.patch<MobileMesh>(pooled).active = true;
    registry.patch<MobileMesh>(crate).active = false;
    EXPECT_EQ(scene.syncMoved(registry), 2u); // pooled moved and put back; crate unchanged
    ASSERT_TRUE(scene.intersect(down));
    EXPECT_EQ(scene.intersect(down)->entity, pooled);
    EXPECT_NEAR(scene.intersect(down)->t, 1.5f, 1e-5f);
    EXPECT_TRUE(scene.mobileActive(pooled));
    EXPECT_FALSE(scene.mobileActive(crate));
    // The mobile-only queries still see an inactive mobile.
    EXPECT_TRUE(scene.occludedByMobile(crate, ray({0, 0, 5}, {0, 0, -1})));
}

TEST(RayScene, SetMobilePoseMovesOneMobileAndRejectsBadPoses) {
    Registry registry;
    const Entity wall = addMesh(registry, quad(-1, -1, 1, 1), kIdentity, Mobility::Static);
    const Entity crate =
        addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(0, 0, 2), Mobility::Mobile);
    RayScene scene;
    scene.build(registry);
    const Ray down = ray({0, 0, 5}, {0, 0, -1});
    EXPECT_EQ(scene.intersect(down)->entity, crate);
    ASSERT_TRUE(scene.setMobilePose(crate, translation(5, 0, 2)));
    EXPECT_EQ(scene.intersect(down)->entity, wall);

    const float nan = std::numeric_limits<float>::quiet_NaN();
    {
        const ScopedLogLevel quiet(LogLevel::Quiet);
        EXPECT_FALSE(scene.setMobilePose(crate, translation(nan, 0, 0)));
        EXPECT_FALSE(scene.setMobilePose(crate, glm::scale(kIdentity, glm::vec3(1, 0, 1))));
        // Parked far away: past kMaxPoseReach (Embree itself aborts on ray origins past ~1.8e18).
        EXPECT_FALSE(scene.setMobilePose(crate, translation(1e30f, 0, 0)));
        EXPECT_FALSE(scene.setMobilePose(crate, translation(0, 0, 2 * kMaxPoseReach)));
        EXPECT_FALSE(
            scene.setMobilePose(crate, glm::scale(kIdentity, glm::vec3(2 * kMaxPoseReach))));
        EXPECT_TRUE(
            scene.setMobilePose(crate, translation(0, -0.5f * kMaxPoseReach, 0))); // far, fine
        EXPECT_TRUE(scene.setMobilePose(crate, translation(5, 0, 2)));
    }
    EXPECT_FALSE(scene.setMobilePose(wall, kIdentity)); // not a mobile
    EXPECT_EQ(scene.mobilePose(crate), translation(5, 0, 2));
    EXPECT_EQ(scene.intersect(down)->entity, wall);
}

TEST(RayScene, IntersectMobileSeesOnlyThatMobileAtTheGivenPose) {
    Registry registry;
    // A static wall at z = 1 hides everything below it from a ray coming down.
    addMesh(registry, quad(-10, -10, 10, 10), translation(0, 0, 1), Mobility::Static);
    const Entity crate = addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(0, 0, -2),
                                 Mobility::Mobile, "crate");
    const Entity other = addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(3, 0, -2),
                                 Mobility::Mobile, "other");
    RayScene scene;
    scene.build(registry);
    const Ray down = ray({0.1f, 0.2f, 5}, {0, 0, -1});
    ASSERT_NE(scene.intersect(down)->entity, crate); // the wall is in front

    std::optional<Hit> hit = scene.intersectMobile(crate, scene.mobilePose(crate), down);
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->entity, crate);
    EXPECT_NEAR(hit->t, 6.5f, 1e-5f);
    EXPECT_NEAR(hit->normal.z, 1.f, 1e-6f);

    // At another pose: rotated 90 degrees about x and lifted; the top face is now at z = -0.5.
    const glm::mat4 pose =
        glm::rotate(translation(0, 0, -1), glm::radians(90.f), glm::vec3(1, 0, 0));
    hit = scene.intersectMobile(crate, pose, down);
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 5.5f, 1e-5f);
    EXPECT_NEAR(hit->normal.z, 1.f, 1e-6f);
    // The object-space ray was scaled by the pose: t stays a world-ray parameter.
    hit = scene.intersectMobile(crate, glm::scale(translation(0, 0, -2), glm::vec3(2.f)), down);
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 6.f, 1e-5f);

    // A ray through the other mobile only misses this one, and the scene itself is unchanged.
    const Ray throughOther = ray({3.1f, 0.2f, 5}, {0, 0, -1});
    EXPECT_FALSE(scene.intersectMobile(crate, scene.mobilePose(crate), throughOther));
    EXPECT_EQ(scene.intersectMobile(other, scene.mobilePose(other), throughOther)->entity, other);
    EXPECT_EQ(scene.mobilePose(crate), translation(0, 0, -2));
    EXPECT_NEAR(scene.intersect(down)->t, 4.f, 1e-5f);
}

TEST(RayScene, OccludedByMobileAnswersWhetherIntersectMobileHits) {
    Registry registry;
    addMesh(registry, quad(-10, -10, 10, 10), translation(0, 0, 1), Mobility::Static);
    const Entity crate = addMesh(registry, test::boxMesh({0.5f, 0.5f, 0.5f}), translation(0, 0, -2),
                                 Mobility::Mobile, "crate");
    RayScene scene;
    scene.build(registry);
    // A pose other than the instance's: turned and stretched, so the object-space ray differs
    // from the world one in origin, direction and length.
    const glm::mat4 pose = glm::scale(
        glm::rotate(translation(0.2f, -0.1f, -1.5f), glm::radians(30.f), glm::vec3(0, 1, 1)),
        glm::vec3(1.f, 2.f, 0.5f));
    const glm::mat4 toObject = glm::inverse(pose);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> coordinate(-2.f, 2.f), length(0.f, 6.f);
    std::size_t hits = 0, misses = 0;
    for (int i = 0; i < 20'000; ++i) {
        // From anywhere, aimed within about a box size of the crate: hits and near misses.
        const glm::vec3 origin(coordinate(rng), coordinate(rng), coordinate(rng) + 1.f);
        const glm::vec3 target =
            glm::vec3(pose[3]) +
            0.5f * glm::vec3(coordinate(rng), coordinate(rng), coordinate(rng));
        if (glm::length(target - origin) < 1e-3f) continue;
        const glm::vec3 direction = glm::normalize(target - origin);
        const float tfar = length(rng);
        const Ray world{origin, 0.f, direction, tfar};
        const Ray local{glm::vec3(toObject * glm::vec4(origin, 1.f)), 0.f,
                        glm::mat3(toObject) * direction, tfar};
        const std::optional<Hit> hit = scene.intersectMobile(crate, pose, world);
        // Rays that graze an edge within rounding may differ between the two traversals.
        if (hit && std::abs(hit->t - tfar) < 1e-4f) continue;
        ASSERT_EQ(scene.occludedByMobile(crate, local), hit.has_value()) << "ray " << i;
        (hit ? hits : misses) += 1;
    }
    EXPECT_GT(hits, 4'000u); // both answers were exercised
    EXPECT_GT(misses, 4'000u);
}

// ---- filtered queries ------------------------------------------------------------------------

TEST(RayScene, FiltersSeeEveryCandidateAndCanSkipEntities) {
    Registry registry;
    std::vector<Entity> layers; // z = 0, -1, -2, -3; the second one mobile
    for (int i = 0; i < 4; ++i)
        layers.push_back(addMesh(registry, quad(-1, -1, 1, 1), translation(0, 0, -float(i)),
                                 i == 1 ? Mobility::Mobile : Mobility::Static));
    RayScene scene;
    scene.build(registry);
    const Ray down = ray({0.3f, -0.2f, 1}, {0, 0, -1});

    std::set<Entity> seen;
    EXPECT_FALSE(scene.intersectFiltered(down, [&](const Hit& h) {
        seen.insert(h.entity);
        return false;
    }));
    EXPECT_EQ(seen, std::set<Entity>(layers.begin(), layers.end()));

    const std::optional<Hit> second =
        scene.intersectFiltered(down, [&](const Hit& h) { return h.entity != layers[0]; });
    ASSERT_TRUE(second);
    EXPECT_EQ(second->entity, layers[1]);
    EXPECT_NEAR(second->t, 2.f, 1e-6f);
    const std::optional<Hit> third = scene.intersectFiltered(
        down, [&](const Hit& h) { return h.t > 2.5f; }); // the candidate's t is its own
    ASSERT_TRUE(third);
    EXPECT_EQ(third->entity, layers[2]);

    EXPECT_FALSE(scene.occludedFiltered(down, [](const Hit&) { return false; }));
    EXPECT_TRUE(scene.occludedFiltered(down, [&](const Hit& h) { return h.entity == layers[3]; }));
}

// ---- edge cases and bad input ---------------------------------------------------------------

TEST(RayScene, WorksWithoutStaticMeshesOrWithoutMobiles) {
    {
        RayScene scene; // never built: everything misses
        EXPECT_FALSE(scene.intersect(ray({0, 0, 0}, {0, 0, 1})));
        Registry empty;
        scene.build(empty);
        EXPECT_FALSE(scene.occluded(ray({0, 0, 0}, {0, 0, 1})));
        EXPECT_EQ(scene.staticTriangleCount(), 0u);
        EXPECT_EQ(scene.mobileCount(), 0u);
    }
    {
        Registry registry;
        const Entity crate = addMesh(registry, test::boxMesh({1, 1, 1}), kIdentity, Mobility::Mobile);
        RayScene scene;
        scene.build(registry);
        EXPECT_EQ(scene.staticTriangleCount(), 0u);
        EXPECT_EQ(scene.intersect(ray({0, 0, 5}, {0, 0, -1}))->entity, crate);
        registry.clearChanges();
        moveTo(registry, crate, translation(0, 0, 2));
        EXPECT_EQ(scene.syncMoved(registry), 1u);
        EXPECT_NEAR(scene.intersect(ray({0, 0, 5}, {0, 0, -1}))->t, 2.f, 1e-5f);
    }
    {
        Registry registry;
        const Entity wall = addMesh(registry, quad(-1, -1, 1, 1), kIdentity, Mobility::Static);
        RayScene scene;
        scene.build(registry);
        EXPECT_EQ(scene.mobileCount(), 0u);
        EXPECT_EQ(scene.intersect(ray({0, 0, 5}, {0, 0, -1}))->entity, wall);
        EXPECT_EQ(scene.syncMoved(registry), 0u);
    }
}

TEST(RayScene, BadGeometryIsAClearErrorAndKeepsThePreviousScene) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const auto expectError = [](const Registry& registry, const char* fragment) {
        RayScene scene;
        try {
            scene.build(registry);
            ADD_FAILURE() << "no error for " << fragment;
        } catch (const Error& e) {
            EXPECT_THAT(e.what(), HasSubstr(fragment));
            EXPECT_THAT(e.what(), HasSubstr("'bad'"));
        }
    };
    {
        Registry registry;
        Mesh mesh = quad(0, 0, 1, 1);
        mesh.positions[2].y = nan;
        addMesh(registry, mesh, kIdentity, Mobility::Static, "bad");
        expectError(registry, "Mesh.positions[2] is not finite");
    }
    {
        Registry registry;
        addMesh(registry, quad(0, 0, 1, 1), translation(0, nan, 0), Mobility::Mobile, "bad");
        expectError(registry, "WorldTransform.matrix is not finite");
    }
    {
        Registry registry;
        Mesh mesh = quad(0, 0, 1, 1);
        mesh.indices[4] = 4;
        addMesh(registry, mesh, kIdentity, Mobility::Static, "bad");
        expectError(registry, "Mesh.indices[4] = 4 is out of range");
    }
    {
        Registry registry;
        Mesh mesh = quad(0, 0, 1, 1);
        mesh.indices.pop_back();
        addMesh(registry, mesh, kIdentity, Mobility::Mobile, "bad");
        expectError(registry, "not a multiple of 3");
    }
    {
        Registry registry; // finite in object space, overflows in world space
        addMesh(registry, quad(0, 0, 1e30f, 1), glm::scale(kIdentity, glm::vec3(1e20f)),
                Mobility::Static, "bad");
        expectError(registry, "not finite or lies farther than");
    }
    {
        Registry registry; // finite, but where Embree cannot trace
        addMesh(registry, quad(0, 0, 1, 1), translation(0, 0, 1e19f), Mobility::Static, "bad");
        expectError(registry, "lies farther than");
    }
    {
        Registry registry;
        addMesh(registry, quad(0, 0, 1, 1), glm::scale(kIdentity, glm::vec3(1, 0, 1)),
                Mobility::Mobile, "bad");
        expectError(registry, "not invertible");
    }
    {
        Registry registry;
        const Entity e = addMesh(registry, quad(0, 0, 1, 1), kIdentity, Mobility::Static, "bad");
        registry.emplace<MobileMesh>(e);
        expectError(registry, "also tagged MobileMesh");
    }
    {
        Registry registry;
        const Entity e = addMesh(registry, quad(0, 0, 1, 1), kIdentity, Mobility::Static, "bad");
        registry.remove<WorldTransform>(e);
        expectError(registry, "has no WorldTransform");
    }

    // A failed rebuild leaves the scene that was there.
    Registry good;
    const Entity wall = addMesh(good, quad(-1, -1, 1, 1), kIdentity, Mobility::Static);
    RayScene scene;
    scene.build(good);
    Mesh broken = quad(0, 0, 1, 1);
    broken.positions[0].x = nan;
    addMesh(good, broken, kIdentity, Mobility::Static, "bad");
    EXPECT_THROW(scene.build(good), Error);
    EXPECT_EQ(scene.intersect(ray({0, 0, 5}, {0, 0, -1}))->entity, wall);
}

TEST(EmbreeDevice, ErrorCallbackRecordsErrorsWithoutCrashing) {
    EmbreeDevice device;
    EXPECT_EQ(device.errorCount(), 0u);
    EXPECT_FALSE(device.takeError());
    SceneHandle scene(rtcNewScene(device.handle()));
    GeometryHandle geometry(rtcNewGeometry(device.handle(), RTC_GEOMETRY_TYPE_TRIANGLE));
    {
        const ScopedLogLevel quiet(LogLevel::Quiet);
        rtcAttachGeometryByID(scene.get(), geometry.get(), 3);
        rtcAttachGeometryByID(scene.get(), geometry.get(), 3);         // the ID is taken
        rtcSetSceneBuildQuality(scene.get(), RTC_BUILD_QUALITY_REFIT); // geometries only
    }
    EXPECT_EQ(device.errorCount(), 2u);
    const std::optional<EmbreeError> error = device.takeError();
    ASSERT_TRUE(error);
    EXPECT_EQ(error->code, RTC_ERROR_INVALID_OPERATION);
    EXPECT_THAT(error->message, HasSubstr("RTC_ERROR_INVALID_OPERATION: invalid geometry ID"));
    EXPECT_FALSE(device.takeError()); // taken; the second error was counted, not queued
    // The device still works after reporting errors.
    SceneHandle fresh(rtcNewScene(device.handle()));
    rtcCommitScene(fresh.get());
    EXPECT_EQ(device.errorCount(), 2u);
}

TEST(EmbreeDevice, BadConfigurationIsAnError) {
    EXPECT_THROW(EmbreeDevice("threads=banana,no_such_option=1"), Error);
}

} // namespace
} // namespace qgi
