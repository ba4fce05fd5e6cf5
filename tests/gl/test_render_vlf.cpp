// GL test of the VLF lookup in the scene shader (runs under `xvfb-run -a`): a room whose floor
// is a mirror and whose walls emit, seen from above; every floor pixel must show what the CPU
// lookup (Vlf::specularRadiance, tested against closed forms in test_vlf_bake) gives for the
// same point and view direction, within what the rasterizer's vertex snapping and float
// rounding of that point can change.
#include "GlTestWindow.h"
#include "components/Camera.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/render/GlWindow.h"
#include "runtime/render/RenderScene.h"
#include "systems/render/RenderSystem.h"
#include "systems/vlf/VlfField.h"
#include "systems/vlf/VlfSystem.h"
#include "tests/unit/test_meshes.h"

#include <epoxy/gl.h>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <optional>
#include <string>

namespace qgi {
namespace {

constexpr int kSize = 96;

using test::quadMesh;

Entity addQuad(Registry& world, const Mesh& mesh, const Material& material) {
    const Entity e = world.create();
    world.emplace<Mesh>(e, mesh);
    world.emplace<WorldTransform>(e);
    world.emplace<Material>(e, material);
    world.emplace<StaticMesh>(e);
    return e;
}

Material emitter(float L) {
    Material m;
    m.baseColor = glm::vec3(0.f);
    m.emission = glm::vec3(L, 0.5f * L, 0.25f * L);
    return m;
}

/// Bakes the world's VLF (no cache file) at a small resolution.
void bakeField(Registry& world, int level, int lines, int tile, int iterations) {
    VlfSystemSettings vs;
    vs.bake.directionLevel = level;
    vs.bake.linesPerSide = lines;
    vs.bake.tileSize = tile;
    vs.bake.iterations = iterations;
    VlfSystem(vs).build(world);
}

/// One frame of the world at kSize x kSize in `mode`, its linear radiance.
ImageF renderFrame(Registry& world, ShadingMode mode) {
    RenderSettings rs;
    rs.width = kSize;
    rs.height = kSize;
    rs.mode = mode;
    RenderSystem renderer(rs);
    renderer.update(world, FrameContext{});
    return renderer.readHdr();
}

/// The floor of the room below: y = 0, facing up. With `faceBelowFirst`, the same entity
/// first holds a second specular face, 1 cm under the floor and facing down (out of view, and
/// nothing reaches it), so the shader has to pick the floor out of the item's two faces.
Mesh floorMesh(bool faceBelowFirst) {
    const Mesh floor = quadMesh({-1, 0, 1}, {2, 0, 0}, {0, 0, -2});
    if (!faceBelowFirst) return floor;
    Mesh mesh = quadMesh({-1, -0.01f, 1}, {0, 0, -2}, {2, 0, 0});
    const auto base = std::uint32_t(mesh.positions.size());
    mesh.positions.insert(mesh.positions.end(), floor.positions.begin(), floor.positions.end());
    mesh.normals.insert(mesh.normals.end(), floor.normals.begin(), floor.normals.end());
    for (const std::uint32_t i : floor.indices)
        mesh.indices.push_back(base + i);
    return mesh;
}

/// A room of emitting walls around a floor of material `floor` (specular, no diffuse part),
/// seen from above: every floor pixel against the CPU lookup, every wall pixel against its
/// emission. The walls' radiance is `brightness` times 0.5 to 3 W/(m^2 sr).
void expectShaderLookupMatchesTheCpuLookup(const Material& floor, bool faceBelowFirst = false,
                                           float brightness = 1.f) {
    QGI_SKIP_WITHOUT_GL();
    GlWindow window(test::testWindow(kSize, kSize, "qgi test_render_vlf"));
    {
        Registry world;
        // Room [-1,1] x [0,2] x [-1,1], faces inwards; walls of different radiance.
        addQuad(world, floorMesh(faceBelowFirst), floor);                           // floor, +y
        addQuad(world, quadMesh({-1, 2, -1}, {2, 0, 0}, {0, 0, 2}),
                emitter(0.5f * brightness)); // ceiling
        addQuad(world, quadMesh({-1, 0, -1}, {2, 0, 0}, {0, 2, 0}),
                emitter(brightness)); // back, +z
        addQuad(world, quadMesh({1, 0, 1}, {-2, 0, 0}, {0, 2, 0}),
                emitter(1.5f * brightness)); // front, -z
        addQuad(world, quadMesh({-1, 0, 1}, {0, 0, -2}, {0, 2, 0}),
                emitter(2.f * brightness)); // left, +x
        addQuad(world, quadMesh({1, 0, -1}, {0, 0, 2}, {0, 2, 0}),
                emitter(3.f * brightness)); // right, -x
        const glm::vec3 eye(0.2f, 1.6f, 0.5f);
        const Entity cam = world.create();
        world.emplace<Camera>(cam, Camera{1.2f, 0.05f, 20.f, true});
        // Looking down at the floor, tilted.
        const glm::mat4 pose =
            glm::inverse(glm::lookAt(eye, glm::vec3(-0.1f, 0.f, -0.2f), glm::vec3(0, 0, -1)));
        world.emplace<WorldTransform>(cam, WorldTransform{pose});

        bakeField(world, 3, 32, 8, 2);
        const VlfField& field = world.ctx().get<VlfField>();
        ASSERT_EQ(field.vlf.specularFaceCount(), faceBelowFirst ? 2u : 1u);
        // The CPU lookup reads the cells as the renderer's atlas holds them (half floats times
        // a power of two): the shader is held to it.
        if (brightness > 1e4f) {
            ASSERT_GT(field.vlf.cellScale(), 1.f) << "the atlas is not scaled";
        }

        // Photon mode, no direct light: the floor shows the VLF alone.
        const ImageF hdr = renderFrame(world, ShadingMode::Photon);

        // The pixel rays (square image) in double from the camera's float pose: their rounding
        // is far below the GPU's.
        const double tanHalf = std::tan(0.5 * double(world.get<Camera>(cam).yfov));
        const glm::dmat3 orientation(pose);
        const glm::dvec3 eyeAt(pose[3]);
        const std::uint32_t face = field.vlf.specularFace(faceBelowFirst ? 1 : 0);
        ASSERT_GT(field.vlf.faces()[face].normal.y, 0.99f); // the floor
        const auto lookup = [&](const glm::dvec3& p) {
            return field.vlf.specularRadiance(face, glm::vec3(p),
                                              glm::vec3(glm::normalize(eyeAt - p)));
        };
        // Where the GPU's floor point may lie. The rasterizer snaps vertices to its sub-pixel
        // grid (2^-GL_SUBPIXEL_BITS of a pixel), so the position a pixel interpolates is that
        // of a point whose ray passes up to that far from the pixel centre in x and y: about
        // 8e-5 m on this floor, where NVIDIA's pixels showed the lookup up to 3.6 times the
        // allowance below away from the centre's value. That position is interpolated in
        // float (planes of p/w and 1/w evaluated at the pixel, then divided), some 16 roundings
        // of terms below 2 m, each up to 2^-23 m: ~2e-6 m; the view direction it takes from
        // that point rounds by ~2^-23 rad, < 1e-6 m at the <= 2.5 m from the eye. kEpsilon
        // covers both with a factor above 2. So the GPU may show any value the lookup takes at
        // the points of the rays through the square of +-rayOffset pixels about the centre,
        // each widened by kEpsilon along either floor axis. The lookup is piecewise bilinear in
        // the point: over so small a square its range is that of the corners and edge
        // midpoints.
        GLint subpixelBits = 0;
        glGetIntegerv(GL_SUBPIXEL_BITS, &subpixelBits);
        const double rayOffset = std::ldexp(1.0, -subpixelBits); // pixels
        constexpr double kEpsilon = 0x1p-17;                     // metres, 7.6e-6
        // The lookup's own arithmetic: ~20 roundings of positive terms in each blend (12 cells,
        // 3 corners, the divisions), ~10 more in the weights, whose errors a contrast of up to
        // 6 between neighbouring cells amplifies; on both sides: 2 (20 + 6 * 10) 2^-24 < 2^-16.
        // The CPU lookup reads the cells the atlas holds (above), so their half-float rounding
        // is on both sides; the shader's multiplication by the scale after the blend, where the
        // CPU's cells were multiplied before it, adds a rounding or two.
        constexpr double kRounding = 0x1p-16; // relative
        int floorPixels = 0, failed = 0, lit = 0, loose = 0, wallPixels = 0, wrongWalls = 0;
        // The walls show their emission and nothing else (black, no irradiance, photon mode):
        // where a pixel's ray leaves the room through one wall, 2 cm and more from its rims,
        // it must read that emission exactly (a VLF lookup leaking onto them would not).
        const auto wallEmission = [&](const glm::dvec3& dir) -> std::optional<glm::vec3> {
            double t[3];
            for (int a = 0; a < 3; ++a) {
                const double low = a == 1 ? 0.0 : -1.0, high = a == 1 ? 2.0 : 1.0;
                t[a] = dir[a] > 0   ? (high - eyeAt[a]) / dir[a]
                       : dir[a] < 0 ? (low - eyeAt[a]) / dir[a]
                                    : std::numeric_limits<double>::infinity();
            }
            const int axis = t[0] < t[1] ? (t[0] < t[2] ? 0 : 2) : (t[1] < t[2] ? 1 : 2);
            const glm::dvec3 hit = eyeAt + t[axis] * dir;
            for (int a = 0; a < 3; ++a) {
                const double low = a == 1 ? 0.0 : -1.0, high = a == 1 ? 2.0 : 1.0;
                if (a != axis && (hit[a] < low + 0.02 || hit[a] > high - 0.02)) return std::nullopt;
            }
            if (axis == 1) // the floor (the mirror) or the ceiling
                return dir.y < 0 ? std::nullopt
                                 : std::optional(emitter(0.5f * brightness).emission);
            if (axis == 2) return emitter((dir.z < 0 ? 1.f : 1.5f) * brightness).emission;
            return emitter((dir.x < 0 ? 2.f : 3.f) * brightness).emission;
        };
        double worst = 0, widest = 0;
        for (int y = 0; y < kSize; ++y)
            for (int x = 0; x < kSize; ++x) {
                // A point of the pixel (top row first; centre at 0.5, 0.5) -> its floor point.
                const auto floorAt = [&](double px, double py) -> std::optional<glm::dvec3> {
                    const double ndcX = 2.0 * px / kSize - 1.0;
                    const double ndcY = 1.0 - 2.0 * py / kSize;
                    const glm::dvec3 dir =
                        orientation *
                        glm::normalize(glm::dvec3(ndcX * tanHalf, ndcY * tanHalf, -1.0));
                    if (dir.y >= -1e-3) return std::nullopt;
                    return eyeAt + (-eyeAt.y / dir.y) * dir;
                };
                const std::optional<glm::dvec3> centre = floorAt(x + 0.5, y + 0.5);
                const glm::dvec3 ray =
                    orientation *
                    glm::normalize(glm::dvec3((2.0 * (x + 0.5) / kSize - 1.0) * tanHalf,
                                              (1.0 - 2.0 * (y + 0.5) / kSize) * tanHalf, -1.0));
                if (const std::optional<glm::vec3> wall = wallEmission(ray)) {
                    ++wallPixels;
                    const float* got = hdr.pixel(x, y);
                    // Emission passes the shader unchanged but for float rounding.
                    bool same = true;
                    for (int c = 0; c < 3; ++c)
                        same &= std::abs(got[c] - (*wall)[c]) <= 1e-6f * (*wall)[c];
                    wrongWalls += !same;
                    continue;
                }
                if (!centre) continue;
                const glm::dvec3 p = *centre;
                if (std::abs(p.x) > 0.98 || std::abs(p.z) > 0.98) continue; // away from walls
                ++floorPixels;
                const glm::vec3 expected = lookup(p);
                glm::dvec3 spread(0.0);
                for (int a = -1; a <= 1; ++a)
                    for (int b = -1; b <= 1; ++b) {
                        const std::optional<glm::dvec3> q =
                            floorAt(x + 0.5 + a * rayOffset, y + 0.5 + b * rayOffset);
                        if (!q) continue;
                        for (int i = -1; i <= 1; ++i)
                            for (int j = -1; j <= 1; ++j)
                                spread = glm::max(
                                    spread, glm::abs(glm::dvec3(lookup(
                                                         *q + kEpsilon * glm::dvec3(i, 0, j))) -
                                                     glm::dvec3(expected)));
                    }
                const float* got = hdr.pixel(x, y);
                bool ok = true, wide = false;
                for (int c = 0; c < 3; ++c) {
                    const double allowed = spread[c] + kRounding * expected[c];
                    const double error = std::abs(double(got[c]) - double(expected[c]));
                    ok &= error <= allowed; // false for NaN
                    if (allowed > 0.0) worst = std::max(worst, error / allowed);
                    if (expected[c] > 0.f) widest = std::max(widest, allowed / expected[c]);
                    wide |= spread[c] > 1e-3 * expected[c]; // beyond the rounding
                }
                failed += !ok;
                loose += wide;
                lit += expected.x > 0.f;
            }
        ::testing::Test::RecordProperty("floorPixels", floorPixels);
        ::testing::Test::RecordProperty("wallPixels", wallPixels);
        ::testing::Test::RecordProperty("failedPixels", failed);
        ::testing::Test::RecordProperty("pixelsWithASpreadOver1e-3", loose);
        ::testing::Test::RecordProperty("widestAllowance", std::to_string(widest));
        ::testing::Test::RecordProperty("worstErrorOverAllowance", std::to_string(worst));
        ASSERT_GT(floorPixels, kSize * kSize / 3);
        EXPECT_GT(wallPixels, 100);
        EXPECT_EQ(wrongWalls, 0) << "of " << wallPixels << " wall pixels";
        // The allowance's spread (what it takes beyond the rounding) is wide only near the
        // lookup's steps: at most a third of the floor (a quarter today), so that a
        // discontinuity cannot widen the test unseen.
        EXPECT_LT(loose, floorPixels / 3);
        EXPECT_GT(lit, floorPixels * 9 / 10);
        EXPECT_EQ(failed, 0) << failed << " of " << floorPixels
                             << " floor pixels outside their allowance; worst error " << worst
                             << " times its allowance";
    }
}

/// A floor that reflects only specularly: k_s `specular`, Phong exponent `exponent` (0: a
/// mirror).
Material specularFloor(const glm::vec3& specular, float exponent) {
    Material m;
    m.baseColor = glm::vec3(0.f);
    m.specular = specular;
    m.phongExponent = exponent;
    return m;
}

TEST(RenderVlf, ShaderLookupMatchesTheCpuLookupOnAMirror) {
    expectShaderLookupMatchesTheCpuLookup(specularFloor({0.8f, 0.7f, 0.6f}, 0.f));
}

TEST(RenderVlf, ShaderLookupMatchesTheCpuLookupOnAGlossyFloor) {
    // The glossy branch: the tiles hold outgoing radiance, looked up along the view direction.
    expectShaderLookupMatchesTheCpuLookup(specularFloor({0.6f, 0.5f, 0.4f}, 20.f));
}

TEST(RenderVlf, ShaderLookupMatchesTheCpuLookupOnAMirrorOfLampsTooBrightForHalfFloats) {
    // Walls of up to 3e5 W/(m^2 sr): the atlas holds the cells divided by a power of two
    // (vlf::packCells), which the shader multiplies back.
    expectShaderLookupMatchesTheCpuLookup(specularFloor({0.8f, 0.7f, 0.6f}, 0.f), false, 1e5f);
}

TEST(RenderVlf, ShaderPicksTheFaceUnderTheFragmentOfATwoFaceMirror) {
    // The item's faces are consecutive in the field, the floor second: the shader's loop over
    // them, and the renderer's range of them, must find the floor for every floor pixel.
    expectShaderLookupMatchesTheCpuLookup(specularFloor({0.8f, 0.7f, 0.6f}, 0.f), true);
}

TEST(RenderVlf, APolishedMetalIsDrawnWithItsDiffusePartOnly) {
    // glTF metallic-roughness: a metal the VLF reads as specular (k_s = metallic) keeps only
    // k_d = baseColor (1 - metallic) as its diffuse albedo, or it would reflect more than it
    // receives; a rough one stays diffuse with albedo baseColor. The floor's two halves, lit
    // by the same vertex irradiance E, photon mode, seen from straight above. Their mirror
    // images show only the black sky (the lamp that lets the VLF bake lies far to the side),
    // so each pixel is albedo / pi * E.
    QGI_SKIP_WITHOUT_GL();
    GlWindow window(test::testWindow(kSize, kSize, "qgi test_render_vlf"));
    {
        Registry world;
        Material polished, rough;
        polished.baseColor = rough.baseColor = glm::vec3(0.8f, 0.6f, 0.4f);
        polished.metallic = rough.metallic = 0.5f;
        polished.roughness = 0.f;
        rough.roughness = 1.f;
        const glm::vec3 E(3.f, 2.f, 1.f);
        const auto lit = [&](Entity e) {
            VertexIrradiance& vi = world.emplace<VertexIrradiance>(e);
            vi.irradiance.assign(world.get<Mesh>(e).positions.size(), E);
            vi.dirty.push_back({0, std::uint32_t(vi.irradiance.size())});
        };
        lit(addQuad(world, quadMesh({-1, 0, 1}, {1, 0, 0}, {0, 0, -2}), polished)); // x < 0
        lit(addQuad(world, quadMesh({0, 0, 1}, {1, 0, 0}, {0, 0, -2}), rough));     // x > 0
        addQuad(world, quadMesh({3, 1, -1}, {0, 0, 2}, {1, 0, 0}), emitter(1.f));
        const Entity cam = world.create();
        world.emplace<Camera>(cam, Camera{1.2f, 0.05f, 20.f, true});
        world.emplace<WorldTransform>(
            cam, WorldTransform{glm::inverse(glm::lookAt(glm::vec3(0.f, 1.5f, 0.f), glm::vec3(0.f),
                                                         glm::vec3(0, 0, -1)))}); // +x: right

        bakeField(world, 2, 16, 4, 1);
        ASSERT_EQ(world.ctx().get<VlfField>().vlf.specularFaceCount(), 1u); // the polished half

        const ImageF hdr = renderFrame(world, ShadingMode::Photon);
        // Pixels well inside either half (the floor spans about +-0.97 of the view).
        int checked = 0;
        for (int y = kSize / 8; y < kSize - kSize / 8; ++y)
            for (int x = kSize / 8; x < kSize - kSize / 8; ++x) {
                if (std::abs(x + 0.5 - kSize / 2.0) < kSize / 8.0) continue; // the seam
                const glm::vec3 albedo =
                    x < kSize / 2 ? polished.baseColor * 0.5f : rough.baseColor;
                const float* got = hdr.pixel(x, y);
                for (int c = 0; c < 3; ++c) {
                    const double want = double(albedo[c]) / glm::pi<double>() * E[c];
                    // Float rounding of albedo / pi * E and of the interpolated irradiance.
                    EXPECT_NEAR(got[c], want, 1e-5 * want) << "pixel " << x << "," << y;
                }
                ++checked;
            }
        EXPECT_GT(checked, kSize * kSize / 3);
    }
}

} // namespace
} // namespace qgi
