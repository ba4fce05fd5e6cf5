// GL image test of the built-in "cornell" scene (runs under `xvfb-run -a`; llvmpipe is fine):
// the renderer's hybrid-mode direct light at time 0 against the independent CPU ray caster in
// ReferenceTracer.cpp, both fed from the same registry.

#include "GlTestWindow.h"
#include "GoldenImage.h"
#include "ReferenceTracer.h"

#include "components/Camera.h"
#include "components/DirectionalLight.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/PointLight.h"
#include "components/ShLighting.h"
#include "components/SpotLight.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/io/Exr.h"
#include "runtime/render/GlWindow.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneQueries.h"
#include "systems/render/RenderSystem.h"

#include <epoxy/gl.h>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/matrix.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace qgi {
namespace {

namespace fs = std::filesystem;
using test::RefImage;
using test::RefTriangle;

// Wider than tall, so a wrong aspect ratio in either renderer shows up as a misplaced wall.
constexpr int kWidth = 128;
constexpr int kHeight = 96;
const fs::path kGolden = fs::path(QGI_TEST_DATA_DIR) / "gl" / "builtin_cornell_direct.exr";

// ---- the registry as the reference sees it --------------------------------------------------

/// Every mesh triangle in world space (one convex surface per entity: the walls, the light
/// quad, the two blocks and the capsule are each convex), the point lights and the active
/// camera, read from a registry built by buildBuiltinScene. Shading normals come from the
/// Mesh, so the avatar's smooth normals are interpolated as the renderer does.
struct ReferenceScene {
    std::vector<RefTriangle> triangles;
    std::vector<test::RefLight> lights;
    test::RefCamera camera;

    RefImage trace() const { return test::traceReference(triangles, lights, camera); }
};

ReferenceScene referenceScene(const Registry& registry) {
    ReferenceScene scene;
    int surface = 0;
    registry.view<const Mesh, const WorldTransform, const Material>().each(
        [&](const Mesh& mesh, const WorldTransform& world, const Material& material) {
            const glm::dmat4 model(world.matrix);
            const glm::dmat3 normalMatrix = glm::transpose(glm::inverse(glm::dmat3(model)));
            const auto position = [&](std::uint32_t i) {
                return glm::dvec3(model * glm::dvec4(glm::dvec3(mesh.positions[i]), 1.0));
            };
            const auto normal = [&](std::uint32_t i) {
                return glm::normalize(normalMatrix * glm::dvec3(mesh.normals[i]));
            };
            for (std::size_t t = 0; t < mesh.indices.size(); t += 3) {
                const std::uint32_t* i = &mesh.indices[t];
                RefTriangle& tri = scene.triangles.emplace_back();
                tri.p0 = position(i[0]);
                tri.p1 = position(i[1]);
                tri.p2 = position(i[2]);
                tri.normal = glm::normalize(glm::cross(tri.p1 - tri.p0, tri.p2 - tri.p0));
                tri.albedo = glm::dvec3(material.baseColor);
                tri.surface = surface;
                tri.emission = glm::dvec3(material.emission);
                tri.vertexNormals = {normal(i[0]), normal(i[1]), normal(i[2])};
            }
            ++surface;
        });
    registry.view<const PointLight, const WorldTransform>().each(
        [&](const PointLight& light, const WorldTransform& world) {
            scene.lights.push_back({test::RefLightType::Point,
                                    glm::dvec3(world.matrix[3]),
                                    {},
                                    glm::dvec3(light.color) * double(light.intensity)});
        });
    const Entity camera = findActiveCamera(registry);
    const Camera& lens = registry.get<Camera>(camera);
    const glm::dmat4 pose(registry.get<WorldTransform>(camera).matrix);
    scene.camera = {glm::dvec3(pose[3]), double(lens.yfov), kWidth, kHeight, glm::dmat3(pose)};
    return scene;
}

/// The built-in Cornell box as buildBuiltinScene makes it: every entity at its time-0 pose.
void buildCornell(Registry& registry) {
    buildBuiltinScene(registry, "cornell", {});
    // The reference knows point lights only, and the comparison is of direct light alone.
    ASSERT_EQ(registry.count<PointLight>(), 1u);
    ASSERT_EQ(registry.count<SpotLight>() + registry.count<DirectionalLight>(), 0u);
    ASSERT_EQ(registry.count<VertexIrradiance>() + registry.count<ShLighting>(), 0u);
    // One emitter, the luminaire: the test finds its pixels by their brightness.
    std::size_t emitters = 0;
    registry.view<const Material>().each(
        [&](const Material& material) { emitters += material.emission != glm::vec3(0.f); });
    ASSERT_EQ(emitters, 1u);
}

/// The renderer as the tests draw the box: kWidth x kHeight, hybrid mode, defaults otherwise.
RenderSettings hybridSettings() {
    RenderSettings settings;
    settings.width = kWidth;
    settings.height = kHeight;
    settings.mode = ShadingMode::Hybrid;
    return settings;
}

/// Emitted radiance of the luminaire, W/(m^2 sr).
glm::vec3 luminaireEmission(const Registry& registry) {
    glm::vec3 emission(0.f);
    registry.view<const Material>().each(
        [&](const Material& material) { emission = glm::max(emission, material.emission); });
    return emission;
}

// ---- comparison ------------------------------------------------------------------------------

/// Per pixel relative error where the renderer and the reference evaluate the same formula at
/// the same pixel centre: float32 interpolation of world positions (~1e-6 m at ~1 m) moves
/// 1/d^2 and cos by ~1e-5 relative, so 1e-3 leaves a factor 100 of headroom.
constexpr double kPixelTolerance = 1e-3;

/// Median over lit pixels of the mean channel radiance: the scale "dark" is measured against.
double medianLitRadiance(const ImageF& image) {
    std::vector<double> lit;
    for (std::size_t i = 0; i < image.rgba.size(); i += 4)
        if (const double mean = (image.rgba[i] + image.rgba[i + 1] + image.rgba[i + 2]) / 3.0;
            mean > 0.0)
            lit.push_back(mean);
    if (lit.empty()) return 0.0;
    const auto middle = lit.begin() + std::ptrdiff_t(lit.size() / 2);
    std::nth_element(lit.begin(), middle, lit.end());
    return *middle;
}

// ---- the test --------------------------------------------------------------------------------

class BuiltinCornellTest : public ::testing::Test {
protected:
    void SetUp() override {
        QGI_SKIP_WITHOUT_GL();
        mWindow = std::make_unique<GlWindow>(
            test::testWindow(kWidth, kHeight, "qgi test_render_cornell"));
    }

    std::unique_ptr<GlWindow> mWindow;
    Registry mWorld; // destroyed before the window, while its context is current
};

TEST_F(BuiltinCornellTest, DirectLightMatchesCpuReference) {
    ASSERT_NO_FATAL_FAILURE(buildCornell(mWorld));
    const RenderSettings settings = hybridSettings();
    RenderSystem renderer(settings);
    renderer.update(mWorld, FrameContext{}); // frame 0, time 0: the poses the scene was built in
    const ImageF actual = renderer.readHdr();
    const ReferenceScene scene = referenceScene(mWorld);
    const RefImage reference = scene.trace();

    // A pixel may differ from the reference only as far as the reference itself moves when its
    // inputs move by what rasterization and shadow mapping may legitimately change
    // (test::referenceRange): the camera ray by the rasterizer's vertex snapping (offsets of
    // 2^-GL_SUBPIXEL_BITS pixels; every offset ray is shaded, as the attributes interpolated at
    // the pixel centre are those of a point moved as far: on the ceiling beside the point
    // light, 2 cm below it, NVIDIA's snapping moves the shading by 0.1-0.2 %), the light's
    // visibility by the shadow lookup's reach (a cube
    // face of shadowMapSize texels spans 90 degrees: 2 / shadowMapSize metres per metre of
    // distance; the lookup sits 1.5 texels off the surface and PCF reads texels within
    // 1.5 sqrt(2) texels of it). Every pixel must lie within kPixelTolerance of that range,
    // relative to its ends, or to 1e-3 of the median lit radiance where they are darker (the
    // luminaire, hundreds of times brighter than the walls, would make a mean useless here),
    // so a shadowed pixel must stay dark. Where the range is no wider than the tolerance (all
    // but silhouettes between differently lit surfaces and the bands along shadow edges) this
    // is the plain comparison with the reference. The avatar's smooth normals are interpolated
    // by both; where its shading normal faces the light but its face does not, the reference
    // hides the light and the renderer leaves it to the shadow map, so the range holds both.
    GLint subpixelBits = 0;
    glGetIntegerv(GL_SUBPIXEL_BITS, &subpixelBits);
    test::RefPerturbation perturbation;
    perturbation.rayOffset = std::ldexp(1.0, -subpixelBits);
    perturbation.shadeEveryOffsetRay = true;
    perturbation.shadowTexel.assign(scene.lights.size(), 2.0 / double(settings.shadowMapSize));
    const test::RefRange range =
        test::referenceRange(scene.triangles, scene.lights, scene.camera, perturbation);
    const test::RangeComparison c =
        test::compareWithRange(actual, reference.radiance, range, kPixelTolerance,
                               1e-3 * medianLitRadiance(reference.radiance));
    RecordProperty("excusedPixels", int(c.excused));
    RecordProperty("worstNarrowError", std::to_string(c.worstNarrow));
    EXPECT_EQ(c.failed, 0u) << c.failed << " pixels outside their range (" << c.excused << " of "
                            << c.failures.size() << " have a range wider than the tolerance)";
    // Wide ranges are silhouettes and shadow bands (15 % of this image on llvmpipe; coarser
    // sub-pixel snapping elsewhere widens them a little): bounded, so that a change that
    // widens them much cannot pass unseen.
    EXPECT_LT(c.excused, c.failures.size() / 4);

    // The luminaire, a strip of about 16 x 3 pixels, must be in view; its pixels (those
    // brighter than half its emission: nothing else in view reflects a tenth of that) are
    // checked above like every other pixel.
    const glm::vec3 bright = 0.5f * luminaireEmission(mWorld);
    std::size_t luminaire = 0;
    for (std::size_t p = 0; p < c.failures.size(); ++p)
        if (const float* r = &reference.radiance.rgba[4 * p];
            r[0] > bright.x && r[1] > bright.y && r[2] > bright.z)
            ++luminaire;
    EXPECT_GE(luminaire, 32u) << "the luminaire should cover about 16 x 3 pixels";

    if (c.failed > 0)
        test::writeFailureImages(fs::path(QGI_TEST_OUTPUT_DIR), "builtin_cornell", actual,
                                 reference.radiance);
}

/// What a frame of the built-in Cornell box leaves in the renderer's HDR target and in the
/// context's default framebuffer (where the renderer presents it), drawn in a context of the
/// given platform.
struct PlatformFrame {
    std::string renderer; ///< GL_RENDERER
    ImageF hdr;
    Image8 ldr;
    std::vector<std::uint8_t> presented; ///< the default framebuffer, RGBA8, top row first
};

PlatformFrame drawCornell(GlPlatform platform) {
    WindowSettings windowSettings = test::testWindow(kWidth, kHeight, "qgi test_render_cornell");
    windowSettings.platform = platform;
    GlWindow window(windowSettings);
    PlatformFrame frame;
    frame.renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    Registry world; // its GPU resources go before the context does
    buildCornell(world);
    RenderSystem renderer(hybridSettings());
    renderer.update(world, FrameContext{});
    frame.hdr = renderer.readHdr();
    frame.ldr = renderer.readLdr();
    GLint drawBuffer = GL_BACK;
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glGetIntegerv(GL_DRAW_BUFFER, &drawBuffer);
    glReadBuffer(GLenum(drawBuffer));
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    const std::size_t row = std::size_t(kWidth) * 4;
    std::vector<std::uint8_t> bottomFirst(row * kHeight, 0);
    glReadPixels(0, 0, kWidth, kHeight, GL_RGBA, GL_UNSIGNED_BYTE, bottomFirst.data());
    for (int y = kHeight - 1; y >= 0; --y)
        frame.presented.insert(frame.presented.end(), bottomFirst.begin() + std::ptrdiff_t(row * y),
                               bottomFirst.begin() + std::ptrdiff_t(row * (y + 1)));
    return frame;
}

// An EGL pbuffer (GlPlatform::Egl, the demo's --context egl for GPU machines without X) is only
// another place for the context: the frame it draws is the window's, bit for bit, when both
// reach the same driver (here Mesa's llvmpipe through GLX and through EGL's device platform),
// and the renderer presents into the pbuffer as into the window.
TEST(GlPlatform, EglPbufferDrawsTheWindowsFrame) {
    if (!GlWindow::displayAvailable())
        GTEST_SKIP() << "no display for the window to compare with: run under 'xvfb-run -a'";
    const PlatformFrame window = drawCornell(GlPlatform::Window);
    const PlatformFrame egl = drawCornell(GlPlatform::Egl);
    if (egl.renderer != window.renderer)
        GTEST_SKIP() << "EGL reaches '" << egl.renderer << "', the window '" << window.renderer
                     << "': different drivers need not agree bit for bit";

    const auto brightest = *std::max_element(window.hdr.rgba.begin(), window.hdr.rgba.end());
    ASSERT_GT(brightest, 0.f) << "the window's frame is black: nothing to compare";
    ASSERT_EQ(egl.hdr.rgba.size(), window.hdr.rgba.size());
    EXPECT_TRUE(egl.hdr.rgba == window.hdr.rgba) << "the HDR frames differ";
    EXPECT_TRUE(egl.ldr.rgba == window.ldr.rgba) << "the tonemapped frames differ";
    EXPECT_TRUE(egl.presented == egl.ldr.rgba) << "the pbuffer did not receive the frame";
}

// Presenting is a same-size blit: the window's default framebuffer holds the tonemapped frame
// byte for byte (a second sRGB encoding on the way would show). Whatever driver EGL reaches.
TEST(GlPlatform, TheWindowReceivesTheTonemappedFrame) {
    if (!GlWindow::displayAvailable())
        GTEST_SKIP() << "no display for the window: run under 'xvfb-run -a'";
    const PlatformFrame window = drawCornell(GlPlatform::Window);
    ASSERT_GT(*std::max_element(window.ldr.rgba.begin(), window.ldr.rgba.end()), 0)
        << "the tonemapped frame is black";
    EXPECT_TRUE(window.presented == window.ldr.rgba) << "the window did not receive the frame";
}

// A regression tripwire for the CPU reference, not a test of the renderer (the test above
// compares with a fresh reference): the committed EXR holds what traceReference computed from
// the built-in scene when it was written, and a fresh trace must agree with it to within what
// float rounding of the scene's inputs on another platform can change (test::roundingRange);
// on the platform that wrote it, exactly. Regenerate with QGI_WRITE_REFERENCE=1 (and look at
// the image before committing it).
TEST(BuiltinCornellReference, GoldenExrEqualsCpuReference) {
    Registry world;
    ASSERT_NO_FATAL_FAILURE(buildCornell(world));
    const ReferenceScene scene = referenceScene(world);
    const ImageF fresh = scene.trace().radiance;
    if (test::checkGolden(kGolden, fresh,
                          test::roundingRange(scene.triangles, scene.lights, scene.camera)) ==
        test::GoldenCheck::Written)
        GTEST_SKIP() << "wrote " << kGolden;
}

} // namespace
} // namespace qgi
