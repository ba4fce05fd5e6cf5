// Point cache (seed 003): stored soft shadows against an independent reference, the cache
// file, the per-frame update.
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/Distance.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/raytrace/RayScene.h"
#include "systems/frame/FrameSchedule.h"
#include "systems/photon_update/PhotonSampling.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonUpdateSystem.h"
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointCacheFile.h"
#include "systems/point_cache/PointCacheSystem.h"
#include "systems/point_cache/PointShading.h"
#include "test_meshes.h"
#include "test_photon_scenes.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace qgi {
namespace {

using test::addMesh;
using test::grey;
using test::gridMesh;
using test::translation;

// Geometry of the soft-shadow scene, metres: a floor at y = 0, a square blocker at kBlockerY,
// a square light of radiance kRadiance facing down at kLightY.
constexpr float kLightHalf = 0.5f, kLightY = 1.5f;
constexpr float kBlockerHalf = 0.3f, kBlockerY = 0.75f;
constexpr float kRadiance = 10.f;
// Far enough that the blocker never stands between it and the floor points the tests check
// (|x| < 1.2: a ray to it passes the blocker's height past x = 1.15).
constexpr float kSecondLightX = 4.f;

struct ShadowScene {
    Registry registry;
    Entity blocker;
    /// `secondLight`: a second panel like the first, centred kSecondLightX along x.
    explicit ShadowScene(bool withBlocker = true, bool blockerMobile = false,
                         bool withCeiling = false, bool secondLight = false) {
        addMesh(registry, gridMesh({-6.f, 0.f, 6.f}, {12.f, 0.f, 0.f}, {0.f, 0.f, -12.f}, 1),
                glm::mat4(1.f), grey(0.5f), false, "floor");
        if (withCeiling) // darts from the floor land on it and back: points all over the floor
            addMesh(registry, gridMesh({-6.f, 3.f, -6.f}, {12.f, 0.f, 0.f}, {0.f, 0.f, 12.f}, 1),
                    glm::mat4(1.f), grey(0.5f), false, "ceiling");
        if (withBlocker)
            blocker =
                addMesh(registry,
                        gridMesh({-kBlockerHalf, 0.f, -kBlockerHalf},
                                 {2.f * kBlockerHalf, 0.f, 0.f}, {0.f, 0.f, 2.f * kBlockerHalf}, 1),
                        translation({0.f, kBlockerY, 0.f}), grey(0.5f), blockerMobile, "blocker");
        Material light = grey(0.5f);
        light.emission = glm::vec3(kRadiance);
        // cross(u, v) = -y: the light faces the floor.
        addMesh(registry,
                gridMesh({-kLightHalf, kLightY, -kLightHalf}, {2.f * kLightHalf, 0.f, 0.f},
                         {0.f, 0.f, 2.f * kLightHalf}, 1),
                glm::mat4(1.f), light, false, "light");
        if (secondLight)
            addMesh(registry,
                    gridMesh({kSecondLightX - kLightHalf, kLightY, -kLightHalf},
                             {2.f * kLightHalf, 0.f, 0.f}, {0.f, 0.f, 2.f * kLightHalf}, 1),
                    glm::mat4(1.f), light, false, "second light");
        test::buildRayScene(registry);
    }
};

/// Lambert's closed form for the unoccluded irradiance of a polygon of uniform radiance:
/// E = L/2 sum_i angle_i (n . unit(v_i x v_{i+1})), v_i = corner_i - x.
double lambertPolygon(const glm::dvec3& x, const glm::dvec3& n, const glm::dvec3 (&corners)[4]) {
    double sum = 0.0;
    for (int i = 0; i < 4; ++i) {
        const glm::dvec3 a = glm::normalize(corners[i] - x),
                         b = glm::normalize(corners[(i + 1) % 4] - x);
        const glm::dvec3 c = glm::cross(a, b);
        sum += std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0)) * glm::dot(n, glm::normalize(c));
    }
    return 0.5 * kRadiance * std::abs(sum);
}

/// An axis-aligned rectangle [x0, x1] x [z0, z1] of the light's plane.
struct Rect {
    double x0 = 0.0, x1 = 0.0, z0 = 0.0, z1 = 0.0;
    bool empty() const { return !(x0 < x1 && z0 < z1); }
};

constexpr Rect kLightRect{-kLightHalf, kLightHalf, -kLightHalf, kLightHalf};

/// Irradiance at floor point x (normal +y) from the part r of the light, by Lambert's form.
double lambertRect(const glm::vec3& x, const Rect& r) {
    const glm::dvec3 corners[4] = {
        {r.x0, kLightY, r.z0}, {r.x1, kLightY, r.z0}, {r.x1, kLightY, r.z1}, {r.x0, kLightY, r.z1}};
    return lambertPolygon(glm::dvec3(x), {0.0, 1.0, 0.0}, corners);
}

/// The part of the light the blocker hides from floor point x: the blocker's square projected
/// from x onto the light's plane, clipped to the light. Shadow rays run between points lifted
/// off their surfaces (photon::offsetFromSurface: x by 1e-4 max(1, |x|_inf) m, every point of
/// the light by 1e-4 kLightY m, its largest coordinate being its height), so the projection is
/// taken between those heights; the lift moves the shadow's edges on the light by about 1e-4 m.
Rect hiddenPart(const glm::vec3& x) {
    const double from = photon::offsetFromSurface(x, {0.f, 1.f, 0.f}).y;
    const double to = photon::offsetFromSurface({0.f, kLightY, 0.f}, {0.f, -1.f, 0.f}).y;
    const double scale = (to - from) / (kBlockerY - from); // blocker plane -> light plane
    const auto project = [&](double b, double at) { return at + (b - at) * scale; };
    Rect r;
    r.x0 = std::max(project(-kBlockerHalf, x.x), kLightRect.x0);
    r.x1 = std::min(project(kBlockerHalf, x.x), kLightRect.x1);
    r.z0 = std::max(project(-kBlockerHalf, x.z), kLightRect.z0);
    r.z1 = std::min(project(kBlockerHalf, x.z), kLightRect.z1);
    return r;
}

/// The exact irradiance at floor point x: the whole light's minus the hidden part's.
double exactIrradiance(const glm::vec3& x, bool withBlocker) {
    double e = lambertRect(x, kLightRect);
    if (withBlocker) {
        const Rect hidden = hiddenPart(x);
        if (!hidden.empty()) e -= lambertRect(x, hidden);
    }
    return e;
}

/// An independent check of the closed forms: the midpoint rule on n x n cells of each of the
/// (up to four) rectangles the visible part of the light splits into, so no cell straddles a
/// shadow edge, and a bound on its error. The integrand f = cos_x cos_y / d^2 = h^2 / q^2,
/// q = h^2 + X^2 + Z^2 (X, Z horizontal offsets from x, h the light's height above x), has
/// f_XX = 4 h^2 (6 X^2 - q) / q^4, so |f_XX|, |f_ZZ| <= 20 h^2 / q^3 <= 20 / h^4, and
/// |f_XZ| = 24 h^2 |XZ| / q^4 <= 12 / h^4. The linear Taylor term integrates to 0 over a cell;
/// the quadratic remainder over an a x b cell to at most
/// [5 (a^3 b + a b^3) / 6 + 3 a^2 b^2 / 4] / h^4.
struct Quadrature {
    double irradiance = 0.0, bound = 0.0;
};

Quadrature midpointRule(const glm::vec3& x, int n, bool withBlocker) {
    const double h = kLightY - x.y, h4 = h * h * h * h;
    const auto f = [&](double lx, double lz) {
        const glm::dvec3 w(lx - x.x, h, lz - x.z);
        const double d2 = glm::dot(w, w);
        return h * h / (d2 * d2);
    };
    std::vector<Rect> pieces;
    const Rect hidden = withBlocker ? hiddenPart(x) : Rect{};
    if (hidden.empty()) {
        pieces.push_back(kLightRect);
    } else {
        const Rect& l = kLightRect;
        pieces = {{l.x0, hidden.x0, l.z0, l.z1},
                  {hidden.x1, l.x1, l.z0, l.z1},
                  {hidden.x0, hidden.x1, l.z0, hidden.z0},
                  {hidden.x0, hidden.x1, hidden.z1, l.z1}};
    }
    Quadrature q;
    for (const Rect& r : pieces) {
        if (r.empty()) continue;
        const double a = (r.x1 - r.x0) / n, b = (r.z1 - r.z0) / n;
        double sum = 0.0;
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j)
                sum += f(r.x0 + (i + 0.5) * a, r.z0 + (j + 0.5) * b);
        q.irradiance += kRadiance * sum * a * b;
        q.bound += kRadiance * double(n) * n *
                   (5.0 * (a * a * a * b + a * b * b * b) / 6.0 + 0.75 * a * a * b * b) / h4;
    }
    return q;
}

// Each point is shaded with kKeys independent keys: 0x80000000 + k. shadeAreaLight draws from
// hashUniform(seed, key, light, dimension), a bijective hash of distinct inputs, and the cache
// itself uses the dart indices (< 2^31) as keys, so these streams are new.
constexpr int kKeys = 64;
constexpr std::uint32_t kFirstKey = 0x80000000u;
// Two-sided Student t quantiles with kKeys - 1 = 63 degrees of freedom, from the t density
// integrated numerically: P(|T_63| > 4.804) = 1.0e-5, P(|T_63| > 5.421) = 1.0e-6.
constexpr double kT63Of1e5 = 4.804, kT63Of1e6 = 5.421;
// Rounding of one 64-sample estimate, relative to the unoccluded irradiance: the float sample
// point (a few ulp of 1.5 m) and cos cos / d^2 (about ten float operations) perturb each f_i
// by at most about 2e-6 relative; allowed: 1e-5.
constexpr double kRounding = 1e-5;

/// kKeys shadings of floor point x: their mean and sample standard deviation, and the range
/// of the visible fraction.
struct Spread {
    double mean = 0.0, sd = 0.0;
    float minVisibility = 1.f, maxVisibility = 0.f;
    double visibilitySd = 0.0; ///< sample standard deviation of the visible fraction
};

Spread shadeWithKeys(const RayScene& rays, const AreaLight& light, const glm::vec3& x,
                     std::uint32_t samples, std::uint64_t seed,
                     const glm::vec3& normal = {0.f, 1.f, 0.f}) {
    double values[kKeys], visible[kKeys];
    Spread s;
    double visibleMean = 0.0;
    for (int k = 0; k < kKeys; ++k) {
        const LightSample ls =
            shadeAreaLight(rays, light, 0, x, normal, samples, seed, kFirstKey + k);
        values[k] = ls.irradiance.x;
        visible[k] = ls.visibility;
        s.mean += values[k] / kKeys;
        visibleMean += visible[k] / kKeys;
        s.minVisibility = std::min(s.minVisibility, ls.visibility);
        s.maxVisibility = std::max(s.maxVisibility, ls.visibility);
    }
    double ss = 0.0, vv = 0.0;
    for (int k = 0; k < kKeys; ++k) {
        ss += (values[k] - s.mean) * (values[k] - s.mean);
        vv += (visible[k] - visibleMean) * (visible[k] - visibleMean);
    }
    s.sd = std::sqrt(ss / (kKeys - 1));
    s.visibilitySd = std::sqrt(vv / (kKeys - 1));
    return s;
}

TEST(PointCacheShading, UnoccludedLightMatchesLambertsClosedForm) {
    ShadowScene scene(false);
    const std::vector<AreaLight> lights = findAreaLights(scene.registry, Aabb{});
    ASSERT_EQ(lights.size(), 1u);
    EXPECT_NEAR(lights[0].area, 1.f, 1e-6f);
    const RayScene& rays = scene.registry.ctx().get<RayScene>();
    for (const glm::vec3 x :
         {glm::vec3(0.f), glm::vec3(0.6f, 0.f, 0.2f), glm::vec3(2.f, 0.f, -1.f)}) {
        const double exact = exactIrradiance(x, false);
        const Quadrature q = midpointRule(x, 400, false);
        EXPECT_NEAR(q.irradiance, exact, q.bound) << x.x; // the closed form itself
        // The mean of kKeys estimates against the closed form: Student t with the estimates'
        // own spread, false alarm 1e-5 per point.
        const Spread s = shadeWithKeys(rays, lights[0], x, 64, 17);
        EXPECT_NEAR(s.mean, exact, kT63Of1e5 * s.sd / std::sqrt(double(kKeys)) + kRounding * exact)
            << x.x;
        EXPECT_FLOAT_EQ(s.minVisibility, 1.f);
        EXPECT_FLOAT_EQ(s.maxVisibility, 1.f);
    }
}

TEST(PointCacheShading, TiltedReceiversMatchLambertsClosedForm) {
    // Receivers turned 30 degrees about z and x, the whole light still above their horizon:
    // the receiver's cosine and the light's are now different (on the flat floor below a
    // level light they are equal, so swapping them would go unseen there).
    ShadowScene scene(false);
    const std::vector<AreaLight> lights = findAreaLights(scene.registry, Aabb{});
    ASSERT_EQ(lights.size(), 1u);
    const RayScene& rays = scene.registry.ctx().get<RayScene>();
    const glm::dvec3 corners[4] = {{-kLightHalf, kLightY, -kLightHalf},
                                   {kLightHalf, kLightY, -kLightHalf},
                                   {kLightHalf, kLightY, kLightHalf},
                                   {-kLightHalf, kLightY, kLightHalf}};
    const float s30 = 0.5f, c30 = std::sqrt(3.f) / 2.f;
    const glm::vec3 x(0.6f, 0.f, 0.2f);
    for (const glm::vec3 n :
         {glm::vec3(s30, c30, 0.f), glm::vec3(-s30, c30, 0.f), glm::vec3(0.f, c30, s30)}) {
        for (const glm::dvec3& corner : corners)
            ASSERT_GT(glm::dot(glm::dvec3(n), corner - glm::dvec3(x)), 0.0); // above the horizon
        const double exact = lambertPolygon(glm::dvec3(x), glm::dvec3(n), corners);
        const Spread s = shadeWithKeys(rays, lights[0], x, 64, 23, n);
        EXPECT_NEAR(s.mean, exact, kT63Of1e5 * s.sd / std::sqrt(double(kKeys)) + kRounding * exact)
            << n.x << "," << n.y << "," << n.z;
    }
}

TEST(PointCacheShading, ALampDrawnThroughItsStandInIsNoAreaLightOfTheCache) {
    // Hybrid mode's shader draws a stand-in's light on every surface, the cache's included:
    // were the panel an area light of the cache too, cached surfaces would get it twice.
    ShadowScene scene(false);
    ASSERT_EQ(findAreaLights(scene.registry, Aabb{}).size(), 1u);
    const Entity bulb = test::addPointLight(scene.registry, {0.f, kLightY - 0.05f, 0.f}, 5.f);
    EXPECT_EQ(findAreaLights(scene.registry, Aabb{}).size(), 1u) << "a bulb without the tag";
    const PointCacheSettings settings;
    const std::uint64_t untagged = pointCacheKey(scene.registry, settings);
    scene.registry.emplace<LightStandIn>(bulb);
    EXPECT_TRUE(findAreaLights(scene.registry, Aabb{}).empty());
    // A cache file made before the tag holds the panel's light: it is stale now.
    EXPECT_NE(pointCacheKey(scene.registry, settings), untagged);
}

TEST(PointCacheShading, SoftShadowBehindABlockerMatchesTheReference) {
    ShadowScene scene;
    const std::vector<AreaLight> lights = findAreaLights(scene.registry, Aabb{});
    ASSERT_EQ(lights.size(), 1u);
    const RayScene& rays = scene.registry.ctx().get<RayScene>();
    int umbra = 0, penumbra = 0;
    // Umbra, penumbra and lit points along a line and off it.
    for (const glm::vec3 x :
         {glm::vec3(0.f), glm::vec3(0.3f, 0.f, 0.f), glm::vec3(0.45f, 0.f, 0.1f),
          glm::vec3(0.6f, 0.f, 0.f), glm::vec3(0.5f, 0.f, 0.5f), glm::vec3(0.8f, 0.f, -0.3f),
          glm::vec3(2.f, 0.f, 0.f)}) {
        const double exact = exactIrradiance(x, true), open = exactIrradiance(x, false);
        const Quadrature q = midpointRule(x, 400, true);
        EXPECT_NEAR(q.irradiance, exact, q.bound) << "at " << x.x << ", " << x.z;
        // Student t on the mean of kKeys estimates, false alarm 1e-5 per point. In the umbra
        // every estimate is 0 (sd 0) and so is the closed form, up to rounding.
        const Spread s = shadeWithKeys(rays, lights[0], x, 64, 99);
        EXPECT_NEAR(s.mean, exact, kT63Of1e5 * s.sd / std::sqrt(double(kKeys)) + kRounding * open)
            << "at " << x.x << ", " << x.z;
        EXPECT_GE(s.minVisibility, 0.f);
        EXPECT_LE(s.maxVisibility, 1.f);
        umbra += exact == 0.0 ? 1 : 0;
        if (exact > 0.05 * open && exact < 0.95 * open) ++penumbra;
    }
    // The test does look at the soft edge: one point in the umbra, five between 5 and 95 % of
    // their unoccluded value.
    EXPECT_EQ(umbra, 1);
    EXPECT_EQ(penumbra, 5);
}

/// The point set the stored-shading tests build over the shadow scene: 64 shadow samples.
PointCacheSettings shadowPointSettings() {
    PointCacheSettings settings;
    settings.rMin = 0.06f;
    settings.rMax = 0.25f;
    settings.shadowSamples = 64;
    settings.particleCount = 512;
    settings.stopAfterRejections = 2000;
    return settings;
}

/// Whether point p lies on the floor facing up, within 1.2 m of the light's foot along x and
/// z: where the closed forms of the shadow scene are checked.
bool onCheckedFloor(const PointCache& cache, std::size_t p) {
    const glm::vec3 x = cache.position[p];
    return std::abs(x.y) < 1e-4f && cache.normal[p].y > 0.99f && std::abs(x.x) < 1.2f &&
           std::abs(x.z) < 1.2f;
}

TEST(PointCacheShading, StoredPointShadowsMatchTheReference) {
    ShadowScene scene;
    const PointCacheSettings settings = shadowPointSettings();
    PointCacheSystem system(settings);
    system.build(scene.registry);
    const PointCache& cache = scene.registry.ctx().get<PointCache>();
    const AreaLight& light = system.areaLights()[0];
    const RayScene& rays = scene.registry.ctx().get<RayScene>();
    std::size_t checked = 0, penumbra = 0, lit = 0, shadowed = 0;
    double difference = 0.0, variance = 0.0, rounding = 0.0, expected = 0.0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p];
        if (!onCheckedFloor(cache, p)) continue;
        ASSERT_LT(cache.dart[p], kFirstKey); // the stored estimate is independent of the spread
        const double exact = exactIrradiance(x, true), open = exactIrradiance(x, false);
        // The stored value is one estimate; kKeys more give its spread: (stored - exact) / sd
        // is Student t with 63 degrees of freedom, false alarm 1e-6 per point.
        const Spread s = shadeWithKeys(rays, light, x, settings.shadowSamples, settings.seed);
        const double stored = cache.direct[p].x;
        EXPECT_NEAR(stored, exact, kT63Of1e6 * s.sd + kRounding * open)
            << p << " at " << x.x << ", " << x.z;
        // The stored visible fraction (weighted by the unoccluded irradiance of each sample)
        // estimates exact / open the same way. As a ratio of two sums it carries a bias of
        // order 1 / shadowSamples of its spread, far inside the bound.
        // Rounding: a ratio of sums each within kRounding of their own scale, and a float.
        EXPECT_NEAR(cache.visibility[p], exact / open, kT63Of1e6 * s.visibilitySd + kRounding)
            << p << " at " << x.x << ", " << x.z;
        difference += stored - exact;
        variance += s.sd * s.sd;
        rounding += kRounding * open;
        expected += exact;
        ++checked;
        penumbra += exact > 0.05 * open && exact < 0.95 * open ? 1 : 0;
        lit += exact >= 0.95 * open ? 1 : 0;
        if (cache.visibility[p] < 0.5f) ++shadowed;
    }
    // Pooled over the points, which are shaded independently: the sum of the differences
    // against the root of the summed variances. Its variance estimate has at least 63 degrees
    // of freedom (Welch-Satterthwaite), so t_63 bounds it; false alarm 1e-5. The 59 points of
    // this build hold sum E = 99.7 W/m^2 and the bound is 2.0 W/m^2: a common scale error
    // moves the sum by 1 W/m^2 per per cent, so one of 3 % fails.
    EXPECT_NEAR(difference, 0.0, kT63Of1e5 * std::sqrt(variance) + rounding)
        << "sum of the exact values " << expected;
    // The compared set covers both kinds of point: this build has 20 lit (over 95 % of the
    // unoccluded value) and 39 in the penumbra (5 to 95 %).
    EXPECT_GE(checked, 50u);
    EXPECT_GE(lit, 10u);
    EXPECT_GE(penumbra, 25u);
    EXPECT_GT(shadowed, 5u);
}

TEST(PointCacheShading, TwoLightsAddUpAndKeepTheirOwnVisibility) {
    // The blocker's scene with a second panel 4 m along x that the blocker never hides from
    // the points checked: each point's stored light is the sum of the two closed forms, and
    // its visible fraction per light is the first light's exact share and exactly 1.
    ShadowScene scene(true, false, false, true);
    const PointCacheSettings settings = shadowPointSettings();
    PointCacheSystem system(settings);
    system.build(scene.registry);
    const PointCache& cache = scene.registry.ctx().get<PointCache>();
    ASSERT_EQ(cache.lightCount, 2u);
    ASSERT_EQ(system.areaLights().size(), 2u);
    // Which is which: the registry's order, told apart by their centres.
    const std::size_t near = system.areaLights()[0].centre.x < 1.f ? 0 : 1, far = 1 - near;
    const RayScene& rays = scene.registry.ctx().get<RayScene>();
    const glm::dvec3 farCorners[4] = {{kSecondLightX - kLightHalf, kLightY, -kLightHalf},
                                      {kSecondLightX + kLightHalf, kLightY, -kLightHalf},
                                      {kSecondLightX + kLightHalf, kLightY, kLightHalf},
                                      {kSecondLightX - kLightHalf, kLightY, kLightHalf}};
    std::size_t checked = 0, shaded = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p];
        if (!onCheckedFloor(cache, p)) continue;
        const double nearExact = exactIrradiance(x, true), nearOpen = exactIrradiance(x, false);
        const double farExact = lambertPolygon(glm::dvec3(x), {0.0, 1.0, 0.0}, farCorners);
        // Each light's stream is its own (keyed by the light's index): the spreads add.
        const Spread a = shadeWithKeys(rays, system.areaLights()[near], x, settings.shadowSamples,
                                       settings.seed);
        const Spread b =
            shadeWithKeys(rays, system.areaLights()[far], x, settings.shadowSamples, settings.seed);
        EXPECT_NEAR(cache.direct[p].x, nearExact + farExact,
                    kT63Of1e6 * std::sqrt(a.sd * a.sd + b.sd * b.sd) +
                        kRounding * (nearOpen + farExact))
            << p << " at " << x.x << ", " << x.z;
        EXPECT_NEAR(cache.visibility[p * 2 + near], nearExact / nearOpen,
                    kT63Of1e6 * a.visibilitySd + kRounding)
            << p;
        EXPECT_EQ(cache.visibility[p * 2 + far], 1.f) << p;
        ++checked;
        shaded += nearExact < 0.95 * nearOpen ? 1 : 0;
    }
    EXPECT_GE(checked, 50u);
    EXPECT_GE(shaded, 20u); // the near light's visibility is not 1 everywhere either
}

// ---- the cache file --------------------------------------------------------------------------

std::filesystem::path scratch(const char* name) {
    const auto dir =
        std::filesystem::temp_directory_path() / ("qgi_point_cache_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    return dir / name;
}

PointCacheSettings smallSettings(const std::string& file) {
    PointCacheSettings s;
    s.rMin = 0.1f;
    s.rMax = 0.3f;
    s.particleCount = 256;
    s.stopAfterRejections = 500;
    s.cacheFile = file;
    return s;
}

TEST(PointCacheFile, AnUnwritableFileStillGivesTheBuiltCache) {
    // The file's folder is a regular file: no one, root included, can write there.
    const std::filesystem::path blocker = scratch("not_a_folder");
    { std::ofstream(blocker) << 'x'; }
    ShadowScene scene;
    PointCacheSystem system(smallSettings((blocker / "cache.qpc").string()));
    EXPECT_NO_THROW(system.build(scene.registry));
    EXPECT_FALSE(system.loadedFromFile());
    EXPECT_GT(scene.registry.ctx().get<PointCache>().size(), 20u);
    std::filesystem::remove(blocker);
}

TEST(PointCacheFile, SomebodysFileAtThePathIsNeverOverwritten) {
    // Not a cache: the build works without a file and leaves it as it was.
    const std::filesystem::path notes = scratch("notes.txt");
    { std::ofstream(notes) << "my notes"; }
    ShadowScene scene;
    PointCacheSystem system(smallSettings(notes.string()));
    EXPECT_NO_THROW(system.build(scene.registry));
    EXPECT_FALSE(system.loadedFromFile());
    std::ifstream in(notes);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(text, "my notes");
    EXPECT_THROW(writePointCacheFile(notes.string(), 1, scene.registry.ctx().get<PointCache>()),
                 Error);
    std::filesystem::remove(notes);
}

TEST(PointCacheFile, RoundTripsAndIsLoadedOnTheNextStart) {
    const std::string file = scratch("roundtrip.qpc").string();
    std::filesystem::remove(file);
    ShadowScene scene;
    PointCacheSystem first(smallSettings(file));
    first.build(scene.registry);
    EXPECT_FALSE(first.loadedFromFile());
    ASSERT_TRUE(std::filesystem::exists(file));
    const PointCache built = scene.registry.ctx().get<PointCache>();
    ASSERT_GT(built.size(), 20u);

    PointCacheSystem second(smallSettings(file));
    second.build(scene.registry);
    EXPECT_TRUE(second.loadedFromFile());
    const PointCache& loaded = scene.registry.ctx().get<PointCache>();
    ASSERT_EQ(loaded.size(), built.size());
    const auto same = [](const auto& a, const auto& b) {
        return a.size() == b.size() &&
               std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0;
    };
    EXPECT_TRUE(same(loaded.position, built.position));
    EXPECT_TRUE(same(loaded.normal, built.normal));
    EXPECT_TRUE(same(loaded.radius, built.radius));
    EXPECT_TRUE(same(loaded.ao, built.ao));
    EXPECT_TRUE(same(loaded.direct, built.direct));
    EXPECT_TRUE(same(loaded.visibility, built.visibility));
    EXPECT_TRUE(same(loaded.dart, built.dart));
    // The recorded shadow samples too (one word per point and light at 16 samples), so a
    // loaded cache's refreshes replay the lights a move cannot shadow.
    EXPECT_EQ(loaded.sampleWords, 1u);
    EXPECT_EQ(loaded.reached.size(), built.size() * built.lightCount);
    EXPECT_TRUE(same(loaded.reached, built.reached));
    EXPECT_TRUE(std::any_of(loaded.reached.begin(), loaded.reached.end(),
                            [](std::uint32_t w) { return w != 0; }));
    std::filesystem::remove_all(std::filesystem::path(file).parent_path());
}

TEST(PointCacheFile, CorruptTruncatedAndStaleFilesAreRejectedAndRebuilt) {
    const std::string file = scratch("corrupt.qpc").string();
    std::filesystem::remove(file);
    ShadowScene scene;
    PointCacheSystem first(smallSettings(file));
    first.build(scene.registry);
    const PointCache built = scene.registry.ctx().get<PointCache>();
    const std::uint64_t key = pointCacheKey(scene.registry, built.settings);
    const auto size = std::filesystem::file_size(file);
    const auto expectError = [&](const char* phrase) {
        PointCache into;
        try {
            readPointCacheFile(file, key, into);
            ADD_FAILURE() << "no error; expected '" << phrase << "'";
        } catch (const Error& error) {
            EXPECT_NE(std::string(error.what()).find(phrase), std::string::npos) << error.what();
        }
        EXPECT_EQ(into.size(), 0u); // nothing half-read
    };
    // One flipped byte in the middle of the data.
    {
        std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
        f.seekg(std::streamoff(size / 2));
        char c = 0;
        f.read(&c, 1);
        c = char(c ^ 0x5a);
        f.seekp(std::streamoff(size / 2));
        f.write(&c, 1);
    }
    expectError("corrupt");
    PointCacheSystem again(smallSettings(file));
    again.build(scene.registry); // reports, rebuilds, rewrites
    EXPECT_FALSE(again.loadedFromFile());
    EXPECT_EQ(std::memcmp(scene.registry.ctx().get<PointCache>().direct.data(), built.direct.data(),
                          built.size() * sizeof(glm::vec3)),
              0);
    PointCache reread;
    EXPECT_NO_THROW(readPointCacheFile(file, key, reread));

    std::filesystem::resize_file(file, size - 7);
    expectError("truncated");
    std::filesystem::resize_file(file, 10);
    expectError("truncated");
    {
        std::ofstream f(file, std::ios::binary | std::ios::trunc);
        f << "not a cache file at all, just some text that is long enough";
    }
    expectError("bad magic");

    // Stale: the same file read with the key of other settings or another scene.
    again.build(scene.registry);
    PointCacheSettings other = built.settings;
    other.seed = 99;
    PointCache into;
    EXPECT_THROW(readPointCacheFile(file, pointCacheKey(scene.registry, other), into), Error);
    test::addPointLight(scene.registry, {1.f, 1.f, 1.f}, 1.f);
    EXPECT_NE(pointCacheKey(scene.registry, built.settings), key);
    PointCacheSystem stale(smallSettings(file));
    stale.build(scene.registry);
    EXPECT_FALSE(stale.loadedFromFile());
    EXPECT_THROW(readPointCacheFile("/nonexistent/dir/x.qpc", key, into), Error);
    std::filesystem::remove_all(std::filesystem::path(file).parent_path());
}

TEST(PointCacheFile, AMobileOutOfTheWorldChangesTheKey) {
    // A file baked with a pooled blocker in the world holds its shadow: it must not load for a
    // start with the blocker out.
    ShadowScene scene(true, /*blockerMobile=*/true);
    const PointCacheSettings settings;
    const std::uint64_t in = pointCacheKey(scene.registry, settings);
    scene.registry.get<MobileMesh>(scene.blocker).active = false;
    EXPECT_NE(pointCacheKey(scene.registry, settings), in);
    scene.registry.get<MobileMesh>(scene.blocker).active = true;
    EXPECT_EQ(pointCacheKey(scene.registry, settings), in);
}

// ---- per-frame update ---------------------------------------------------------------------------

/// A small point set over the shadow scene, re-shading 40 points a frame.
PointCacheSettings budgetedSettings() {
    PointCacheSettings settings;
    settings.rMin = 0.06f;
    settings.rMax = 0.25f;
    settings.particleCount = 512;
    settings.stopAfterRejections = 2000;
    settings.updateBudget = 40;
    return settings;
}

TEST(PointCacheUpdate, BudgetIsRespectedFarPointsStayAndTheQueueDrainsToFreshValues) {
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true);
    // The mobile blocker starts low and to the side: its shadow falls on part of the floor.
    const glm::vec3 blockerOld(2.f, 0.3f, 0.f);
    scene.registry.patch<WorldTransform>(scene.blocker).matrix = translation(blockerOld);
    RayScene& rays = scene.registry.ctx().get<RayScene>();
    rays.syncMoved(scene.registry);
    scene.registry.clearChanges();
    const PointCacheSettings settings = budgetedSettings();
    PointCacheSystem system(settings);
    system.build(scene.registry);
    PointCache& cache = scene.registry.ctx().get<PointCache>();
    system.update(scene.registry, FrameContext{});
    scene.registry.clearChanges();
    const PointCache before = cache;

    // Identical frames change nothing.
    system.update(scene.registry, FrameContext{1});
    EXPECT_EQ(system.lastFrame().refreshed, 0u);
    EXPECT_EQ(
        std::memcmp(cache.direct.data(), before.direct.data(), cache.size() * sizeof(glm::vec3)),
        0);

    // Move the blocker 0.4 m along x.
    const glm::vec3 offset(0.4f, 0.f, 0.f);
    std::vector<float> queueKey(cache.size()); // distance to the blocker's centre, old or new
    std::vector<std::uint32_t> queued;
    scene.registry.patch<WorldTransform>(scene.blocker).matrix = translation(blockerOld + offset);
    rays.syncMoved(scene.registry);
    system.update(scene.registry, FrameContext{2});
    scene.registry.clearChanges();
    const auto stats = system.lastFrame();
    // The queue is exactly what testing every point would give (the system culls by blocks and
    // cells of its grid first): the points with a light above their horizon whose cone of
    // rays to the light's bounding sphere (distanceBeyondCone) comes within the blocker's
    // bounding sphere, old or new pose.
    {
        Aabb box;
        for (const glm::vec3& v : scene.registry.get<Mesh>(scene.blocker).positions)
            box.extend(v);
        const float radius = 0.5f * glm::length(box.extent());
        std::size_t expected = 0;
        for (std::size_t p = 0; p < cache.size(); ++p) {
            const glm::vec3 x = cache.position[p];
            queueKey[p] = std::min(glm::length(blockerOld + box.center() - x),
                                   glm::length(blockerOld + offset + box.center() - x));
            bool hit = false;
            for (const AreaLight& l : system.areaLights()) {
                if (glm::dot(cache.normal[p], l.centre - x) < -l.boundRadius) continue;
                for (const glm::vec3 at : {blockerOld, blockerOld + offset})
                    hit = hit || distanceBeyondCone(at + box.center(), x, l.centre, l.boundRadius) <
                                     double(radius);
            }
            expected += hit ? 1 : 0;
            if (hit) queued.push_back(std::uint32_t(p));
        }
        EXPECT_EQ(stats.queued, expected);
        EXPECT_LT(stats.shadowCandidates, cache.size()); // the culling culled something
        EXPECT_GE(stats.shadowCandidates, stats.queued);
    }
    ASSERT_GT(stats.queued, settings.updateBudget);
    EXPECT_EQ(stats.refreshed, settings.updateBudget);
    EXPECT_EQ(stats.pending, stats.queued - settings.updateBudget);

    // Points whose segment to the light passes nowhere near the blocker (old or new) kept their
    // value bit for bit; the refreshed ones are the nearest to the blocker.
    const glm::vec3 blockerNew = blockerOld + offset;
    const float reach = std::sqrt(2.f) * kBlockerHalf + std::sqrt(2.f) * kLightHalf;
    std::size_t far = 0, changed = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const glm::vec3 x = cache.position[p];
        const glm::vec3 light(0.f, kLightY, 0.f);
        const auto dist = [&](const glm::vec3& c) {
            const glm::vec3 ab = light - x;
            const float t = std::clamp(glm::dot(c - x, ab) / glm::dot(ab, ab), 0.f, 1.f);
            return glm::length(x + t * ab - c);
        };
        const bool same = std::memcmp(&cache.direct[p], &before.direct[p], sizeof(glm::vec3)) == 0;
        if (dist(blockerOld) > 1.01f * reach && dist(blockerNew) > 1.01f * reach) {
            ++far;
            EXPECT_TRUE(same) << p;
        }
        changed += same ? 0 : 1;
    }
    EXPECT_GT(far, 50u);
    EXPECT_LE(changed, settings.updateBudget);
    // Nearest first: every point whose value changed is among the updateBudget queued points
    // nearest to the blocker (a refreshed point may keep its value, so the test cannot ask
    // for all of them). Keys within a float rounding of the cut count as tied.
    std::sort(queued.begin(), queued.end(),
              [&](std::uint32_t a, std::uint32_t b) { return queueKey[a] < queueKey[b]; });
    const float cut = queueKey[queued[settings.updateBudget - 1]];
    ASSERT_LT(cut, 0.9f * queueKey[queued.back()]); // the budget leaves far points waiting
    std::size_t changedBeyondTheCut = 0;
    for (std::size_t p = 0; p < cache.size(); ++p)
        if (std::memcmp(&cache.direct[p], &before.direct[p], sizeof(glm::vec3)) != 0)
            changedBeyondTheCut += queueKey[p] > cut * (1.f + 1e-5f);
    EXPECT_EQ(changedBeyondTheCut, 0u);
    EXPECT_GT(changed, 0u); // and some of them did change

    // Drain the queue: every point then holds exactly the value a fresh shading gives.
    for (std::uint64_t f = 3; f < 200 && system.lastFrame().pending > 0; ++f) {
        system.update(scene.registry, FrameContext{f});
        EXPECT_LE(system.lastFrame().refreshed, settings.updateBudget);
    }
    EXPECT_EQ(system.lastFrame().pending, 0u);
    const auto& light = system.areaLights()[0];
    std::size_t mismatches = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        const LightSample s =
            shadeAreaLight(rays, light, 0, cache.position[p], cache.normal[p],
                           cache.settings.shadowSamples, cache.settings.seed, cache.dart[p]);
        mismatches += std::memcmp(&s.irradiance, &cache.direct[p], sizeof(glm::vec3)) != 0;
    }
    EXPECT_EQ(mismatches, 0u);
    // Shading updates never touch the point set itself.
    ASSERT_EQ(cache.size(), before.size());
    EXPECT_EQ(std::memcmp(cache.position.data(), before.position.data(),
                          cache.size() * sizeof(glm::vec3)),
              0);
    EXPECT_EQ(cache.radius, before.radius);
    EXPECT_EQ(cache.ao, before.ao);
}

TEST(PointCacheShading, ReplayingTheRecordedSamplesGivesTheTracedValueBitForBit) {
    // Floor points in and around the blocker's shadow, 16 (stratified) and 5 (not) samples.
    ShadowScene scene;
    PointCacheSystem system(shadowPointSettings());
    system.build(scene.registry);
    const RayScene& rays = scene.registry.ctx().get<RayScene>();
    const AreaLight& light = system.areaLights()[0];
    std::size_t partial = 0;
    for (const std::uint32_t samples : {16u, 5u})
        for (int i = 0; i < 40; ++i) {
            const glm::vec3 x(-1.f + 0.05f * float(i), 0.f, 0.1f);
            const glm::vec3 n(0.f, 1.f, 0.f);
            std::uint32_t reached[1] = {0xdeadbeefu}; // cleared by the recording call
            const LightSample plain = shadeAreaLight(rays, light, 3, x, n, samples, 7, 11);
            const LightSample traced =
                shadeAreaLight(rays, light, 3, x, n, samples, 7, 11, reached);
            const LightSample replayed = replayAreaLight(light, 3, x, n, samples, 7, 11, reached);
            EXPECT_EQ(std::memcmp(&plain, &traced, sizeof plain), 0) << i;
            EXPECT_EQ(std::memcmp(&traced, &replayed, sizeof plain), 0) << i;
            EXPECT_EQ(reached[0] >> samples, 0u) << "bits past the samples";
            partial += reached[0] != 0 && reached[0] != (1u << samples) - 1u ? 1 : 0;
        }
    EXPECT_GT(partial, 10u); // penumbra points, where the bits matter one by one
}

TEST(PointCacheUpdate, ARefreshTracesOnlyTheLightsAMoveMayShadowAndEqualsAFullReshade) {
    // Two panels 4 m apart and a mobile blocker low between them, moved every frame for
    // 12 frames with a budget that leaves points waiting across moves, then drained. A
    // refreshed point casts rays only towards the lights a move came between; the others are
    // replayed from its recorded samples. Afterwards every point must hold, bit for bit, what
    // tracing both lights afresh gives: a light wrongly left unmarked keeps a stale shadow.
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true, /*secondLight=*/true);
    RayScene& rays = scene.registry.ctx().get<RayScene>();
    const PointCacheSettings settings = budgetedSettings();
    PointCacheSystem system(settings);
    system.build(scene.registry);
    const PointCache& cache = scene.registry.ctx().get<PointCache>();
    ASSERT_EQ(system.areaLights().size(), 2u);
    system.update(scene.registry, FrameContext{});
    scene.registry.clearChanges();

    std::size_t traced = 0, replayed = 0, waited = 0;
    std::uint64_t frame = 1;
    const auto step = [&] {
        system.update(scene.registry, FrameContext{frame++});
        scene.registry.clearChanges();
        const auto& stats = system.lastFrame();
        EXPECT_EQ(stats.lightsTraced + stats.lightsReplayed, 2 * stats.refreshed);
        traced += stats.lightsTraced;
        replayed += stats.lightsReplayed;
    };
    for (int move = 0; move < 12; ++move) {
        const glm::vec3 at(0.3f * float(move) - 0.5f, 0.3f, move % 2 == 0 ? 0.2f : -0.3f);
        scene.registry.patch<WorldTransform>(scene.blocker).matrix = translation(at);
        rays.syncMoved(scene.registry);
        step();
        waited += system.lastFrame().pending > 0 ? 1 : 0;
    }
    while (system.lastFrame().pending > 0 && frame < 400)
        step();
    ASSERT_EQ(system.lastFrame().pending, 0u);
    EXPECT_GT(waited, 6u); // points waited across moves: their marks had to add up
    EXPECT_GT(traced, 0u);
    EXPECT_GT(replayed, traced / 4) << "hardly a light was spared its rays";

    std::size_t mismatches = 0;
    for (std::size_t p = 0; p < cache.size(); ++p) {
        glm::vec3 sum(0.f);
        for (std::uint32_t l = 0; l < 2; ++l) {
            const LightSample s =
                shadeAreaLight(rays, system.areaLights()[l], l, cache.position[p], cache.normal[p],
                               cache.settings.shadowSamples, cache.settings.seed, cache.dart[p]);
            sum += s.irradiance;
            mismatches += s.visibility != cache.visibility[p * 2 + l] ? 1 : 0;
        }
        mismatches += std::memcmp(&sum, &cache.direct[p], sizeof sum) != 0 ? 1 : 0;
    }
    EXPECT_EQ(mismatches, 0u);
}

/// Every point's stored light against tracing every light afresh: the count that differ.
std::size_t pointsOffAFullReshade(const PointCacheSystem& system, const PointCache& cache,
                                  const RayScene& rays) {
    std::size_t mismatches = 0;
    const auto lights = std::uint32_t(system.areaLights().size());
    for (std::size_t p = 0; p < cache.size(); ++p) {
        glm::vec3 sum(0.f);
        bool visibilityOff = false;
        for (std::uint32_t l = 0; l < lights; ++l) {
            const LightSample s =
                shadeAreaLight(rays, system.areaLights()[l], l, cache.position[p], cache.normal[p],
                               cache.settings.shadowSamples, cache.settings.seed, cache.dart[p]);
            sum += s.irradiance;
            visibilityOff |= s.visibility != cache.visibility[p * lights + l];
        }
        mismatches += visibilityOff || std::memcmp(&sum, &cache.direct[p], sizeof sum) != 0;
    }
    return mismatches;
}

TEST(PointCacheUpdate, PosesTheRaySceneRefusesAndShearedPosesKeepRefreshesExact) {
    // The two-panel scene and its mobile blocker, moved through poses that test the bounds
    // the refresh relies on; after each, the queue is drained and every point must equal a
    // full re-shade bit for bit:
    //  - a pose the ray scene refuses (scaled to nothing, or parked past kMaxPoseReach): the
    //    blocker stays where it was for every ray, so the next move must be from there;
    //  - sheared poses (a turned child of a stretched parent): the blocker reaches farther
    //    from its centre than its longest axis's scale says.
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true, /*secondLight=*/true);
    RayScene& rays = scene.registry.ctx().get<RayScene>();
    PointCacheSettings settings = budgetedSettings();
    settings.updateBudget = 100000; // every queued point each frame
    PointCacheSystem system(settings);
    system.build(scene.registry);
    const PointCache& cache = scene.registry.ctx().get<PointCache>();
    system.update(scene.registry, FrameContext{});
    scene.registry.clearChanges();
    std::uint64_t frame = 1;
    const auto pose = [&](const glm::mat4& m, const char* what) {
        scene.registry.patch<WorldTransform>(scene.blocker).matrix = m;
        rays.syncMoved(scene.registry);
        system.update(scene.registry, FrameContext{frame++});
        scene.registry.clearChanges();
        ASSERT_EQ(system.lastFrame().pending, 0u) << what;
        EXPECT_EQ(pointsOffAFullReshade(system, cache, rays), 0u) << what;
    };
    pose(translation({0.f, kBlockerY, 0.f}), "under the first panel");
    pose(translation({0.f, -50.f, 0.f}) * glm::scale(glm::mat4(1.f), glm::vec3(0.f)),
         "scaled to nothing (refused)");
    pose(translation({2.f, kBlockerY, 0.f}), "between the panels");
    pose(translation({1e8f, 0.f, 0.f}), "parked past the reach (refused)");
    pose(translation({kSecondLightX, kBlockerY, 0.f}), "under the second panel");
    // Unit columns (so a longest-axis scale of 1), the box's corner 1.35 times as far out.
    glm::mat4 shear(1.f);
    shear[1] = glm::vec4(0.8f, 0.6f, 0.f, 0.f);
    shear[2] = glm::vec4(0.8f, 0.f, 0.6f, 0.f);
    for (int k = 0; k < 12; ++k)
        pose(translation({0.35f * float(k) - 0.2f, kBlockerY, 0.1f * float(k % 3)}) * shear,
             "sheared");
}

TEST(PointCacheUpdate, ABlockerTakenOutAndPutBackDrainsToFreshShadows) {
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true);
    const PointCacheSettings settings = budgetedSettings();
    PointCacheSystem system(settings);
    system.build(scene.registry);
    const PointCache& cache = scene.registry.ctx().get<PointCache>();
    system.update(scene.registry, FrameContext{});
    scene.registry.clearChanges();
    const PointCache before = cache;
    RayScene& rays = scene.registry.ctx().get<RayScene>();

    // Each switch queues the points it may shadow; once drained, every point holds what a
    // fresh shading of the scene as it is gives: the light unblocked, then the first values.
    std::uint64_t frame = 1;
    for (const bool active : {false, true}) {
        scene.registry.patch<MobileMesh>(scene.blocker).active = active;
        rays.syncMoved(scene.registry);
        system.update(scene.registry, FrameContext{frame++});
        scene.registry.clearChanges();
        EXPECT_GT(system.lastFrame().queued, settings.updateBudget);
        while (system.lastFrame().pending > 0 && frame < 400)
            system.update(scene.registry, FrameContext{frame++});
        ASSERT_EQ(system.lastFrame().pending, 0u);
        std::size_t mismatches = 0, unchanged = 0;
        for (std::size_t p = 0; p < cache.size(); ++p) {
            const LightSample s =
                shadeAreaLight(rays, system.areaLights()[0], 0, cache.position[p], cache.normal[p],
                               cache.settings.shadowSamples, cache.settings.seed, cache.dart[p]);
            mismatches += std::memcmp(&s.irradiance, &cache.direct[p], sizeof(glm::vec3)) != 0;
            unchanged += cache.direct[p] == before.direct[p] ? 1 : 0;
        }
        EXPECT_EQ(mismatches, 0u) << (active ? "put back" : "taken out");
        if (active)
            EXPECT_EQ(unchanged, cache.size());
        else
            EXPECT_GT(cache.size() - unchanged, 10u); // its shadow went
    }
}

TEST(PointCacheUpdate, IndirectFollowsThePhotonDeltaExactly) {
    Registry registry;
    const test::Room room = test::buildRoom(registry, {-1.f, -1.25f, 0.5f}, {0.5f, -1.3f, -1.f});
    test::buildRayScene(registry);
    PhotonSettings photons;
    photons.photonCount = 20'000;
    PhotonUpdateSystem photonSystem(photons);
    PointCacheSettings settings;
    settings.rMin = 0.08f;
    settings.rMax = 0.3f;
    settings.detpRadius = 0.3f; // discs small enough that some miss every delta segment
    settings.particleCount = 512;
    settings.stopAfterRejections = 1000;
    PointCacheSystem system(settings);
    system.build(registry);
    test::firstUpdate(registry, photonSystem);
    system.update(registry, FrameContext{});
    EXPECT_TRUE(system.lastFrame().fullIndirect);
    PointCache& cache = registry.ctx().get<PointCache>();
    double total = 0.0;
    for (const glm::vec3& e : cache.indirect)
        total += e.x;
    EXPECT_GT(total, 0.0);
    // DETP written out: every stored segment after a bounce that crosses a point's disc
    // (crossesDisc, the rule DiscIndex is checked against), over pi r^2.
    {
        const PhotonStore& store = registry.ctx().get<PhotonStore>();
        const float r = cache.settings.detpRadius;
        const auto& s = store.segments;
        for (std::size_t p = 0; p < cache.size(); p += 7) {
            glm::dvec3 sum(0.0);
            for (const PhotonPath& path : store.paths)
                for (std::uint32_t k = 0; k < path.count; ++k) {
                    const std::size_t i = path.first + k;
                    if (s.bounce[i] == 0) continue;
                    if (crossesDisc(s.origin[i], s.direction[i], s.length[i], cache.position[p],
                                    cache.normal[p], r))
                        sum += glm::dvec3(s.power[i]);
                }
            const glm::dvec3 expected = sum / (glm::pi<double>() * double(r) * double(r));
            // Both sum in double; the published float differs by its rounding (2^-24
            // relative), where one missed crossing would change it by a whole photon's power.
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(cache.indirect[p][c], expected[c], 1.2e-7 * expected[c] + 1e-9) << p;
        }
    }
    const std::vector<glm::vec3> before = cache.indirect;

    // Move the cube; the incremental value must equal a full re-estimate over the new set.
    test::moveAndUpdate(registry, photonSystem, room.cube, translation({-0.6f, -1.25f, 0.3f}), 1);
    system.update(registry, FrameContext{1});
    EXPECT_FALSE(system.lastFrame().fullIndirect);
    EXPECT_GT(system.lastFrame().deltaSegments, 0u);
    EXPECT_LT(system.lastFrame().indirectWritten, cache.size());
    const std::vector<glm::vec3> incremental = cache.indirect;
    std::size_t untouched = 0;
    for (std::size_t p = 0; p < cache.size(); ++p)
        untouched += std::memcmp(&incremental[p], &before[p], sizeof(glm::vec3)) == 0;
    EXPECT_GE(untouched, cache.size() - system.lastFrame().indirectWritten);

    // The photon update skipped a frame: the same delta again changes nothing.
    system.update(registry, FrameContext{2});
    EXPECT_FALSE(system.lastFrame().fullIndirect);
    EXPECT_EQ(system.lastFrame().deltaSegments, 0u);
    EXPECT_EQ(system.lastFrame().indirectWritten, 0u);
    EXPECT_EQ(0, std::memcmp(cache.indirect.data(), incremental.data(),
                             incremental.size() * sizeof(glm::vec3)));

    // A full delta (the photon set shot anew): re-estimated in full.
    PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
    delta.sequence += 1;
    delta.full = true;
    system.update(registry, FrameContext{3});
    EXPECT_TRUE(system.lastFrame().fullIndirect);
    delta.full = false;

    // A delta missed (the next one's sequence skips one): re-estimated in full too.
    delta.sequence += 2;
    system.update(registry, FrameContext{4});
    EXPECT_TRUE(system.lastFrame().fullIndirect);
    // Exactly up to the final rounding: the double sums differ by about 2^-53 of their largest
    // partial sum, far below the float's half ulp, so the floats agree to one ulp (2^-23).
    for (std::size_t p = 0; p < cache.size(); ++p)
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(incremental[p][c], cache.indirect[p][c],
                        1.2e-7f * cache.indirect[p][c] + 1e-9f)
                << p;
}

TEST(PointCacheSchedule, RunsAsTheTimedPointCachePhase) {
    ShadowScene scene(true, /*blockerMobile=*/true, /*withCeiling=*/true);
    FrameSettings settings;
    settings.photons->photonCount = 5000;
    settings.irradiance.discRadius = 0.2f;
    settings.render.reset();
    settings.pointCache = PointCacheSettings{};
    settings.pointCache->rMin = 0.1f;
    settings.pointCache->rMax = 0.3f;
    settings.pointCache->stopAfterRejections = 500;
    settings.pointCache->particleCount = 512;
    settings.pointCache->updateBudget = 7;
    FrameSchedule frame(scene.registry, settings);
    ASSERT_NE(frame.pointCache(), nullptr);
    bool listed = false;
    for (const Schedule::Entry* entry : frame.schedule().entries())
        listed |= entry->name == "point.cache";
    EXPECT_TRUE(listed);
    FrameProfiler& profiler = scene.registry.ctx().get<FrameProfiler>();
    for (std::uint64_t f = 0; f < 3; ++f) { // Schedule::run opens and closes the profiler frame
        if (f == 2)                         // the blocker moves: the budget bounds the refresh
            scene.registry.patch<WorldTransform>(scene.blocker).matrix =
                translation({0.3f, kBlockerY, 0.f});
        frame.run(scene.registry, FrameContext{f});
    }
    EXPECT_EQ(frame.pointCache()->lastFrame().refreshed, 7u);
    EXPECT_GT(frame.pointCache()->lastFrame().pending, 0u);
    bool timed = false;
    for (const ProfileStats& stats : profiler.statistics())
        timed |= stats.name == "point.cache" && stats.count == 3;
    EXPECT_TRUE(timed);
    EXPECT_GT(scene.registry.ctx().get<PointCache>().size(), 20u);
}

} // namespace
} // namespace qgi
