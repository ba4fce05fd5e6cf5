// glTF import of the known files in tests/data/gltf/good (written by make_corpus.py there):
// every expected value below is read off that script, not off the importer.

#include "runtime/scene/GltfImporter.h"
#include "runtime/scene/MeshProcessing.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneLoader.h"
#include "runtime/scene/TextureLibrary.h"

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

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <stb/stb_image_write.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>

namespace qgi {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const fs::path kGood = fs::path(QGI_TEST_DATA_DIR) / "gltf" / "good";
// An edge bound far above every file's size: meshes keep exactly the file's vertices.
const SceneOptions kNoRefinement{.maxEdgeLength = 1000.f};
// Float data passes through unchanged; composed matrices pick up a few ulps.
constexpr float kExact = 1e-6f;
constexpr float kComposed = 1e-5f;

// The 2x2 texture of make_corpus.py: red, green / blue, white at alpha 128.
const std::vector<std::uint8_t> kTexture = {255, 0, 0,   255, 0,   255, 0,   255,
                                            0,   0, 255, 255, 255, 255, 255, 128};

Entity entityNamed(const Registry& registry, std::string_view name) {
    Entity found;
    int matches = 0;
    registry.view<const Name>().each([&](Entity e, const Name& n) {
        if (n.value == name) {
            found = e;
            ++matches;
        }
    });
    EXPECT_EQ(matches, 1) << "entities named " << name;
    return found;
}

glm::vec3 apply(const glm::mat4& m, const glm::vec3& p) {
    return glm::vec3(m * glm::vec4(p, 1.f));
}

void expectNear(const glm::vec3& actual, const glm::vec3& expected, float tolerance) {
    EXPECT_NEAR(actual.x, expected.x, tolerance);
    EXPECT_NEAR(actual.y, expected.y, tolerance);
    EXPECT_NEAR(actual.z, expected.z, tolerance);
}

void expectNear(const glm::mat4& actual, const glm::mat4& expected, float tolerance) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            EXPECT_NEAR(actual[c][r], expected[c][r], tolerance) << "column " << c << " row " << r;
}

/// Index of the vertex at `p`, or -1.
int vertexAt(const Mesh& mesh, const glm::vec3& p) {
    for (std::size_t i = 0; i < mesh.positions.size(); ++i)
        if (glm::length(mesh.positions[i] - p) <= kExact) return int(i);
    return -1;
}

/// The mesh's vertices are exactly `expected`, in any order.
void expectVertexSet(const Mesh& mesh, const std::vector<glm::vec3>& expected) {
    EXPECT_EQ(mesh.positions.size(), expected.size());
    for (const glm::vec3& p : expected)
        EXPECT_GE(vertexAt(mesh, p), 0) << "no vertex at " << p.x << " " << p.y << " " << p.z;
}

TEST(GltfImport, TriangleIsPlacedByItsNode) {
    Registry registry;
    importGltf(registry, kGood / "triangle.gltf", kNoRefinement);

    ASSERT_EQ(registry.count<Mesh>(), 1u);
    const Entity e = entityNamed(registry, "Triangle");
    const Mesh& mesh = registry.get<Mesh>(e);
    expectVertexSet(mesh, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    ASSERT_EQ(mesh.indices.size(), 3u);
    for (const glm::vec3& n : mesh.normals)
        expectNear(n, {0, 0, 1}, kExact); // counter-clockwise
    EXPECT_TRUE(mesh.uvs.empty());

    const Transform& t = registry.get<Transform>(e);
    expectNear(t.translation, {1, 2, 3}, 0.f);
    EXPECT_TRUE(t.parent.isNull());
    expectNear(registry.get<WorldTransform>(e).matrix,
               glm::translate(glm::mat4(1.f), glm::vec3(1, 2, 3)), 0.f);

    EXPECT_TRUE(registry.has<StaticMesh>(e)); // the default mobility
    EXPECT_FALSE(registry.has<MobileMesh>(e));
    const Material& m = registry.get<Material>(e); // no material in the file: Material{}
    expectNear(m.baseColor, Material{}.baseColor, 0.f);
    EXPECT_EQ(m.baseColorTexture, -1);

    const SceneInfo& info = registry.ctx().get<SceneInfo>();
    EXPECT_EQ(info.name, "triangle");
    EXPECT_EQ(info.source, (kGood / "triangle.gltf").string());
    expectNear(info.bounds.min, {1, 2, 3}, kExact);
    expectNear(info.bounds.max, {2, 3, 3}, kExact);
    EXPECT_EQ(info.maxEdgeLength, 1000.f);
    EXPECT_TRUE(registry.ctx().get<TextureLibrary>().images.empty());
}

TEST(GltfImport, DefaultEdgeBoundIsOneFiftiethOfTheSceneDiagonal) {
    Registry registry;
    importGltf(registry, kGood / "triangle.gltf", SceneOptions{});

    // Bounds (1, 2, 3)..(2, 3, 3): diagonal sqrt(2).
    const float bound = registry.ctx().get<SceneInfo>().maxEdgeLength;
    EXPECT_NEAR(bound, std::sqrt(2.f) / 50.f, 1e-7f);
    const Mesh& mesh = registry.get<Mesh>(entityNamed(registry, "Triangle"));
    EXPECT_GT(mesh.positions.size(), 3u);
    for (std::size_t k = 0; k < mesh.indices.size(); k += 3)
        for (int c = 0; c < 3; ++c) {
            const glm::vec3 a = mesh.positions[mesh.indices[k + std::size_t(c)]];
            const glm::vec3 b = mesh.positions[mesh.indices[k + std::size_t((c + 1) % 3)]];
            EXPECT_LE(glm::length(a - b), bound * (1.f + 1e-5f)); // unit scale: object = world
        }
    EXPECT_NEAR(meshArea(mesh), 0.5, 1e-6); // refinement only subdivides
}

TEST(GltfImport, MatrixParentAndTrsChildComposeWorldMatrices) {
    Registry registry;
    importGltf(registry, kGood / "hierarchy.gltf", kNoRefinement);

    // The file's parent matrix: translate(0, 1, 0) * rotateY(90 degrees) * scale(2).
    const glm::mat4 parentMatrix(glm::vec4(0, 0, -2, 0), glm::vec4(0, 2, 0, 0),
                                 glm::vec4(2, 0, 0, 0), glm::vec4(0, 1, 0, 1));
    const Entity parent = entityNamed(registry, "Parent");
    const Transform& pt = registry.get<Transform>(parent);
    expectNear(pt.translation, {0, 1, 0}, kExact);
    expectNear(pt.scale, {2, 2, 2}, kExact);
    expectNear(pt.rotation * glm::vec3(1, 0, 0), {0, 0, -1}, kExact);
    expectNear(pt.rotation * glm::vec3(0, 0, 1), {1, 0, 0}, kExact);
    expectNear(registry.get<WorldTransform>(parent).matrix, parentMatrix, kExact);

    const Entity child = entityNamed(registry, "Child");
    EXPECT_EQ(registry.get<Transform>(child).parent, parent);
    const glm::mat4 childLocal =
        glm::scale(glm::rotate(glm::translate(glm::mat4(1.f), glm::vec3(1, 0, 0)),
                               glm::radians(90.f), glm::vec3(0, 0, 1)),
                   glm::vec3(1, 0.5f, 1));
    const glm::mat4 childWorld = parentMatrix * childLocal;
    expectNear(registry.get<WorldTransform>(child).matrix, childWorld, kComposed);

    const Entity leaf = entityNamed(registry, "Leaf");
    EXPECT_EQ(registry.get<Transform>(leaf).parent, child);
    expectNear(registry.get<WorldTransform>(leaf).matrix,
               childWorld * glm::translate(glm::mat4(1.f), glm::vec3(0, 0, 5)), kComposed);
    // By hand: leaf origin = parent(child(0, 0, 5)) = parent((1, 0, 5)) = (10, 1, -2).
    expectNear(apply(registry.get<WorldTransform>(leaf).matrix, {0, 0, 0}), {10, 1, -2}, kComposed);

    // Three primitives: three child entities of "Child", which holds no mesh itself.
    EXPECT_FALSE(registry.has<Mesh>(child));
    for (int k = 0; k < 3; ++k) {
        const Entity e = entityNamed(registry, "Child#" + std::to_string(k));
        EXPECT_EQ(registry.get<Transform>(e).parent, child);
        expectNear(registry.get<WorldTransform>(e).matrix, childWorld, kComposed);
        const Mesh& mesh = registry.get<Mesh>(e);
        const float z = float(k); // make_corpus.py stacks the quads at z = 0, 1, 2
        expectVertexSet(mesh, {{0, 0, z}, {1, 0, z}, {1, 1, z}, {0, 1, z}});
        EXPECT_EQ(mesh.indices.size(), 6u);
        // FLOAT, normalized UNSIGNED_BYTE and normalized UNSIGNED_SHORT texcoords: 255 and
        // 65535 are exactly 1.
        ASSERT_EQ(mesh.uvs.size(), mesh.positions.size());
        for (const glm::vec3 corner :
             {glm::vec3(1, 0, z), glm::vec3(1, 1, z), glm::vec3(0, 1, z)}) {
            const glm::vec2 uv = mesh.uvs[std::size_t(vertexAt(mesh, corner))];
            EXPECT_EQ(uv, glm::vec2(corner.x, corner.y)) << "primitive " << k;
        }
        EXPECT_TRUE(registry.has<StaticMesh>(e));
    }
    const Material& clay = registry.get<Material>(entityNamed(registry, "Child#0"));
    expectNear(clay.baseColor, {0.5f, 0.25f, 0.125f}, 0.f);
    EXPECT_EQ(clay.metallic, 0.f);
    EXPECT_EQ(clay.roughness, 0.5f);
    const Material& glow = registry.get<Material>(entityNamed(registry, "Child#1"));
    expectNear(glow.baseColor, {1, 1, 1}, 0.f); // glTF's defaults for an explicit material
    EXPECT_EQ(glow.metallic, 1.f);
    EXPECT_EQ(glow.roughness, 1.f);
    expectNear(glow.emission, {0.2f, 0.4f, 0.6f}, kExact);
    expectNear(registry.get<Material>(entityNamed(registry, "Child#2")).baseColor,
               Material{}.baseColor, 0.f);

    // A mirroring matrix decomposes with a negative x scale; one primitive lives on the node.
    const Entity mirror = entityNamed(registry, "Mirror");
    expectNear(registry.get<Transform>(mirror).scale, {-1, 1, 1}, kExact);
    const glm::mat4 mirrorWorld = registry.get<WorldTransform>(mirror).matrix;
    const Mesh& triangle = registry.get<Mesh>(mirror);
    EXPECT_EQ(triangle.positions.size(), 3u);
    for (const glm::vec3 expected : {glm::vec3(5, 0, 0), glm::vec3(4, 0, 0), glm::vec3(5, 1, 0)}) {
        bool found = false;
        for (const glm::vec3& p : triangle.positions)
            found = found || glm::length(apply(mirrorWorld, p) - expected) <= kExact;
        EXPECT_TRUE(found) << expected.x << " " << expected.y;
    }
    EXPECT_EQ(registry.count<Mesh>(), 4u);
}

TEST(GltfImport, LightsCamerasMobilityAndEmissiveStrength) {
    Registry registry;
    importGltf(registry, kGood / "lights.gltf", kNoRefinement);

    const Entity bulb = entityNamed(registry, "Bulb");
    const PointLight& point = registry.get<PointLight>(bulb);
    expectNear(point.color, {1, 0.5f, 0.25f}, 0.f);
    EXPECT_EQ(point.intensity, 10.f); // W/sr, no photometric conversion
    expectNear(apply(registry.get<WorldTransform>(bulb).matrix, {0, 0, 0}), {0, 3, 0}, 0.f);

    const Entity spotEntity = entityNamed(registry, "Spot");
    const SpotLight& spot = registry.get<SpotLight>(spotEntity);
    expectNear(spot.color, {1, 1, 1}, 0.f);
    EXPECT_EQ(spot.intensity, 20.f);
    EXPECT_FLOAT_EQ(spot.innerConeAngle, 0.2f);
    EXPECT_FLOAT_EQ(spot.outerConeAngle, 0.6f);
    // Rotated -90 degrees about x: the light's -Z axis points down.
    const glm::mat4 spotWorld = registry.get<WorldTransform>(spotEntity).matrix;
    expectNear(glm::vec3(spotWorld * glm::vec4(0, 0, -1, 0)), {0, -1, 0}, kExact);

    const DirectionalLight& sun = registry.get<DirectionalLight>(entityNamed(registry, "Sun"));
    expectNear(sun.color, {1, 1, 0.5f}, 0.f);
    EXPECT_EQ(sun.irradiance, 3.f); // W/m^2

    // cameras[0] is active although the node using cameras[1] comes first.
    const Camera& main = registry.get<Camera>(entityNamed(registry, "MainCamera"));
    EXPECT_TRUE(main.active);
    EXPECT_FLOAT_EQ(main.yfov, 0.8f);
    EXPECT_FLOAT_EQ(main.znear, 0.1f);
    EXPECT_FLOAT_EQ(main.zfar, 100.f);
    const Camera& side = registry.get<Camera>(entityNamed(registry, "SideCamera"));
    EXPECT_FALSE(side.active);
    EXPECT_FLOAT_EQ(side.yfov, 1.f);
    EXPECT_FLOAT_EQ(side.znear, 0.5f);
    // No zfar in the file: glTF's infinite projection (500 m, the component's default, had cut
    // off everything past it in a large level).
    EXPECT_EQ(side.zfar, std::numeric_limits<float>::infinity());

    // Mobility: Crate says mobile, Lid inherits it, Bolt overrides it, Lamp has the default.
    const auto tags = [&](std::string_view name) {
        const Entity e = entityNamed(registry, name);
        return std::tuple(registry.has<StaticMesh>(e), registry.has<MobileMesh>(e),
                          registry.has<Avatar>(e));
    };
    EXPECT_EQ(tags("Crate"), std::tuple(false, true, false));
    EXPECT_EQ(tags("Lid"), std::tuple(false, true, false));
    EXPECT_EQ(tags("Bolt"), std::tuple(true, false, false));
    EXPECT_EQ(tags("Walker"), std::tuple(false, false, true));
    EXPECT_EQ(tags("Lamp"), std::tuple(true, false, false));
    // Walker: the unit quad scaled by 2, world bounds 2 x 2 x 0: radius = sqrt(8) / 2.
    EXPECT_NEAR(registry.get<Avatar>(entityNamed(registry, "Walker")).radius, std::sqrt(2.f),
                kComposed);

    const Material& emitter = registry.get<Material>(entityNamed(registry, "Lamp"));
    expectNear(emitter.emission, {4, 2, 1}, kExact); // emissiveFactor x emissiveStrength 4
    expectNear(emitter.baseColor, {1, 1, 1}, 0.f);
    EXPECT_EQ(emitter.metallic, 0.25f);
    EXPECT_EQ(emitter.roughness, 0.75f);
    ASSERT_EQ(emitter.baseColorTexture, 0);
    const auto& images = registry.ctx().get<TextureLibrary>().images;
    ASSERT_EQ(images.size(), 1u);
    EXPECT_EQ(images[0].name, "checker");
    EXPECT_EQ(images[0].width, 2);
    EXPECT_EQ(images[0].height, 2);
    EXPECT_TRUE(images[0].srgb);
    EXPECT_EQ(images[0].rgba, kTexture);
}

TEST(GltfImport, GlbWithTextureInBufferView) {
    Registry registry;
    importGltf(registry, kGood / "box.glb", kNoRefinement);

    const Entity box = entityNamed(registry, "Box");
    const Mesh& mesh = registry.get<Mesh>(box);
    expectVertexSet(mesh, {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}});
    EXPECT_EQ(mesh.indices.size(), 6u);
    expectNear(registry.get<Transform>(box).translation, {0, 0, -1}, 0.f);
    EXPECT_EQ(registry.get<Material>(box).baseColorTexture, 0);
    const auto& images = registry.ctx().get<TextureLibrary>().images;
    ASSERT_EQ(images.size(), 1u);
    EXPECT_EQ(images[0].rgba, kTexture);
    EXPECT_EQ(registry.ctx().get<SceneInfo>().name, "box");
}

TEST(GltfImport, JpegTextureIsDecoded) {
    // A flat 8x8 JPEG at quality 100: only DC coefficients, quantised with step 1, so the
    // 8-bit YCbCr round trip bounds the error (about 0.5 * (1 + 1.772) + 0.5 < 2 levels).
    constexpr int kSide = 8;
    const std::uint8_t colour[3] = {200, 100, 50};
    std::vector<std::uint8_t> rgb;
    for (int i = 0; i < kSide * kSide; ++i)
        rgb.insert(rgb.end(), colour, colour + 3);
    std::string jpeg;
    ASSERT_TRUE(stbi_write_jpg_to_func(
        [](void* out, void* data, int size) {
            static_cast<std::string*>(out)->append(static_cast<const char*>(data),
                                                   std::size_t(size));
        },
        &jpeg, kSide, kSide, 3, rgb.data(), 100));

    // An external file next to the scene: also the accepted side of URI confinement.
    const fs::path dir = fs::path(::testing::TempDir()) / "qgi_gltf_jpeg";
    fs::create_directories(dir);
    std::ofstream(dir / "flat colour.jpg", std::ios::binary) << jpeg;
    const fs::path path = dir / "jpeg.gltf";
    std::ofstream(path)
        << R"({"asset": {"version": "2.0"}, "images": [{"uri": "flat%20colour.jpg"}]})";

    Registry registry;
    importGltf(registry, path, kNoRefinement);
    const auto& images = registry.ctx().get<TextureLibrary>().images;
    ASSERT_EQ(images.size(), 1u);
    ASSERT_EQ(images[0].width, kSide);
    ASSERT_EQ(images[0].height, kSide);
    for (std::size_t i = 0; i < images[0].rgba.size(); i += 4) {
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(int(images[0].rgba[i + std::size_t(c)]), int(colour[c]), 2) << i;
        EXPECT_EQ(images[0].rgba[i + 3], 255);
    }
}

/// A .gltf written from JSON plus float arrays: each array becomes a buffer view and an
/// accessor (in order) in one base64 buffer.
struct GltfWriter {
    nlohmann::json doc = {{"asset", {{"version", "2.0"}}}};
    std::vector<unsigned char> bytes;

    /// A buffer view over `size` bytes of `data`; returns its index.
    int view(const void* data, std::size_t size) {
        const std::size_t offset = bytes.size();
        const auto* p = static_cast<const unsigned char*>(data);
        bytes.insert(bytes.end(), p, p + size);
        doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", size}});
        return int(doc["bufferViews"].size() - 1);
    }
    int floats(const std::vector<float>& values, const char* type) {
        const int components = std::string(type) == "SCALAR" ? 1
                               : std::string(type) == "VEC3" ? 3
                                                             : 4;
        view(values.data(), values.size() * sizeof(float));
        nlohmann::json accessor = {{"bufferView", doc["bufferViews"].size() - 1},
                                   {"componentType", 5126},
                                   {"count", values.size() / std::size_t(components)},
                                   {"type", type}};
        if (components == 3) { // positions need their bounds
            std::vector<float> lo(3, 1e30f), hi(3, -1e30f);
            for (std::size_t i = 0; i < values.size(); ++i) {
                lo[i % 3] = std::min(lo[i % 3], values[i]);
                hi[i % 3] = std::max(hi[i % 3], values[i]);
            }
            accessor["min"] = lo;
            accessor["max"] = hi;
        }
        doc["accessors"].push_back(accessor);
        return int(doc["accessors"].size() - 1);
    }
    void write(const fs::path& path) {
        static constexpr char kDigits[] =
            "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        std::string base64;
        for (std::size_t i = 0; i < bytes.size(); i += 3) {
            const std::uint32_t n = std::uint32_t(bytes[i]) << 16 |
                                    (i + 1 < bytes.size() ? std::uint32_t(bytes[i + 1]) << 8 : 0) |
                                    (i + 2 < bytes.size() ? std::uint32_t(bytes[i + 2]) : 0);
            base64 += kDigits[n >> 18 & 63];
            base64 += kDigits[n >> 12 & 63];
            base64 += i + 1 < bytes.size() ? kDigits[n >> 6 & 63] : '=';
            base64 += i + 2 < bytes.size() ? kDigits[n & 63] : '=';
        }
        doc["buffers"] = {{{"byteLength", bytes.size()},
                           {"uri", "data:application/octet-stream;base64," + base64}}};
        std::ofstream(path) << doc.dump();
    }
};

TEST(GltfImport, GeometryDroppedAsDegenerateDoesNotSetTheDefaultEdgeBound) {
    // A unit triangle, and beside it a zero-area triangle along a 20 km line: dropped, it must
    // not stretch the scene the default edge bound (and from it the disc radius) scales with.
    GltfWriter w;
    const int triangle = w.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    const int line = w.floats({-1e4f, 0, 0, 0, 0, 0, 1e4f, 0, 0}, "VEC3");
    w.doc["meshes"] = {{{"primitives", {{{"attributes", {{"POSITION", triangle}}}}}}},
                       {{"primitives", {{{"attributes", {{"POSITION", line}}}}}}}};
    w.doc["nodes"] = {{{"name", "Triangle"}, {"mesh", 0}}, {{"name", "Line"}, {"mesh", 1}}};
    w.doc["scenes"] = {{{"nodes", {0, 1}}}};
    const fs::path path = fs::path(::testing::TempDir()) / "qgi_degenerate_line.gltf";
    w.write(path);
    Registry registry;
    importGltf(registry, path, SceneOptions{});
    const SceneInfo& info = registry.ctx().get<SceneInfo>();
    EXPECT_NEAR(info.maxEdgeLength, std::sqrt(2.f) / 50.f, 1e-7f); // the triangle's diagonal
    EXPECT_EQ(registry.count<Mesh>(), 1u);
    expectNear(info.bounds.max, {1, 1, 0}, kExact);
    fs::remove(path);
}

TEST(GltfImport, AnimationsBecomeScriptedPathsOfMobiles) {
    GltfWriter w;
    const int triangle = w.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    w.doc["meshes"] = {{{"primitives", {{{"attributes", {{"POSITION", triangle}}}}}}}};
    w.doc["nodes"] = {{{"name", "Crate"}, {"mesh", 0}, {"extras", {{"mobility", "mobile"}}}},
                      {{"name", "Wall"}, {"mesh", 0}, {"translation", {0, 0, -3}}},
                      {{"name", "Cart"}, {"mesh", 0}, {"extras", {{"mobility", "mobile"}}}}};
    w.doc["scenes"] = {{{"nodes", {0, 1, 2}}}};
    const float h = std::sqrt(0.5f);
    const int t3 = w.floats({0, 1, 2}, "SCALAR");
    const int moves = w.floats({0, 0, 0, 1, 0, 0, 1, 2, 0}, "VEC3");
    const int t2 = w.floats({0.5f, 1.5f}, "SCALAR");
    const int turns = w.floats({0, 0, 0, 1, 0, h, 0, h}, "VEC4"); // identity, 90 deg about y
    const int wallMoves = w.floats({0, 0, -3, 0, 1, -3}, "VEC3");
    const int t01 = w.floats({0, 1}, "SCALAR");
    // Cubic spline: (in-tangent, value, out-tangent) per key.
    const int spline = w.floats({9, 9, 9, 5, 0, 0, 9, 9, 9, 9, 9, 9, 6, 0, 0, 9, 9, 9}, "VEC3");
    w.doc["animations"] = {
        {{"samplers",
          {{{"input", t3}, {"output", moves}},
           {{"input", t2}, {"output", turns}, {"interpolation", "STEP"}},
           {{"input", t01}, {"output", wallMoves}},
           {{"input", t01}, {"output", spline}, {"interpolation", "CUBICSPLINE"}}}},
         {"channels",
          {{{"sampler", 0}, {"target", {{"node", 0}, {"path", "translation"}}}},
           {{"sampler", 1}, {"target", {{"node", 0}, {"path", "rotation"}}}},
           {{"sampler", 2}, {"target", {{"node", 1}, {"path", "translation"}}}},
           {{"sampler", 0}, {"target", {{"node", 0}, {"path", "scale"}}}},
           {{"sampler", 3}, {"target", {{"node", 2}, {"path", "translation"}}}}}}}};
    const fs::path path = fs::path(::testing::TempDir()) / "animated.gltf";
    w.write(path);
    Registry registry;
    importGltf(registry, path, kNoRefinement);

    // The crate: keys at both channels' times, and just before the held rotation changes.
    const PathFollower* crate = registry.tryGet<PathFollower>(entityNamed(registry, "Crate"));
    ASSERT_NE(crate, nullptr);
    EXPECT_TRUE(crate->loop);
    const std::vector<float> times{0.f, 0.5f, 1.f, 1.5f - 1e-3f, 1.5f, 2.f};
    ASSERT_EQ(crate->keys.size(), times.size());
    const glm::quat identity(1.f, 0.f, 0.f, 0.f);
    const glm::quat quarter = glm::angleAxis(glm::half_pi<float>(), glm::vec3(0, 1, 0));
    for (std::size_t k = 0; k < times.size(); ++k) {
        SCOPED_TRACE(k);
        EXPECT_NEAR(crate->keys[k].time, times[k], 1e-6f);
        const float t = times[k];
        const glm::vec3 position = t <= 1.f ? glm::vec3(t, 0, 0) : glm::vec3(1, 2 * (t - 1), 0);
        EXPECT_NEAR(glm::length(crate->keys[k].position - position), 0.f, 1e-5f);
        const glm::quat expected = t < 1.5f ? identity : quarter; // STEP holds each value
        EXPECT_NEAR(std::abs(glm::dot(crate->keys[k].rotation, expected)), 1.f, 1e-6f);
    }
    // The wall is static: its animation is ignored. The cart's spline keeps its values.
    EXPECT_FALSE(registry.has<PathFollower>(entityNamed(registry, "Wall")));
    const PathFollower* cart = registry.tryGet<PathFollower>(entityNamed(registry, "Cart"));
    ASSERT_NE(cart, nullptr);
    ASSERT_EQ(cart->keys.size(), 2u);
    EXPECT_EQ(cart->keys[0].position, glm::vec3(5, 0, 0));
    EXPECT_EQ(cart->keys[1].position, glm::vec3(6, 0, 0));
    fs::remove(path);
}

TEST(GltfImport, ValidButUnusualFilesLoad) {
    // Valid glTF that qgi cannot use as given: it adapts, with a warning, instead of refusing.
    const fs::path dir = fs::path(QGI_TEST_DATA_DIR) / "gltf" / "unusual";
    const auto meshCount = [](const Registry& r) { return r.view<const Mesh>().entities().size(); };
    {
        Registry r; // a LINES primitive has no surface: skipped
        importGltf(r, dir / "lines_only.gltf", kNoRefinement);
        EXPECT_EQ(meshCount(r), 0u);
    }
    {
        Registry r; // a node scaled to nothing hides its mesh
        importGltf(r, dir / "mesh_node_flat_scale.gltf", kNoRefinement);
        EXPECT_EQ(meshCount(r), 0u);
    }
    {
        Registry r; // a camera whose node scales to zero sees nothing: not imported
        importGltf(r, dir / "camera_zero_scale.gltf", kNoRefinement);
        EXPECT_TRUE(r.view<const Camera>().entities().empty());
        EXPECT_EQ(meshCount(r), 1u);
    }
    {
        Registry r; // a field of view just under pi is narrowed to what projection resolves
        importGltf(r, dir / "camera_fov_near_pi.gltf", kNoRefinement);
        const auto cameras = r.view<const Camera>().entities();
        ASSERT_EQ(cameras.size(), 1u);
        EXPECT_LT(r.get<Camera>(cameras.front()).yfov, 3.14f);
        EXPECT_GT(r.get<Camera>(cameras.front()).yfov, 3.13f);
    }
}

TEST(GltfImport, SparseAccessorsAndAccessorsWithoutDataAreRead) {
    // A unit quad whose third corner a sparse accessor lifts to z = 1, with texture
    // coordinates from an accessor that has no buffer view (all zeros, per the spec).
    GltfWriter w;
    const int base = w.floats({0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}, "VEC3");
    const std::vector<std::uint32_t> which{2};
    const std::vector<float> lifted{1, 1, 1};
    const int indexView = w.view(which.data(), 4);
    const int valueView = w.view(lifted.data(), 12);
    w.doc["accessors"][std::size_t(base)]["sparse"] = {
        {"count", 1},
        {"indices", {{"bufferView", indexView}, {"componentType", 5125}}},
        {"values", {{"bufferView", valueView}}}};
    w.doc["accessors"][std::size_t(base)]["max"] = {1, 1, 1};
    w.doc["accessors"].push_back({{"componentType", 5126}, {"count", 4}, {"type", "VEC2"}});
    const std::vector<std::uint16_t> corners{0, 1, 2, 0, 2, 3};
    const int indexData = w.view(corners.data(), 12);
    w.doc["accessors"].push_back(
        {{"bufferView", indexData}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}});
    w.doc["meshes"] = {
        {{"primitives",
          {{{"attributes", {{"POSITION", base}, {"TEXCOORD_0", 1}}}, {"indices", 2}}}}}};
    w.doc["nodes"] = {{{"name", "Quad"}, {"mesh", 0}}};
    w.doc["scenes"] = {{{"nodes", {0}}}};
    const fs::path path = fs::path(::testing::TempDir()) / "sparse.gltf";
    w.write(path);
    Registry registry;
    importGltf(registry, path, kNoRefinement);
    const Mesh& mesh = registry.get<Mesh>(entityNamed(registry, "Quad"));
    // (The lifted corner folds the quad along its diagonal, a crease: the corners on it get a
    // normal per side, so there are more than four vertices.)
    int raised = 0, flat = 0;
    for (const glm::vec3& p : mesh.positions) {
        raised += p == glm::vec3(1, 1, 1);
        flat += p == glm::vec3(1, 1, 0);
    }
    EXPECT_GE(raised, 1);
    EXPECT_EQ(flat, 0);
    ASSERT_EQ(mesh.uvs.size(), mesh.positions.size());
    for (const glm::vec2& uv : mesh.uvs)
        EXPECT_EQ(uv, glm::vec2(0.f));
    fs::remove(path);
}

/// An accessor of `count` zero positions: no buffer view (a few bytes of JSON that glTF lets
/// stand for any number of zeros).
int zeroPositions(GltfWriter& w, std::size_t count) {
    w.doc["accessors"].push_back({{"componentType", 5126},
                                  {"count", count},
                                  {"type", "VEC3"},
                                  {"min", {0, 0, 0}},
                                  {"max", {0, 0, 0}}});
    return int(w.doc["accessors"].size() - 1);
}

/// Imports `w` and returns the error's message ("" when it loads), checking that a failed
/// import left the registry empty.
std::string importError(GltfWriter& w, const char* name) {
    const fs::path path = fs::path(::testing::TempDir()) / name;
    w.write(path);
    Registry registry;
    std::string message;
    try {
        importGltf(registry, path, kNoRefinement);
    } catch (const Error& e) {
        message = e.what();
        EXPECT_EQ(registry.aliveCount(), 0u);
    }
    fs::remove(path);
    return message;
}

TEST(GltfImport, ZeroPositionsDeclaringMoreTrianglesThanASceneHoldsAreRefusedBeforeDecoding) {
    // 3 * kSceneMaxTriangles + 3 zeros as a triangle list: one triangle over the limit, in
    // a few hundred bytes of JSON that would decode to 1.4 GB.
    GltfWriter w;
    const float unused[3] = {};
    w.view(unused, sizeof unused); // the file's buffer may not be empty
    const std::size_t count = 3 * std::size_t(kSceneMaxTriangles) + 3;
    const int zeros = zeroPositions(w, count);
    w.doc["meshes"] = {{{"primitives", {{{"attributes", {{"POSITION", zeros}}}}}}}};
    w.doc["nodes"] = {{{"mesh", 0}}};
    w.doc["scenes"] = {{{"nodes", {0}}}};
    const std::string message = importError(w, "zero_triangles.gltf");
    EXPECT_THAT(message, HasSubstr("zero_triangles.gltf: meshes[0].primitives[0]: "
                                   "accessors[0].count " +
                                   std::to_string(count)));
    EXPECT_THAT(message, HasSubstr("20000001 triangles, more than the limit of 2e+07"));
}

TEST(GltfImport, AccessorsDecodingToMoreThanTheFileLimitTogetherAreRefusedBeforeTheLastOne) {
    // A real triangle (36 bytes decoded), then a second primitive with one triangle over
    // zero positions that alone decode to exactly kGltfMaxDecodedBytes (12 bytes of zeros
    // and 12 of positions each): together 36 bytes over the limit.
    GltfWriter w;
    const int triangle = w.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    const std::size_t count = std::size_t(kGltfMaxDecodedBytes / 24);
    ASSERT_EQ(count * 24, kGltfMaxDecodedBytes);
    ASSERT_LE(count * 12, kGltfMaxFileBytes); // within the limit on one accessor
    const int zeros = zeroPositions(w, count);
    const std::vector<std::uint16_t> corners{0, 1, 2};
    const int cornerView = w.view(corners.data(), 6);
    w.doc["accessors"].push_back(
        {{"bufferView", cornerView}, {"componentType", 5123}, {"count", 3}, {"type", "SCALAR"}});
    w.doc["meshes"] = {{{"primitives",
                         {{{"attributes", {{"POSITION", triangle}}}},
                          {{"attributes", {{"POSITION", zeros}}}, {"indices", 2}}}}}};
    w.doc["nodes"] = {{{"mesh", 0}}};
    w.doc["scenes"] = {{{"nodes", {0}}}};
    const std::string message = importError(w, "zero_bytes.gltf");
    EXPECT_THAT(message,
                HasSubstr("zero_bytes.gltf: accessors[1].count: " + std::to_string(count) +
                          " elements read as meshes[0].primitives[1].attributes.POSITION"));
    EXPECT_THAT(message, HasSubstr(str("to ", kGltfMaxDecodedBytes + 36,
                                       " bytes, over the limit of ", kGltfMaxDecodedBytes)));
}

TEST(GltfImport, AnImageNoMaterialDrawsMayBeUndecodable) {
    // An optional extension's image (here just bytes that are no PNG) next to what materials
    // draw: it becomes one white pixel, and the file loads.
    GltfWriter w;
    const int triangle = w.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    w.doc["meshes"] = {{{"primitives", {{{"attributes", {{"POSITION", triangle}}}}}}}};
    w.doc["nodes"] = {{{"name", "Triangle"}, {"mesh", 0}}};
    w.doc["scenes"] = {{{"nodes", {0}}}};
    w.doc["images"] = {{{"uri", "data:image/png;base64,UklGRgAAAABXRUJQ"}}}; // WebP bytes
    const fs::path path = fs::path(::testing::TempDir()) / "unused_image.gltf";
    w.write(path);
    Registry registry;
    importGltf(registry, path, kNoRefinement);
    const TextureLibrary& library = registry.ctx().get<TextureLibrary>();
    ASSERT_EQ(library.images.size(), 1u);
    EXPECT_EQ(library.images[0].width, 1);
    EXPECT_EQ(library.images[0].rgba, (std::vector<std::uint8_t>{255, 255, 255, 255}));
    fs::remove(path);
}

TEST(GltfImport, StripsAndFansBecomeTriangleLists) {
    GltfWriter w;
    // Five vertices along a zigzag make a strip of three triangles, all facing -z; five around
    // the origin make a fan of three (the first vertex with each later pair), facing +z.
    const int zigzag = w.floats({0, 0, 0, 0, 1, 0, 1, 0, 0, 1, 1, 0, 2, 0, 0}, "VEC3");
    const int around = w.floats({0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, -1, 1, 0}, "VEC3");
    w.doc["meshes"] = {{{"primitives", {{{"attributes", {{"POSITION", zigzag}}}, {"mode", 5}}}}},
                       {{"primitives", {{{"attributes", {{"POSITION", around}}}, {"mode", 6}}}}}};
    w.doc["nodes"] = {{{"name", "Strip"}, {"mesh", 0}}, {{"name", "Fan"}, {"mesh", 1}}};
    w.doc["scenes"] = {{{"nodes", {0, 1}}}};
    const fs::path path = fs::path(::testing::TempDir()) / "strips.gltf";
    w.write(path);
    Registry registry;
    importGltf(registry, path, kNoRefinement);
    // The strip alternates its winding, so no triangle flips.
    for (const char* name : {"Strip", "Fan"}) {
        SCOPED_TRACE(name);
        const Mesh& mesh = registry.get<Mesh>(entityNamed(registry, name));
        ASSERT_EQ(mesh.indices.size(), 9u);
        for (std::size_t t = 0; t < 9; t += 3) {
            const glm::vec3 a = mesh.positions[mesh.indices[t]];
            const glm::vec3 b = mesh.positions[mesh.indices[t + 1]];
            const glm::vec3 c = mesh.positions[mesh.indices[t + 2]];
            EXPECT_GT(glm::cross(b - a, c - a).z * (std::string(name) == "Fan" ? 1.f : -1.f), 0.f)
                << "triangle " << t / 3;
        }
    }
    fs::remove(path);
}

TEST(GltfImport, LoadSceneTakesGltfPathsAndNamesTheBuiltinsOnATypo) {
    Registry registry;
    loadScene(registry, (kGood / "box.glb").string(), kNoRefinement);
    EXPECT_EQ(registry.ctx().get<SceneInfo>().name, "box");
    EXPECT_EQ(registry.count<Mesh>(), 1u);

    Registry empty;
    try {
        loadScene(empty, "cornel", kNoRefinement);
        ADD_FAILURE() << "an unknown name was accepted";
    } catch (const Error& e) {
        const std::string message = e.what();
        for (const std::string& name : builtinSceneNames())
            EXPECT_NE(message.find(name), std::string::npos) << message;
    }
    EXPECT_EQ(empty.aliveCount(), 0u);
}

TEST(GltfImport, JsonNestingDepthIgnoresBracketsInStrings) {
    EXPECT_EQ(jsonNestingDepth(""), 0);
    EXPECT_EQ(jsonNestingDepth("[]"), 1);
    EXPECT_EQ(jsonNestingDepth(R"({"a": [[1], {"b": []}], "c": {}})"), 4);
    EXPECT_EQ(jsonNestingDepth(R"(["[[[{{", "\"[[", "\\"])"), 1);
    EXPECT_EQ(jsonNestingDepth(std::string(10000, '[') + std::string(10000, ']')), 10000);
}

TEST(GltfImport, DecomposeTrsRecoversTranslationRotationAndScale) {
    std::mt19937 random(1234);
    std::uniform_real_distribution<float> uniform(-1.f, 1.f);
    for (int trial = 0; trial < 200; ++trial) {
        const glm::vec3 translation(10.f * uniform(random), 10.f * uniform(random),
                                    10.f * uniform(random));
        const glm::quat rotation = glm::normalize(
            glm::quat(uniform(random), uniform(random), uniform(random), uniform(random)));
        // Positive scales in [0.1, 3.1]; the sign of a mirror is not unique, tested below.
        const glm::vec3 scale(1.6f + 1.5f * uniform(random), 1.6f + 1.5f * uniform(random),
                              1.6f + 1.5f * uniform(random));
        const glm::mat4 m = glm::translate(glm::mat4(1.f), translation) * glm::mat4_cast(rotation) *
                            glm::scale(glm::mat4(1.f), scale);
        const std::optional<Transform> t = decomposeTrs(m);
        ASSERT_TRUE(t) << trial;
        expectNear(t->translation, translation, 0.f);
        expectNear(t->scale, scale, 1e-5f * 3.1f);
        EXPECT_NEAR(std::abs(glm::dot(t->rotation, rotation)), 1.f, 1e-5f) << trial; // q ~ -q
    }
    // A mirror in y comes back as a mirror in x composed with a half turn about z: same matrix.
    const glm::mat4 mirror = glm::scale(glm::mat4(1.f), glm::vec3(1, -1, 1));
    const std::optional<Transform> t = decomposeTrs(mirror);
    ASSERT_TRUE(t);
    EXPECT_LT(t->scale.x, 0.f);
    expectNear(t->rotation * (t->scale * glm::vec3(1, 2, 3)), glm::vec3(1, -2, 3), kExact);

    glm::mat4 shear(1.f);
    shear[1][0] = 0.5f;
    EXPECT_FALSE(decomposeTrs(shear));
    glm::mat4 projective(1.f);
    projective[2][3] = -1.f;
    EXPECT_FALSE(decomposeTrs(projective));
    EXPECT_FALSE(decomposeTrs(glm::scale(glm::mat4(1.f), glm::vec3(1, 0, 1))));
    glm::mat4 nan(1.f);
    nan[3][0] = std::nanf("");
    EXPECT_FALSE(decomposeTrs(nan));
}

} // namespace
} // namespace qgi
