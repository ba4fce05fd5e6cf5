#include "runtime/scene/BuiltinScenes.h"

#include "components/Avatar.h"
#include "components/Camera.h"
#include "components/DirectionalLight.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/Transform.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/scene/MeshProcessing.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/TextureLibrary.h"

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

namespace qgi {
namespace {

constexpr float kPi = glm::pi<float>();

Entity findByName(const Registry& registry, const std::string& name) {
    Entity found;
    registry.view<const Name>().each([&](Entity e, const Name& n) {
        if (n.value == name) found = e;
    });
    return found;
}

std::size_t triangleCount(const Registry& registry) {
    std::size_t triangles = 0;
    registry.view<const Mesh>().each([&](const Mesh& m) { triangles += m.indices.size() / 3; });
    return triangles;
}

glm::vec3 toWorld(const Registry& registry, Entity e, const glm::vec3& p) {
    return glm::vec3(registry.get<WorldTransform>(e).matrix * glm::vec4(p, 1.f));
}

Aabb worldBounds(const Registry& registry, Entity e) {
    Aabb box;
    for (const glm::vec3& p : registry.get<Mesh>(e).positions)
        box.extend(toWorld(registry, e, p));
    return box;
}

// Edges (by corner positions, so crease copies count as one vertex) bordered by more than two
// triangles. The built-in geometry is manifold; a triangle that processing had to cut loose
// from its neighbours would show up here as a third triangle on an edge.
std::size_t nonManifoldEdges(const Mesh& mesh) {
    struct EdgeHash {
        std::size_t operator()(const std::array<float, 6>& e) const {
            std::size_t h = 0;
            for (const float f : e)
                h = h * 1000003u ^ std::hash<float>{}(f);
            return h;
        }
    };
    std::unordered_map<std::array<float, 6>, int, EdgeHash> borders;
    for (std::size_t k = 0; k < mesh.indices.size(); k += 3)
        for (int j = 0; j < 3; ++j) {
            glm::vec3 a = mesh.positions[mesh.indices[k + std::size_t(j)]];
            glm::vec3 b = mesh.positions[mesh.indices[k + std::size_t((j + 1) % 3)]];
            if (std::tie(b.x, b.y, b.z) < std::tie(a.x, a.y, a.z)) std::swap(a, b);
            ++borders[{a.x, a.y, a.z, b.x, b.y, b.z}];
        }
    return std::size_t(std::count_if(borders.begin(), borders.end(),
                                     [](const auto& entry) { return entry.second > 2; }));
}

/// A point of the published Cornell box data (mm) in the scene's frame as BuiltinCornellBox.h
/// documents it: a half turn about Y with the camera's x at 0, in metres.
glm::vec3 cornellPoint(float x, float y, float z) {
    return glm::vec3(278.f - x, y, -z) / 1000.f;
}

// Tolerance for a published coordinate read back from float geometry: 1 mm (the data's own
// precision is 0.1 mm).
constexpr float kMillimetre = 1e-3f;

class BuiltinScenes : public ::testing::TestWithParam<const char*> {};

// Invariants every built-in scene keeps.
TEST_P(BuiltinScenes, EntitiesAreComplete) {
    Registry registry;
    buildBuiltinScene(registry, GetParam(), SceneOptions{});
    const SceneInfo* info = registry.ctx().find<SceneInfo>();
    ASSERT_NE(info, nullptr);
    EXPECT_EQ(info->name, GetParam());
    EXPECT_EQ(info->source, std::string("builtin:") + GetParam());
    EXPECT_GT(info->maxEdgeLength, 0.f);
    EXPECT_TRUE(registry.ctx().contains<TextureLibrary>());

    registry.view<const Transform>().each([&](Entity e, const Transform& t) {
        ASSERT_TRUE(registry.has<Name>(e));
        ASSERT_TRUE(registry.has<WorldTransform>(e)) << registry.get<Name>(e).value;
        EXPECT_TRUE(t.parent.isNull());
        const glm::mat4 expected = glm::translate(glm::mat4(1.f), t.translation) *
                                   glm::mat4_cast(t.rotation) * glm::scale(glm::mat4(1.f), t.scale);
        const glm::mat4& actual = registry.get<WorldTransform>(e).matrix;
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r)
                EXPECT_NEAR(actual[c][r], expected[c][r], 1e-6f);
        EXPECT_NEAR(glm::length(t.rotation), 1.f, 1e-6f);
    });
    EXPECT_EQ(registry.count<Transform>(), registry.aliveCount());

    registry.view<const Mesh>().each([&](Entity e, const Mesh&) {
        const std::string& name = registry.get<Name>(e).value;
        EXPECT_TRUE(registry.has<Material>(e)) << name;
        EXPECT_EQ(int(registry.has<StaticMesh>(e)) + int(registry.has<MobileMesh>(e)) +
                      int(registry.has<Avatar>(e)),
                  1)
            << name;
        if (!registry.has<StaticMesh>(e)) {
            EXPECT_TRUE(registry.has<PathFollower>(e)) << name;
        }
    });

    std::size_t activeCameras = 0;
    registry.view<const Camera>().each([&](Entity e, const Camera& c) {
        activeCameras += c.active;
        EXPECT_TRUE(registry.has<PathFollower>(e));
        EXPECT_GT(c.yfov, 0.f);
        EXPECT_LT(c.yfov, kPi);
    });
    EXPECT_EQ(activeCameras, 1u);

    // Paths: sorted keys, unit rotations, loops that close on themselves, and a first key
    // that is the entity's pose at load (nothing jumps on the first frame).
    registry.view<const PathFollower>().each([&](Entity e, const PathFollower& path) {
        const std::string& name = registry.get<Name>(e).value;
        ASSERT_GE(path.keys.size(), 2u) << name;
        for (std::size_t k = 1; k < path.keys.size(); ++k)
            EXPECT_LT(path.keys[k - 1].time, path.keys[k].time) << name;
        for (const PathKey& key : path.keys)
            EXPECT_NEAR(glm::length(key.rotation), 1.f, 1e-5f);
        if (path.loop) {
            EXPECT_NEAR(glm::distance(path.keys.front().position, path.keys.back().position), 0.f,
                        1e-6f)
                << name;
            EXPECT_NEAR(std::abs(glm::dot(path.keys.front().rotation, path.keys.back().rotation)),
                        1.f, 1e-6f)
                << name;
        }
        const Transform& t = registry.get<Transform>(e);
        EXPECT_NEAR(glm::distance(t.translation, path.keys.front().position), 0.f, 1e-6f) << name;
        EXPECT_NEAR(std::abs(glm::dot(t.rotation, path.keys.front().rotation)), 1.f, 1e-6f) << name;
    });
}

TEST_P(BuiltinScenes, MeshesAreProcessedAndBounded) {
    Registry registry;
    buildBuiltinScene(registry, GetParam(), SceneOptions{});
    const SceneInfo& info = registry.ctx().get<SceneInfo>();
    // Squared lengths are compared in float: 1e-6 relative covers their rounding.
    const double maxEdge = double(info.maxEdgeLength) * (1.0 + 1e-6);
    // Bounds were built from the same float transforms; allow one float rounding of the
    // scene's extent.
    const glm::vec3 slack = glm::vec3(1e-6f * glm::length(info.bounds.extent()));
    registry.view<const Mesh>().each([&](Entity e, const Mesh& mesh) {
        const std::string& name = registry.get<Name>(e).value;
        ASSERT_FALSE(mesh.indices.empty()) << name;
        ASSERT_EQ(mesh.indices.size() % 3, 0u) << name;
        ASSERT_EQ(mesh.normals.size(), mesh.positions.size()) << name;
        EXPECT_TRUE(mesh.uvs.empty()) << name;
        for (const glm::vec3& n : mesh.normals)
            ASSERT_NEAR(glm::length(n), 1.f, 1e-5f) << name;
        for (const std::uint32_t i : mesh.indices)
            ASSERT_LT(i, mesh.positions.size()) << name;
        double longest = 0.0;
        for (std::size_t k = 0; k < mesh.indices.size(); k += 3)
            for (int j = 0; j < 3; ++j) {
                const glm::dvec3 a(mesh.positions[mesh.indices[k + std::size_t(j)]]);
                const glm::dvec3 b(mesh.positions[mesh.indices[k + std::size_t((j + 1) % 3)]]);
                longest = std::max(longest, glm::length(b - a));
            }
        EXPECT_LE(longest, maxEdge) << name;
        EXPECT_EQ(nonManifoldEdges(mesh), 0u) << name;
        for (const glm::vec3& p : mesh.positions) {
            const glm::vec3 w = toWorld(registry, e, p);
            ASSERT_TRUE(glm::all(glm::greaterThanEqual(w, info.bounds.min - slack)) &&
                        glm::all(glm::lessThanEqual(w, info.bounds.max + slack)))
                << name;
        }
    });
}

TEST_P(BuiltinScenes, BuildIsDeterministic) {
    Registry first, second;
    buildBuiltinScene(first, GetParam(), SceneOptions{});
    buildBuiltinScene(second, GetParam(), SceneOptions{});
    const std::vector<Entity> a = first.view<const Mesh>().entities();
    const std::vector<Entity> b = second.view<const Mesh>().entities();
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
        ASSERT_EQ(first.get<Name>(a[i]).value, second.get<Name>(b[i]).value);
        const Mesh& ma = first.get<Mesh>(a[i]);
        const Mesh& mb = second.get<Mesh>(b[i]);
        EXPECT_EQ(ma.positions, mb.positions) << first.get<Name>(a[i]).value;
        EXPECT_EQ(ma.normals, mb.normals);
        EXPECT_EQ(ma.indices, mb.indices);
    }
}

INSTANTIATE_TEST_SUITE_P(All, BuiltinScenes, ::testing::Values("cornell", "atrium"));

TEST(BuiltinSceneNames, ListsAndRejects) {
    EXPECT_EQ(builtinSceneNames(), (std::vector<std::string>{"cornell", "cornell-glossy", "atrium"}));
    EXPECT_TRUE(isBuiltinScene("atrium"));
    EXPECT_FALSE(isBuiltinScene("Cornell"));
    EXPECT_FALSE(isBuiltinScene(""));
    Registry registry;
    EXPECT_THROW(buildBuiltinScene(registry, "sponza", SceneOptions{}), Error);
    EXPECT_THROW(buildBuiltinScene(registry, "cornell", SceneOptions{-0.1f}), Error);
    EXPECT_THROW(buildBuiltinScene(registry, "cornell",
                                   SceneOptions{std::numeric_limits<float>::quiet_NaN()}),
                 Error);
    EXPECT_EQ(registry.aliveCount(), 0u);
}

TEST(CornellBox, MatchesThePublishedMeasurements) {
    Registry registry;
    buildBuiltinScene(registry, "cornell", SceneOptions{});
    const SceneInfo& info = registry.ctx().get<SceneInfo>();
    EXPECT_FLOAT_EQ(info.maxEdgeLength, 0.02f);
    EXPECT_EQ(info.environment, glm::vec3(0.f));
    // The room: 556 mm wide (the red wall's top edge), 548.8 high, 559.2 deep.
    EXPECT_NEAR(info.bounds.min.x, cornellPoint(556, 0, 0).x, kMillimetre);
    EXPECT_NEAR(info.bounds.max.x, cornellPoint(0, 0, 0).x, kMillimetre);
    EXPECT_NEAR(info.bounds.min.y, 0.f, kMillimetre);
    EXPECT_NEAR(info.bounds.max.y, 0.5488f, kMillimetre);
    EXPECT_NEAR(info.bounds.min.z, cornellPoint(0, 0, 559.2f).z, kMillimetre);
    EXPECT_NEAR(info.bounds.max.z, 0.f, kMillimetre);

    // Every published corner of the blocks is a vertex of the scene.
    const auto hasVertexNear = [&](const char* name, const glm::vec3& target) {
        const Entity e = findByName(registry, name);
        float best = std::numeric_limits<float>::max();
        for (const glm::vec3& p : registry.get<Mesh>(e).positions)
            best = std::min(best, glm::distance(toWorld(registry, e, p), target));
        return best <= kMillimetre;
    };
    for (const auto& c :
         std::vector<std::array<float, 2>>{{423, 247}, {265, 296}, {314, 456}, {472, 406}})
        for (const float y : {0.f, 330.f})
            EXPECT_TRUE(hasVertexNear("tall block", cornellPoint(c[0], y, c[1])));
    for (const auto& c :
         std::vector<std::array<float, 2>>{{130, 65}, {82, 225}, {240, 272}, {290, 114}})
        for (const float y : {0.f, 165.f})
            EXPECT_TRUE(hasVertexNear("short block", cornellPoint(c[0], y, c[1])));
    for (const auto& c :
         std::vector<std::array<float, 2>>{{343, 227}, {343, 332}, {213, 332}, {213, 227}})
        EXPECT_TRUE(hasVertexNear("light", cornellPoint(c[0], 548.8f, c[1])));

    // Surfaces face into the room, the red wall is on the camera's left.
    const auto facesAlong = [&](const char* name, const glm::vec3& expected) {
        const Entity e = findByName(registry, name);
        for (const glm::vec3& n : registry.get<Mesh>(e).normals)
            if (glm::dot(glm::mat3(registry.get<WorldTransform>(e).matrix) * n, expected) < 0.99f)
                return false;
        return true;
    };
    EXPECT_TRUE(facesAlong("floor", {0, 1, 0}));
    EXPECT_TRUE(facesAlong("ceiling", {0, -1, 0}));
    EXPECT_TRUE(facesAlong("back wall", {0, 0, 1}));
    EXPECT_TRUE(facesAlong("left wall (red)", {1, 0, 0}));
    EXPECT_TRUE(facesAlong("right wall (green)", {-1, 0, 0}));
    EXPECT_TRUE(facesAlong("light", {0, -1, 0}));
    EXPECT_LT(worldBounds(registry, findByName(registry, "left wall (red)")).max.x, -0.27f);
    const glm::vec3 red = registry.get<Material>(findByName(registry, "left wall (red)")).baseColor;
    const glm::vec3 green =
        registry.get<Material>(findByName(registry, "right wall (green)")).baseColor;
    EXPECT_GT(red.r, 5.f * red.g);
    EXPECT_GT(green.g, 2.f * green.r);

    // The area light: 130 x 105 mm just under the ceiling, 10-20 W; the point light stands in
    // with a comparable power (4 pi I for a point, pi L A for a Lambertian quad).
    const Entity light = findByName(registry, "light");
    const double area = meshArea(registry.get<Mesh>(light));
    EXPECT_NEAR(area, 0.130 * 0.105, 1e-6);
    const Aabb lightBox = worldBounds(registry, light);
    EXPECT_LT(lightBox.max.y, 0.5488f);
    EXPECT_GT(lightBox.min.y, 0.5488f - kMillimetre);
    std::size_t emitters = 0;
    registry.view<const Material>().each(
        [&](const Material& m) { emitters += m.emission != glm::vec3(0.f); });
    EXPECT_EQ(emitters, 1u);
    const glm::vec3 radiance = registry.get<Material>(light).emission;
    const double areaPower = kPi * area * radiance.g;
    EXPECT_GE(areaPower, 10.0);
    EXPECT_LE(areaPower, 20.0);
    ASSERT_EQ(registry.count<PointLight>(), 1u);
    registry.view<const PointLight>().each([&](Entity e, const PointLight& p) {
        const double pointPower = 4.0 * kPi * p.intensity * p.color.g;
        EXPECT_GT(pointPower, 0.5 * areaPower);
        EXPECT_LT(pointPower, 2.0 * areaPower);
        const glm::vec3 at = registry.get<Transform>(e).translation;
        EXPECT_LT(at.y, lightBox.min.y);
        EXPECT_GT(at.y, lightBox.min.y - 0.05f);
        EXPECT_GT(at.x, lightBox.min.x);
        EXPECT_LT(at.x, lightBox.max.x);
    });

    // The standard camera: (278, 273, -800) mm, looking into the box, 39.3 degree fov.
    registry.view<const Camera, const Transform>().each([&](const Camera& c, const Transform& t) {
        EXPECT_NEAR(c.yfov, 2.f * std::atan(12.5f / 35.f), 1e-5f);
        EXPECT_NEAR(glm::distance(t.translation, cornellPoint(278, 273, -800)), 0.f, kMillimetre);
        EXPECT_GT(glm::dot(t.rotation * glm::vec3(0, 0, -1), glm::vec3(0, 0, -1)), 0.9999f);
    });
}

// Distance from a point to a convex polygon in the floor plane (0 inside).
float distanceToPolygon(const glm::vec2& p, const std::vector<glm::vec2>& polygon) {
    bool inside = true;
    float nearest = std::numeric_limits<float>::max();
    for (std::size_t i = 0; i < polygon.size(); ++i) {
        const glm::vec2 a = polygon[i], b = polygon[(i + 1) % polygon.size()];
        const float side = (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
        const float sideOfRest = (b.x - a.x) * (polygon[(i + 2) % polygon.size()].y - a.y) -
                                 (b.y - a.y) * (polygon[(i + 2) % polygon.size()].x - a.x);
        if (side * sideOfRest < 0.f) inside = false;
        const float t = std::clamp(glm::dot(p - a, b - a) / glm::dot(b - a, b - a), 0.f, 1.f);
        nearest = std::min(nearest, glm::distance(p, a + t * (b - a)));
    }
    return inside ? 0.f : nearest;
}

TEST(CornellBox, OneMobileBlockAndOneAvatarThatKeepClear) {
    Registry registry;
    buildBuiltinScene(registry, "cornell", SceneOptions{});
    ASSERT_EQ(registry.count<MobileMesh>(), 1u);
    ASSERT_EQ(registry.count<Avatar>(), 1u);
    const Entity block = findByName(registry, "short block");
    EXPECT_TRUE(registry.has<MobileMesh>(block));
    EXPECT_EQ(registry.count<StaticMesh>(), registry.count<Mesh>() - 2);

    // The block slides a few cm at a few cm/s and stays inside the room.
    const PathFollower& slide = registry.get<PathFollower>(block);
    float travel = 0.f;
    for (std::size_t k = 1; k < slide.keys.size(); ++k) {
        const float d = glm::distance(slide.keys[k].position, slide.keys[k - 1].position);
        const float speed = d / (slide.keys[k].time - slide.keys[k - 1].time);
        EXPECT_LE(speed, 0.05f);
        travel = std::max(travel, glm::distance(slide.keys[k].position, slide.keys[0].position));
    }
    EXPECT_GE(travel, 0.02f);
    EXPECT_LE(travel, 0.10f);

    // The avatar is about 15 cm tall, walks on the floor, and never enters a block (the short
    // block anywhere along its slide) or a wall.
    const Entity avatar = findByName(registry, "avatar");
    ASSERT_TRUE(registry.has<Avatar>(avatar));
    const Aabb body = worldBounds(registry, avatar);
    EXPECT_NEAR(body.extent().y, 0.15f, 0.01f);
    EXPECT_NEAR(body.min.y, 0.f, kMillimetre);
    const float radius = 0.5f * std::max(body.extent().x, body.extent().z);
    const auto footprint = [](std::initializer_list<std::array<float, 2>> mm, float shiftX) {
        std::vector<glm::vec2> polygon;
        for (const auto& c : mm) {
            const glm::vec3 p = cornellPoint(c[0], 0, c[1]);
            polygon.emplace_back(p.x + shiftX, p.z);
        }
        return polygon;
    };
    const auto tall = footprint({{423, 247}, {265, 296}, {314, 456}, {472, 406}}, 0.f);
    const PathFollower& walk = registry.get<PathFollower>(avatar);
    for (std::size_t k = 1; k < walk.keys.size(); ++k)
        for (float u = 0.f; u <= 1.f; u += 0.05f) {
            const glm::vec3 p = glm::mix(walk.keys[k - 1].position, walk.keys[k].position, u);
            const glm::vec2 ground(p.x, p.z);
            EXPECT_GT(distanceToPolygon(ground, tall), radius);
            for (float shift = 0.f; shift <= travel + 1e-6f; shift += 0.01f)
                EXPECT_GT(
                    distanceToPolygon(
                        ground, footprint({{130, 65}, {82, 225}, {240, 272}, {290, 114}}, shift)),
                    radius);
            // The red wall leans in to 549.6 mm at the floor; the front is open at z = 0.
            EXPECT_GT(p.x - radius, cornellPoint(549.6f, 0, 0).x);
            EXPECT_LT(p.x + radius, cornellPoint(0, 0, 0).x);
            EXPECT_GT(p.z - radius, cornellPoint(0, 0, 559.2f).z);
            EXPECT_LT(p.z + radius, 0.f);
        }
}

TEST(Atrium, IsLargeAndFullyCast) {
    Registry registry;
    buildBuiltinScene(registry, "atrium", SceneOptions{});
    EXPECT_GE(triangleCount(registry), 200000u);
    EXPECT_GE(registry.count<MobileMesh>(), 3u);
    EXPECT_GE(registry.count<Avatar>(), 5u);
    EXPECT_GE(registry.count<PointLight>(), 1u);
    EXPECT_GE(registry.count<SpotLight>(), 1u);
    EXPECT_GE(registry.count<DirectionalLight>(), 1u);
    std::size_t emitters = 0;
    registry.view<const Material, const StaticMesh>().each(
        [&](const Material& m, const StaticMesh&) { emitters += glm::length(m.emission) > 0.f; });
    EXPECT_GE(emitters, 1u);

    const SceneInfo& info = registry.ctx().get<SceneInfo>();
    for (const int axis : {0, 2}) {
        EXPECT_GE(info.bounds.extent()[axis], 20.f);
        EXPECT_LE(info.bounds.extent()[axis], 30.f);
    }
    EXPECT_NEAR(info.bounds.min.y, 0.f, 1e-6f); // everything stands on the ground

    // The walkthrough loops in 20-30 s.
    registry.view<const Camera, const PathFollower>().each(
        [&](const Camera& c, const PathFollower& path) {
            if (!c.active) return;
            EXPECT_TRUE(path.loop);
            const float duration = path.keys.back().time - path.keys.front().time;
            EXPECT_GE(duration, 20.f);
            EXPECT_LE(duration, 30.f);
        });
    // The spot light looks at something: its axis passes within a metre of the bronze sphere.
    const Aabb sphere = worldBounds(registry, findByName(registry, "bronze sphere"));
    registry.view<const SpotLight, const Transform>().each(
        [&](const SpotLight&, const Transform& t) {
            const glm::vec3 axis = t.rotation * glm::vec3(0, 0, -1);
            const glm::vec3 toSphere = sphere.center() - t.translation;
            EXPECT_LT(glm::length(toSphere - glm::dot(toSphere, axis) * axis), 1.f);
        });
}

} // namespace
} // namespace qgi
