// The fragment shader's point-cache blend (shaders/common/pointcache.glsl) against the CPU
// query (PointCache::sample) it mirrors, pixel by pixel (runs under `xvfb-run -a`): each pixel
// within the range of values the blend takes over the points where the GPU's fragment may lie,
// with the float arithmetic of both sides counted.
#include "GlTestWindow.h"
#include "components/Camera.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/PointCacheShaded.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/render/GlWindow.h"
#include "systems/point_cache/PointCache.h"
#include "systems/render/RenderSystem.h"

#include <epoxy/gl.h>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace qgi {
namespace {

constexpr int kSize = 96;
constexpr float kAlbedo = 0.5f, kHeight = 3.f, kFov = 0.9f;
// float32's unit roundoff: one rounding moves a value by at most this fraction of it (an ulp
// of the GLSL precision rules is at most 2 kU of the value).
constexpr double kU = 0x1p-24;
// An allowance above this fraction of the value counts as wide (the median is below 1e-3).
constexpr double kWide = 1e-2;

/// A cache point's weight over the positions a pixel's fragment may take, and its irradiance.
struct WeightRange {
    double lo = 0, hi = 0;
    glm::dvec3 value{0.0};
};

/// The lowest (or highest) blend sum w_p v_p / sum w_p in channel c that weights within their
/// ranges can give; none when no weight can be positive. At the extreme each weight sits at an
/// end of its range: the upper end for the points darker (brighter) than the result, the lower
/// end for the others. So the extreme is one of the blends that raise the weights in order of
/// value, darkest (brightest) first.
std::optional<double> blendExtreme(std::vector<WeightRange>& points, int c, bool highest) {
    std::sort(points.begin(), points.end(), [&](const WeightRange& a, const WeightRange& b) {
        return highest ? a.value[c] > b.value[c] : a.value[c] < b.value[c];
    });
    double sum = 0, weight = 0;
    for (const WeightRange& p : points) {
        sum += p.lo * p.value[c];
        weight += p.lo;
    }
    std::optional<double> best;
    const auto consider = [&] {
        if (!(weight > 0)) return;
        const double v = sum / weight;
        if (!best || (highest ? v > *best : v < *best)) best = v;
    };
    consider();
    for (const WeightRange& p : points) {
        sum += (p.hi - p.lo) * p.value[c];
        weight += p.hi - p.lo;
        consider();
    }
    return best;
}

TEST(RenderPointCache, FragmentBlendMatchesTheCpuQuery) {
    QGI_SKIP_WITHOUT_GL();
    GlWindow context(test::testWindow(kSize, kSize, "qgi test_render_point_cache"));
    // Each falloff exponent the settings allow (the shader has a branch for each).
    for (const std::uint32_t falloff : {1u, 2u, 3u}) {
        SCOPED_TRACE(::testing::Message() << "falloff exponent " << falloff);
        Registry world;
        // A 4 x 4 m floor at y = 0 facing up, no lights: the cache lights it where its points
        // reach, its per-vertex irradiance elsewhere. Its mesh is given in an object space
        // turned about y and moved, so the shader must query with world positions.
        const glm::mat4 model = glm::rotate(glm::translate(glm::mat4(1.f), {0.3f, 0.f, -0.2f}),
                                            0.7f, glm::vec3(0.f, 1.f, 0.f));
        const Entity floor = world.create();
        Mesh& mesh = world.emplace<Mesh>(floor);
        for (const glm::vec3& corner : {glm::vec3(-2.f, 0.f, 2.f), glm::vec3(2.f, 0.f, 2.f),
                                        glm::vec3(2.f, 0.f, -2.f), glm::vec3(-2.f, 0.f, -2.f)})
            mesh.positions.push_back(glm::vec3(glm::inverse(model) * glm::vec4(corner, 1.f)));
        mesh.normals.assign(4, glm::vec3(0.f, 1.f, 0.f));
        mesh.indices = {0, 1, 2, 0, 2, 3};
        world.emplace<WorldTransform>(floor, WorldTransform{model});
        Material material;
        material.baseColor = glm::vec3(kAlbedo);
        world.emplace<Material>(floor, material);
        // Where no point reaches, the shader falls back to this per-vertex irradiance.
        const glm::vec3 vertexIrradiance(0.37f, 0.21f, 0.11f);
        VertexIrradiance& vi = world.emplace<VertexIrradiance>(floor);
        vi.irradiance.assign(4, vertexIrradiance);
        vi.dirty.push_back({0, 4});
        world.emplace<PointCacheShaded>(floor);

        // The camera kHeight above the origin looking straight down (local -Z to world -Y).
        const Entity camera = world.create();
        Camera& cam = world.emplace<Camera>(camera);
        cam.yfov = kFov;
        cam.active = true;
        const glm::mat4 pose = glm::rotate(glm::translate(glm::mat4(1.f), {0.f, kHeight, 0.f}),
                                           -glm::half_pi<float>(), glm::vec3(1.f, 0.f, 0.f));
        world.emplace<WorldTransform>(camera, WorldTransform{pose});

        // Random points on the floor (a gap on the left half-plane x < -1.2 shows the fallback).
        // A fifth of them turned off the floor's normal, and a fifth lifted off its plane, by
        // amounts on both sides of the rules that leave such points out of a query.
        PointCache& cache = world.ctx().emplace<PointCache>();
        cache.settings.falloffExponent = falloff;
        std::mt19937 rng(3);
        std::uniform_real_distribution<float> u(0.f, 1.f);
        for (int i = 0; i < 400; ++i) {
            glm::vec3 p(-1.0f + 3.f * u(rng), 0.f, -2.f + 4.f * u(rng));
            glm::vec3 n(0.f, 1.f, 0.f);
            if (i % 5 == 1) {
                const float tilt = 1.4f * u(rng); // up to 80 degrees: the rule's limit is 60
                n = glm::vec3(std::sin(tilt), std::cos(tilt), 0.f);
            } else if (i % 5 == 2) {
                p.y = 0.5f * (u(rng) - 0.5f); // up to 25 cm off: past half R for most
            }
            cache.position.push_back(p);
            cache.normal.push_back(n);
            cache.radius.push_back(0.08f + 0.12f * u(rng));
            cache.dart.push_back(std::uint32_t(i));
            cache.ao.push_back(u(rng));
            cache.direct.push_back({2.f * u(rng), 2.f * u(rng), 2.f * u(rng)});
            cache.indirect.push_back(glm::vec3(0.5f * u(rng)));
        }
        cache.buildGrid();

        RenderSettings settings;
        settings.width = kSize;
        settings.height = kSize;
        settings.mode = ShadingMode::Hybrid;
        RenderSystem renderer(settings);
        renderer.update(world, FrameContext{});
        const ImageF hdr = renderer.readHdr();

        // The CPU side of the comparison: the floor point of each pixel centre, in double from
        // the camera's float pose (its rounding is far below the GPU's), and the query there.
        const double tanHalf = std::tan(0.5 * double(cam.yfov));
        const glm::dmat3 orientation(pose);
        const glm::dvec3 eye(pose[3]);
        const auto floorAt = [&](double px, double py) {
            const glm::dvec3 dir =
                orientation * glm::dvec3((2.0 * px / kSize - 1.0) * tanHalf,
                                         (1.0 - 2.0 * py / kSize) * tanHalf, -1.0);
            return eye + (-eye.y / dir.y) * dir;
        };
        // Where the GPU's floor point for a pixel may lie. The rasterizer snaps the vertices to
        // its sub-pixel grid (2^-GL_SUBPIXEL_BITS of a pixel; rounding to the nearest step
        // moves them half that), so the position a fragment interpolates is that of a point up
        // to that far from the pixel centre in x and y; the camera's float matrices move the
        // vertices on screen by some 2^-24 of 96 pixels more, inside the factor 2. The camera
        // looks straight down, so that square of the image is a square on the floor,
        // pixelMetres per pixel. Then float arithmetic moves the point in all three axes: the
        // vertices are the model matrix times positions already rounded through its inverse
        // (their distance from the floor's corners is measured below in double, and the GPU's
        // product adds 7 roundings of terms below 4 m: 2e-6 m), and the interpolation (planes
        // of p/w and 1/w evaluated at the fragment, then divided) some 16 roundings of terms
        // below 4 m: 4e-6 m. kEpsilon covers the two with a factor above 2, and the rounding of
        // the rules' own tests (a few 2^-24 of R_p < 0.4 m) many times over.
        GLint subpixelBits = 0;
        glGetIntegerv(GL_SUBPIXEL_BITS, &subpixelBits);
        double vertexError = 0;
        for (std::size_t v = 0; v < 4; ++v) {
            const glm::dvec3 placed(glm::dmat4(model) *
                                    glm::dvec4(glm::dvec3(mesh.positions[v]), 1.0));
            const glm::dvec3 corner(v == 0 || v == 3 ? -2.0 : 2.0, 0.0, v < 2 ? 2.0 : -2.0);
            vertexError = std::max(vertexError, glm::length(placed - corner));
        }
        constexpr double kEpsilon = 0x1p-16; // metres, 1.5e-5
        const double pixelMetres = 2.0 * tanHalf * kHeight / kSize;
        const glm::dvec3 half(std::ldexp(pixelMetres, -subpixelBits) + kEpsilon + vertexError,
                              kEpsilon + vertexError,
                              std::ldexp(pixelMetres, -subpixelBits) + kEpsilon + vertexError);
        const double reach = glm::length(half); // the box lies in this ball about the centre

        // The normal rule is decided the same way on both sides only away from its threshold:
        // the GPU's normal (normal matrix, interpolation, normalize) lies some 40 roundings,
        // 2.4e-6, from straight up, where the CPU queries.
        const float minCos = cache.settings.minNormalCosine;
        for (std::size_t p = 0; p < cache.size(); ++p)
            ASSERT_GT(std::abs(cache.normal[p].y - minCos), 0x1p-16f) << "point " << p;

        int cached = 0, fallback = 0, failed = 0, wide = 0, outside = 0;
        double worst = 0, widest = 0;
        std::vector<WeightRange> ranges;
        for (int y = 0; y < kSize; ++y)
            for (int x = 0; x < kSize; ++x) {
                const glm::dvec3 at = floorAt(x + 0.5, y + 0.5);
                if (std::abs(at.x) > 1.98 || std::abs(at.z) > 1.98) continue;
                const PointCacheSample s = cache.sample(glm::vec3(at), {0.f, 1.f, 0.f});
                const glm::dvec3 nominal(s.count > 0 ? s.irradiance() : vertexIrradiance);
                (s.count > 0 ? cached : fallback) += 1;

                // Each point's weight over the box. Its distance lies within `reach` of the
                // centre's and n_p . (x - p) within the box's extent along n_p, so a point is
                // left out where a rule fails over the whole box, and may drop out (its weight's
                // lower end 0) where a rule's edge or its rim crosses the box. The weight falls
                // with the distance: its ends are at dLow and dHigh. Then float arithmetic, by
                // the GLSL 4.5 precision rules (which the CPU's IEEE arithmetic meets too): x - p
                // rounds each component (u), its dot product adds 3 products and 2 sums (d^2
                // within 5u), sqrt inherits 1 / inversesqrt's 4.5 ulp (d within 11.5u) and d / R
                // 2.5 ulp, so q = d / R lies within 17u q of itself, a = 1 - q within
                // 17u q + u a, and the k - 1 products of w = a^k add (k - 1) u a^k: w lies within
                // u (17 k a^(k-1) + (2k - 1) a^k), q <= 1. Twice that, for the GPU's weights
                // and the CPU's, at the box's largest a, widens both ends.
                ranges.clear();
                bool fallbackPossible = true; // no weight stays positive over the whole box
                for (std::size_t p = 0; p < cache.size(); ++p) {
                    const glm::dvec3 offset = at - glm::dvec3(cache.position[p]);
                    const glm::dvec3 n(cache.normal[p]);
                    const double R = cache.searchRadius(std::uint32_t(p));
                    const double d = glm::length(offset);
                    const double dLow = std::max(0.0, d - reach), dHigh = d + reach;
                    const double plane = std::abs(glm::dot(n, offset));
                    const double tilt = glm::dot(glm::abs(n), half);
                    const double tolerance = cache.settings.planeTolerance * R;
                    if (dLow >= R || n.y < minCos || plane - tilt > tolerance) continue;
                    const double aHigh = 1.0 - dLow / R, aLow = std::max(0.0, 1.0 - dHigh / R);
                    const auto k = int(falloff);
                    const double error =
                        2.0 * kU *
                        (17.0 * k * std::pow(aHigh, k - 1) + (2.0 * k - 1.0) * std::pow(aHigh, k));
                    WeightRange range;
                    range.hi = std::pow(aHigh, k) + error;
                    const bool edge = dHigh >= R || plane + tilt > tolerance;
                    range.lo = edge ? 0.0 : std::max(0.0, std::pow(aLow, k) - error);
                    range.value = glm::dvec3(cache.direct[p] + cache.indirect[p]);
                    fallbackPossible &= !(range.lo > 0.0);
                    ranges.push_back(range);
                }
                const auto points = double(ranges.size());

                const float* got = hdr.pixel(x, y);
                bool ok = true, isWide = false;
                for (int c = 0; c < 3; ++c) {
                    double low = std::numeric_limits<double>::infinity(), high = -low;
                    if (const std::optional<double> v = blendExtreme(ranges, c, false)) low = *v;
                    if (const std::optional<double> v = blendExtreme(ranges, c, true)) high = *v;
                    // Where every weight may vanish the fallback shows: the per-vertex irradiance
                    // interpolated through the same ~16 roundings as the position, taken twice.
                    if (fallbackPossible) {
                        const double e = vertexIrradiance[c];
                        low = std::min(low, e * (1.0 - 32.0 * kU));
                        high = std::max(high, e * (1.0 + 32.0 * kU));
                    }
                    // The CPU's own value lies in the range (its point is the box's centre, its
                    // weights within their ranges) but for its last few roundings.
                    outside +=
                        nominal[c] < low * (1.0 - 8.0 * kU) || nominal[c] > high * (1.0 + 8.0 * kU);
                    // The GPU's blend lies in the range too, so it differs from the CPU's by at
                    // most `spread`, plus the roundings after the weights: the GPU's sums of n
                    // products (n u for sum w v, (n - 1) u for sum w) and its division (2.5 ulp,
                    // 5u), each point's direct + indirect rounded once on upload (u), its output
                    // albedo * (1 / PI) * E (PI, the reciprocal's 2.5 ulp, two products: 8u); the
                    // CPU's casts of its two blends and their sum, and albedo / pi * E (5u).
                    const double spread = std::max(high - nominal[c], nominal[c] - low);
                    const double rounding = (2.0 * points + 18.0) * kU * std::max(high, nominal[c]);
                    const double allowed = kAlbedo / glm::pi<double>() * (spread + rounding);
                    const double expected = double(kAlbedo / glm::pi<float>() * float(nominal[c]));
                    const double error = std::abs(double(got[c]) - expected);
                    ok &= error <= allowed; // false for NaN
                    worst = std::max(worst, error / allowed);
                    widest = std::max(widest, allowed / expected);
                    isWide |= allowed > kWide * expected;
                }
                failed += !ok;
                wide += isWide;
            }
        const std::string tag = "k" + std::to_string(falloff) + "_";
        ::testing::Test::RecordProperty(tag + "failedPixels", failed);
        ::testing::Test::RecordProperty(tag + "widePixels", wide);
        ::testing::Test::RecordProperty(tag + "widestAllowance", std::to_string(widest));
        ::testing::Test::RecordProperty(tag + "worstErrorOverAllowance", std::to_string(worst));
        EXPECT_GT(cached, 3000);
        EXPECT_GT(fallback, 100);
        EXPECT_EQ(outside, 0) << "CPU values outside the range derived for them";
        // Within the box a weight changes by at most k reach / R_p < 0.4 % of its peak, so an
        // allowance passes 1 % of the value only where a point far brighter than the blend
        // enters at its rim, or where a step (a rule's edge, the cached region's rim) crosses
        // the box: curves, which the box, under 1 % of a pixel across, meets in few pixels. At
        // most 1 % of them (0.05 to 0.16 % today), so that a step or a wrong allowance cannot
        // widen the test unseen.
        EXPECT_LT(wide, (cached + fallback) / 100);
        EXPECT_EQ(failed, 0) << failed << " of " << cached + fallback
                             << " pixels outside their allowance; worst error " << worst
                             << " times its allowance";
    }
}

} // namespace
} // namespace qgi
