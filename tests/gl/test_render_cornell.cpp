// GL image test of the built-in "cornell" scene (runs under `xvfb-run -a`; llvmpipe is fine):
// the renderer's hybrid-mode direct light at time 0 against the independent CPU ray caster in
// ReferenceTracer.cpp, both fed from the same registry.

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

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/matrix.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <limits>
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

struct Comparison {
    std::vector<double> error; ///< per pixel: largest channel error, relative (see compare)
    std::vector<bool> edges;   ///< per pixel: near a discontinuity of the reference
    double smoothWithin = 0;   ///< of the pixels away from discontinuities, fraction within
    double within = 0;         ///< of all pixels, fraction within tolerance
    double discontinuity = 0;  ///< fraction of pixels near a discontinuity
};

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

/// Each channel's error is relative to the reference value, or to 1e-3 of the median lit
/// radiance where the reference is darker than that, so a shadowed pixel must stay dark (the
/// luminaire, hundreds of times brighter than the walls, would make a mean useless here).
/// A value that is not finite is the largest error.
Comparison compare(const ImageF& actual, const RefImage& reference) {
    const ImageF& expected = reference.radiance;
    const double floor = 1e-3 * medianLitRadiance(expected);
    Comparison c;
    c.edges = test::discontinuities(reference);
    c.error.resize(c.edges.size());
    std::size_t smooth = 0, smoothWithin = 0, within = 0;
    for (std::size_t p = 0; p < c.edges.size(); ++p) {
        double& error = c.error[p];
        for (std::size_t ch = 0; ch < 3; ++ch) {
            const double r = expected.rgba[4 * p + ch], a = actual.rgba[4 * p + ch];
            error = std::max(error, std::isfinite(a) ? std::abs(a - r) / std::max(r, floor)
                                                     : std::numeric_limits<double>::infinity());
        }
        within += error <= kPixelTolerance;
        if (!c.edges[p]) {
            ++smooth;
            smoothWithin += error <= kPixelTolerance;
        }
    }
    const auto pixels = double(c.edges.size());
    c.smoothWithin = double(smoothWithin) / double(std::max<std::size_t>(smooth, 1));
    c.within = double(within) / pixels;
    c.discontinuity = (pixels - double(smooth)) / pixels;
    return c;
}

// ---- the test --------------------------------------------------------------------------------

class BuiltinCornellTest : public ::testing::Test {
protected:
    void SetUp() override {
        if (!std::getenv("DISPLAY") && !std::getenv("WAYLAND_DISPLAY"))
            GTEST_SKIP() << "no display: run the GL tests under 'xvfb-run -a'";
        WindowSettings settings;
        settings.width = kWidth;
        settings.height = kHeight;
        settings.headless = true;
        settings.title = "qgi test_render_cornell";
        mWindow = std::make_unique<GlWindow>(settings);
    }

    std::unique_ptr<GlWindow> mWindow;
    Registry mWorld; // destroyed before the window, while its context is current
};

TEST_F(BuiltinCornellTest, DirectLightMatchesCpuReference) {
    ASSERT_NO_FATAL_FAILURE(buildCornell(mWorld));
    RenderSettings settings;
    settings.width = kWidth;
    settings.height = kHeight;
    settings.mode = ShadingMode::Hybrid;
    RenderSystem renderer(settings);
    renderer.update(mWorld, FrameContext{}); // frame 0, time 0: the poses the scene was built in
    const ImageF actual = renderer.readHdr();
    const RefImage reference = referenceScene(mWorld).trace();
    const Comparison c = compare(actual, reference);
    bool ok = true;

    // Away from discontinuities (a 3x3 neighbourhood that sees one surface with one set of
    // unoccluded lights) nothing may differ. Shadow-map filtering (a 3x3-texel PCF tent, a
    // 1.5-texel normal offset) blurs shadow edges over ~3 texels of 2d / 1024, at most 3.9 mm
    // for the d <= 0.66 m between the light and any visible point; a pixel covers >= 6 mm of
    // the nearest visible surface (0.8 m away), so the blur cannot reach the centre of a pixel
    // whose neighbours all agree. The avatar's smooth normals are interpolated by both, so its
    // pixels count like the rest; where its shading normal faces the light but its face does
    // not, the reference counts the light as hidden (as the shadow map sees it), and the
    // terminator between is a discontinuity. 0.1% allows for numeric ties.
    ok &= c.smoothWithin >= 0.999;
    EXPECT_GE(c.smoothWithin, 0.999);

    // Discontinuities (18% of this image: the blocks cast long shadows from a light at the
    // ceiling) may differ only where a pixel centre falls into that <= 3.9 mm band along a
    // shadow edge or a contact line: silhouettes are sampled at the same pixel centres by
    // both. The reference has ~220 pixel lengths of shadow edge and < 70 of shadowed floor
    // against a block or the avatar; at most ~2/3 of a pixel wide, the band can flip at most
    // ~190 pixels (1.6%): 98% of all pixels must match.
    ok &= c.within >= 0.98;
    EXPECT_GE(c.within, 0.98) << "discontinuities: " << c.discontinuity;

    // The luminaire, a strip of about 16 x 3 pixels, lies mostly in the discontinuity set. Its
    // pixels are those brighter than half its emission: nothing else in view reflects a tenth
    // of that. Rasterization and ray casting agree on which pixel centres it covers, so all
    // but a rim pixel or so must match.
    const glm::vec3 bright = 0.5f * luminaireEmission(mWorld);
    std::size_t luminaire = 0, luminaireWithin = 0;
    for (std::size_t p = 0; p < c.error.size(); ++p)
        if (const float* r = &reference.radiance.rgba[4 * p];
            r[0] > bright.x && r[1] > bright.y && r[2] > bright.z) {
            ++luminaire;
            luminaireWithin += c.error[p] <= kPixelTolerance;
        }
    EXPECT_GE(luminaire, 32u) << "the luminaire should cover about 16 x 3 pixels";
    const double luminaireFraction =
        double(luminaireWithin) / double(std::max<std::size_t>(luminaire, 1));
    ok &= luminaireFraction >= 0.9;
    EXPECT_GE(luminaireFraction, 0.9) << "of " << luminaire << " luminaire pixels";

    if (!ok)
        test::writeFailureImages(fs::path(QGI_TEST_OUTPUT_DIR), "builtin_cornell", actual,
                                 reference.radiance);
}

// The committed reference EXR must be exactly what the CPU reference computes today from the
// built-in scene, so the golden file is backed by the independent math, not by the renderer.
// Regenerate with QGI_WRITE_REFERENCE=1 (and look at the image before committing it).
TEST(BuiltinCornellReference, GoldenExrEqualsCpuReference) {
    Registry world;
    ASSERT_NO_FATAL_FAILURE(buildCornell(world));
    const ImageF fresh = referenceScene(world).trace().radiance;
    if (test::checkGolden(kGolden, fresh) == test::GoldenCheck::Written)
        GTEST_SKIP() << "wrote " << kGolden;
}

} // namespace
} // namespace qgi
