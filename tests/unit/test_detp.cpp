#include "systems/detp/DetpIrradianceSystem.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/detp/DiscCrossing.h"
#include "systems/photon_update/PhotonPathGrid.h"
#include "systems/photon_update/PhotonStore.h"

#include "systems/photon_update/PhotonUpdateSystem.h"
#include "test_detp_world.h"
#include "test_meshes.h"
#include "test_photon_scenes.h"
#include <gmock/gmock.h>

#include <gtest/gtest.h>

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include <oneapi/tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <span>
#include <vector>

namespace qgi {
namespace {

using ::testing::HasSubstr;

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr double kPi = glm::pi<double>();
const glm::mat4 kIdentity{1.f};

using test::addDetpResources;
using test::addReceiverMesh;
using test::gridMesh;

struct Segment {
    glm::vec3 origin{0.f};
    glm::vec3 direction{0.f, -1.f, 0.f};
    float length = kInf;
    glm::vec3 power{1.f};
    Entity hit;
    std::uint32_t primitive = 0;
    std::uint8_t bounce = 0;
};

void push(PhotonSegments& s, const Segment& seg) {
    s.origin.push_back(seg.origin);
    s.direction.push_back(seg.direction);
    s.length.push_back(seg.length);
    s.power.push_back(seg.power);
    s.hitEntity.push_back(seg.hit);
    s.hitPrimitive.push_back(seg.primitive);
    s.bounce.push_back(seg.bounce);
}

void appendPath(PhotonStore& store, std::span<const Segment> path, std::uint16_t light = 0) {
    store.paths.push_back(
        {std::uint32_t(store.segments.size()), std::uint16_t(path.size()), light});
    for (const Segment& seg : path)
        push(store.segments, seg);
}

/// The floor most tests light: [0, 1] x [0, 1] at y = 0, facing up, in `quads` x `quads` quads
/// (vertex (i, j) at z = i / quads, x = j / quads), static, named "floor".
Entity addUnitFloor(Registry& registry, int quads) {
    return addReceiverMesh(registry,
                           gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, quads),
                           kIdentity, false, "floor");
}

const VertexIrradiance& irradiance(const Registry& registry, Entity e) {
    return registry.get<VertexIrradiance>(e);
}

/// Expected DETP value at the foot of an isotropic point light of power P at height h over a
/// plane: the fraction of photons that cross the disc (its solid angle over 4 pi) times P,
/// over the disc's area. 1 - h / sqrt(h^2 + r^2) is computed without cancellation.
double footExpectation(double power, double h, double r) {
    const double x = (r * r) / (h * h);
    const double oneMinusCos = -std::expm1(-0.5 * std::log1p(x));
    return power * oneMinusCos / (2.0 * kPi * r * r);
}

/// The binomial standard error of the DETP estimate at the foot: the count of the N photons
/// that cross the disc is binomial(N, p), p = the disc's solid angle / 4 pi.
double footSigma(double power, double h, double r, double photons) {
    const double expected = footExpectation(power, h, r);
    const double p = expected * kPi * r * r / power;
    return expected * std::sqrt((1.0 - p) / (photons * p));
}

/// DETP's estimate (red channel) at vertex `vertex` (by default 4, the middle) of `floor`, with
/// discs of radius r, over the registry's photons.
double detpAtFoot(Registry& registry, Entity floor, double r, std::size_t vertex = 4) {
    DetpSettings settings;
    settings.discRadius = float(r);
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    return irradiance(registry, floor).irradiance[vertex].x;
}

// ---- analytic cases -----------------------------------------------------------------------

TEST(Detp, PointLightClosedFormTendsToTheInverseSquareLaw) {
    // E(r) / E0 = (2 / x) (1 - (1 + x)^-1/2) = 1 - 3x/4 + 5x^2/8 - ..., x = r^2 / h^2: an
    // alternating series, so the relative bias is -3x/4 within 5x^2/8 (plus a few ulps of the
    // ratio's rounding in double, 4 x 2^-52).
    const double power = 100.0, h = 2.0;
    const double e0 = power / (4.0 * kPi * h * h);
    for (const double r : {0.2, 0.02, 0.002}) {
        const double x = r * r / (h * h);
        const double relative = footExpectation(power, h, r) / e0 - 1.0;
        EXPECT_NEAR(relative, -0.75 * x, 0.625 * x * x + std::ldexp(4.0, -52)) << "r = " << r;
    }
}

TEST(Detp, PointLightOverABlackPlane) {
    constexpr double kPower = 100.0, kHeight = 1.0;
    constexpr std::size_t kPhotons = 2'000'000;
    Registry registry;
    addDetpResources(registry);
    // A 2 x 2 quad floor over [-1, 1]^2 at y = 0: vertex 4 is the foot of the light.
    const Entity floor =
        addReceiverMesh(registry, gridMesh({-1.f, 0.f, -1.f}, {0.f, 0.f, 2.f}, {2.f, 0.f, 0.f}, 2),
                        kIdentity, false, "floor");
    ASSERT_EQ(registry.get<Mesh>(floor).positions[4], glm::vec3(0.f));

    // Isotropic photons; those heading down end on the plane, the rest leave the scene.
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    std::mt19937_64 rng(2024);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const glm::vec3 light(0.f, float(kHeight), 0.f);
    const glm::vec3 photonPower(float(kPower / double(kPhotons)));
    for (std::size_t i = 0; i < kPhotons; ++i) {
        const double cosTheta = 1.0 - 2.0 * unit(rng), phi = 2.0 * kPi * unit(rng);
        const double sinTheta = std::sqrt(std::max(0.0, 1.0 - cosTheta * cosTheta));
        const glm::vec3 d(float(sinTheta * std::cos(phi)), float(cosTheta),
                          float(sinTheta * std::sin(phi)));
        const bool down = d.y < 0.f;
        const Segment seg{
            light, d, down ? float(kHeight) / -d.y : kInf, photonPower, down ? floor : Entity{},
            0,     0};
        appendPath(store, std::span(&seg, 1));
    }

    for (const double r : {0.1, 0.03}) {
        // (footExpectation's limit, I / h^2, is checked by
        // PointLightClosedFormTendsToTheInverseSquareLaw.)
        EXPECT_NEAR(detpAtFoot(registry, floor, r), footExpectation(kPower, kHeight, r),
                    4.0 * footSigma(kPower, kHeight, r, double(kPhotons)))
            << "r = " << r;
    }

    // The estimate itself tends to the inverse-square law P / (4 pi h^2) as r shrinks: its
    // relative gap is -3x/4 to within 5x^2/8 (x = r^2 / h^2) and four standard errors. At
    // r = 0.4 the gap is 10.6 % (sigma 0.37 %), at 0.2 2.9 % (0.71 %), at 0.1 0.75 % (1.4 %).
    const double e0 = kPower / (4.0 * kPi * kHeight * kHeight);
    double previousGap = 1.0;
    for (const double r : {0.4, 0.2, 0.1}) {
        const double x = r * r / (kHeight * kHeight);
        const double gap = detpAtFoot(registry, floor, r) / e0 - 1.0;
        const double sigma =
            footSigma(kPower, kHeight, r, double(kPhotons)) / footExpectation(kPower, kHeight, r);
        EXPECT_NEAR(gap, -0.75 * x, 0.625 * x * x + 4.0 * sigma) << "r = " << r;
        if (r >= 0.2) { // the gap shrinks where it stands out of the noise
            EXPECT_LT(std::abs(gap), previousGap) << "r = " << r;
        }
        previousGap = std::abs(gap) + 4.0 * sigma;
    }
}

// The same light through the real systems: the emitter's quasi-random photons, traced by the
// photon update onto a black floor (every photon that heads down ends there), then DETP at
// three radii, each within four binomial standard errors of the closed form. At r = 0.3 the
// closed form lies 6.28 % below the inverse-square law P / (4 pi h^2), more than four standard
// errors of 500k photons there (3.85 %), so the estimate must be told apart from the law: it
// follows the disc's closed form, whose limit as r shrinks is the law
// (PointLightClosedFormTendsToTheInverseSquareLaw). (Binomial errors are those of independent
// photons; quasi-random ones err less, so the bounds are conservative.)
TEST(Detp, PointLightOverABlackPlaneThroughTheRealEmitterAndTracerFollowsTheClosedForm) {
    constexpr float kIntensity = 10.f; // W/sr: power 4 pi I
    constexpr std::uint32_t kPhotons = 500'000;
    const double power = 4.0 * kPi * double(kIntensity), h = 1.0;
    Registry registry;
    // A 20 m square floor at y = 0 in 2 x 2 quads: vertex 4 is the foot of the light.
    const Entity floor = test::addMesh(
        registry, gridMesh({-10.f, 0.f, -10.f}, {0.f, 0.f, 20.f}, {20.f, 0.f, 0.f}, 2), kIdentity,
        test::grey(0.f), false, "floor");
    ASSERT_EQ(registry.get<Mesh>(floor).positions[4], glm::vec3(0.f));
    test::addPointLight(registry, {0.f, float(h), 0.f}, kIntensity);
    test::buildRayScene(registry);
    PhotonSettings photonSettings;
    photonSettings.photonCount = kPhotons;
    PhotonUpdateSystem photons(photonSettings);
    photons.update(registry, FrameContext{});
    ASSERT_EQ(registry.ctx().get<PhotonStore>().pathCount(), kPhotons);

    const double inverseSquare = power / (4.0 * kPi * h * h);
    for (const double r : {0.3, 0.1, 0.03}) {
        const double estimate = detpAtFoot(registry, floor, r);
        const double sigma = footSigma(power, h, r, double(kPhotons));
        EXPECT_NEAR(estimate, footExpectation(power, h, r), 4.0 * sigma) << "r = " << r;
        if (r == 0.3) {
            EXPECT_GT(std::abs(estimate - inverseSquare), 4.0 * sigma);
        }
    }
}

// A lamp added in play: its photons are appended at the power per photon of the light already
// shining and shot within the budget, so its irradiance fades in. A 10 W/sr light over the
// middle of a black floor, shot with 400k photons; then a 5 W/sr lamp 10 m to its side, its
// 200k photons shot 100k a frame. At each stage DETP at each light's foot follows the closed
// form for the power shot so far, plus the other light's far irradiance I cos / R^2, within
// four binomial standard errors of each light's photons. Then the lamp is dimmed far below
// its share and dealt new photons: the same at its foot once the sweeps end.
TEST(Detp, ALampAddedInPlayFadesInToTheClosedFormAndIsDealtNewPhotonsWhenDimmed) {
    constexpr float kIntensity = 10.f, kLampIntensity = 5.f; // W/sr
    constexpr std::uint32_t kPhotons = 400'000, kBudget = 100'000;
    const double h = 1.0, side = 10.0;
    const double perPhoton = 4.0 * kPi * double(kIntensity) / double(kPhotons);
    Registry registry;
    // 2 x 2 quads over 20 m: vertex 4 at the middle, vertex 5 at (10, 0, 0).
    const Entity floor = test::addMesh(
        registry, gridMesh({-10.f, 0.f, -10.f}, {0.f, 0.f, 20.f}, {20.f, 0.f, 0.f}, 2), kIdentity,
        test::grey(0.f), false, "floor");
    ASSERT_EQ(registry.get<Mesh>(floor).positions[5], glm::vec3(float(side), 0.f, 0.f));
    test::addPointLight(registry, {0.f, float(h), 0.f}, kIntensity);
    test::buildRayScene(registry);
    PhotonSettings photonSettings;
    photonSettings.photonCount = kPhotons;
    photonSettings.reshootBudget = kBudget;
    PhotonUpdateSystem photons(photonSettings);
    photons.update(registry, FrameContext{});
    registry.clearChanges();

    // Expected irradiance and standard error at the foot of one light (power, photons) with
    // the other's (power, photons) at distance `side`.
    const double farCos = h / std::hypot(h, side), farR2 = h * h + side * side;
    const auto expectAtFoot = [&](std::size_t vertex, double power, double photonsShot,
                                  double otherPower, double otherPhotons, const char* what) {
        for (const double r : {0.3, 0.1, 0.03}) {
            const double near = footExpectation(power, h, r);
            const double far = otherPower / (4.0 * kPi) * farCos / farR2;
            // Binomial: photons that cross the disc, each carrying power / photons.
            const auto sigma = [&](double e, double p, double n) {
                if (n == 0.0) return 0.0;
                const double q = e * kPi * r * r / p;
                return e * std::sqrt((1.0 - q) / (n * q));
            };
            const double error =
                std::hypot(sigma(near, power, photonsShot), sigma(far, otherPower, otherPhotons));
            EXPECT_NEAR(detpAtFoot(registry, floor, r, vertex), near + far, 4.0 * error)
                << what << ", r = " << r;
        }
    };

    const Entity lamp = test::addPointLight(registry, {float(side), float(h), 0.f}, kLampIntensity);
    const double light = perPhoton * kPhotons;
    for (std::uint64_t frame = 0; frame <= 2; ++frame) {
        if (frame > 0) {
            photons.update(registry, FrameContext{frame, 0.0, 0.f, 0});
            registry.clearChanges();
            ASSERT_FALSE(registry.ctx().get<PhotonDelta>().full);
            ASSERT_EQ(photons.lastFrame().reshotPaths, kBudget);
        }
        const double lampShot = double(frame * kBudget); // at the light's power per photon
        const std::string when = "frame " + std::to_string(frame);
        expectAtFoot(4, light, kPhotons, perPhoton * lampShot, lampShot, when.c_str());
        expectAtFoot(5, perPhoton * lampShot, lampShot, light, kPhotons, when.c_str());
    }
    EXPECT_EQ(registry.ctx().get<PhotonStore>().pathCount(), 600'000u);

    // Dimmed twentyfold (0.25 W/sr), the lamp holds 200k photons against a share of 14,634 of
    // the lit lights' 600k, more than 4x off: it is dealt 14,634 new ones while its old ones
    // go dark; the light keeps its 400k.
    registry.patch<PointLight>(lamp).intensity = kLampIntensity / 20.f;
    std::uint64_t frame = 2;
    do {
        photons.update(registry, FrameContext{++frame, 0.0, 0.f, 0});
        registry.clearChanges();
        ASSERT_FALSE(registry.ctx().get<PhotonDelta>().full);
    } while (photons.lastFrame().reshotPaths > 0 && frame < 100);
    ASSERT_EQ(registry.ctx().get<PhotonStore>().lights[1].photonCount, 14'634u);
    const double dimmed = 4.0 * kPi * double(kLampIntensity) / 20.0;
    expectAtFoot(5, dimmed, 14'634.0, light, kPhotons, "dimmed");
    expectAtFoot(4, light, kPhotons, dimmed, 14'634.0, "dimmed");
}

/// Parallel rays of total power 1 W over the unit square at y = 0, in a 10 x 10 quad floor; the
/// true irradiance is 1 W/m^2. Returns the relative errors at the 81 interior vertices, whose
/// discs (r = 0.04, spacing 0.1) are disjoint and inside the square.
std::vector<double> beamErrors(Registry& registry, DetpIrradianceSystem& system, Entity floor,
                               std::size_t photons, std::uint64_t seed) {
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    store = PhotonStore{};
    registry.ctx().get<PhotonDelta>().full = true;
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    const glm::vec3 power(1.f / float(photons));
    for (std::size_t i = 0; i < photons; ++i) {
        const float x = unit(rng), z = unit(rng);
        // The triangle it lands on (gridMesh: quad (i, j) spans z in [i, i + 1] / 10 and x in
        // [j, j + 1] / 10; its first triangle holds the part where the z fraction is larger).
        const int qi = std::min(int(z * 10.f), 9), qj = std::min(int(x * 10.f), 9);
        const bool second = x * 10.f - float(qj) > z * 10.f - float(qi);
        const std::uint32_t triangle = std::uint32_t(2 * (qi * 10 + qj) + (second ? 1 : 0));
        const Segment seg{{x, 1.f, z}, {0.f, -1.f, 0.f}, 1.f, power, floor, triangle, 0};
        appendPath(store, std::span(&seg, 1));
    }
    system.update(registry, {});
    std::vector<double> errors;
    const auto& values = irradiance(registry, floor).irradiance;
    for (int i = 1; i < 10; ++i)
        for (int j = 1; j < 10; ++j)
            errors.push_back(double(values[i * 11 + j].x) - 1.0);
    return errors;
}

TEST(Detp, UniformBeamErrorFallsAsOneOverSqrtN) {
    constexpr double kRadius = 0.04;
    Registry registry;
    addDetpResources(registry);
    const Entity floor = addUnitFloor(registry, 10);
    DetpSettings settings;
    settings.discRadius = float(kRadius);
    DetpIrradianceSystem system(settings);
    system.build(registry);

    // Each disc's count is binomial(N, p), p = pi r^2 / A: relative error sqrt((1 - p) / (N p)).
    // The RMS of M such errors has a relative standard deviation of about 1 / sqrt(2M); the
    // ratio of two independent RMS values about 1 / sqrt(M). Both are checked at 4 sigma. Every
    // photon count and seed draws its own stream, so the sets are independent (not prefixes of
    // one another).
    constexpr int kSeeds = 4;
    const double p = kPi * kRadius * kRadius;
    std::vector<double> rms;
    std::uint64_t stream = 100;
    for (const std::size_t photons : {20'000u, 80'000u, 320'000u}) {
        double sum2 = 0.0;
        std::size_t m = 0;
        for (int seed = 0; seed < kSeeds; ++seed)
            for (const double e : beamErrors(registry, system, floor, photons, stream++)) {
                sum2 += e * e;
                ++m;
            }
        rms.push_back(std::sqrt(sum2 / double(m)));
        const double theory = std::sqrt((1.0 - p) / (double(photons) * p));
        EXPECT_NEAR(rms.back(), theory, 4.0 * theory / std::sqrt(2.0 * double(m)))
            << photons << " photons";
    }
    const double samples = 81.0 * kSeeds;
    for (std::size_t i = 0; i + 1 < rms.size(); ++i)
        EXPECT_NEAR(rms[i] / rms[i + 1], 2.0, 2.0 * 4.0 / std::sqrt(samples)) << "step " << i;
}

TEST(Detp, ImpactCountUnderAUniformBeamHasItsBinomialError) {
    // Impact count at an interior vertex: the power landing on its six triangles (0.03 m^2 of
    // the 1 m^2 beam) over their area, so its count is binomial(N, 0.03) and its relative error
    // has standard deviation sigma = sqrt((1 - p) / (N p)): each vertex within 4 sigma. Their
    // mean: a vertex shares a third of its area with each of its 6 neighbours, so it covaries
    // with them by about sigma^2 / 3 and the mean of the 81 has variance about
    // 81 (1 + 6 / 3) sigma^2 / 81^2; within 4 of its standard deviations, which a 2 % scale
    // error exceeds.
    Registry registry;
    addDetpResources(registry);
    const Entity floor = addUnitFloor(registry, 10);
    DetpSettings settings;
    settings.estimator = IrradianceEstimator::ImpactCount;
    settings.discRadius = 0.04f; // unused by impact count; spares a SceneInfo
    DetpIrradianceSystem system(settings);
    system.build(registry);
    constexpr std::size_t kPhotons = 400'000;
    const double p = 0.03;
    const double sigma = std::sqrt((1.0 - p) / (double(kPhotons) * p));
    const std::vector<double> errors = beamErrors(registry, system, floor, kPhotons, 7);
    double mean = 0.0;
    for (std::size_t i = 0; i < errors.size(); ++i) {
        EXPECT_LT(std::abs(errors[i]), 4.0 * sigma) << "vertex " << i;
        mean += errors[i] / double(errors.size());
    }
    EXPECT_LT(std::abs(mean), 4.0 * sigma * std::sqrt(3.0 / 81.0));
}

// ---- counting rules -----------------------------------------------------------------------

TEST(Detp, SegmentsFromBehindDoNotCount) {
    Registry registry;
    addDetpResources(registry);
    const Entity floor =
        addReceiverMesh(registry, gridMesh({-1.f, 0.f, -1.f}, {0.f, 0.f, 2.f}, {2.f, 0.f, 0.f}, 2),
                        kIdentity, false, "floor");
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    const Segment fromBelow{{0.f, -1.f, 0.f}, {0.f, 1.f, 0.f}, kInf, glm::vec3(3.f), {}, 0, 1};
    appendPath(store, std::span(&fromBelow, 1));
    DetpSettings settings;
    settings.discRadius = 0.1f;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    EXPECT_EQ(irradiance(registry, floor).irradiance[4], glm::vec3(0.f));

    const Segment fromAbove{{0.f, 1.f, 0.f}, {0.f, -1.f, 0.f}, 1.f, glm::vec3(3.f), floor, 0, 1};
    appendPath(store, std::span(&fromAbove, 1));
    registry.ctx().get<PhotonDelta>().full = true;
    system.update(registry, {});
    EXPECT_FLOAT_EQ(irradiance(registry, floor).irradiance[4].x, float(3.0 / (kPi * 0.01)));
}

TEST(Detp, HybridModeSkipsOnlyTheSegmentsThatLeaveAPunctualLight) {
    Registry registry;
    addDetpResources(registry);
    const Entity floor =
        addReceiverMesh(registry, gridMesh({-1.f, 0.f, -1.f}, {0.f, 0.f, 2.f}, {2.f, 0.f, 0.f}, 2),
                        kIdentity, false, "floor");
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    store.lights = {PhotonLight{{}, glm::vec3(2.f), 2, true},   // a point light
                    PhotonLight{{}, glm::vec3(7.f), 1, false}}; // an emissive surface
    const Segment direct{{0.f, 1.f, 0.f}, {0.f, -1.f, 0.f}, 1.f, {2.f, 0.f, 0.f}, floor, 0, 0};
    const Segment bounced{{0.05f, 1.f, 0.f}, {0.f, -1.f, 0.f}, 1.f, {0.f, 5.f, 0.f}, floor, 0, 1};
    const Segment fromPanel{
        {-0.05f, 1.f, 0.f}, {0.f, -1.f, 0.f}, 1.f, {0.f, 0.f, 7.f}, floor, 1, 0};
    appendPath(store, std::span(&direct, 1), 0);
    appendPath(store, std::span(&bounced, 1), 0);
    appendPath(store, std::span(&fromPanel, 1), 1);
    const float area = float(kPi * 0.01);
    for (const bool hybrid : {false, true}) {
        DetpSettings settings;
        settings.discRadius = 0.1f;
        settings.hybrid = hybrid;
        DetpIrradianceSystem system(settings);
        system.build(registry);
        system.update(registry, {});
        const glm::vec3 e = irradiance(registry, floor).irradiance[4];
        EXPECT_FLOAT_EQ(e.x, hybrid ? 0.f : 2.f / area); // the renderer draws the point light
        EXPECT_FLOAT_EQ(e.y, 5.f / area);                // its indirect light always counts
        EXPECT_FLOAT_EQ(e.z, 7.f / area);                // and so does the area light
    }

    // The comparison estimators follow the same rule: in hybrid mode each gives what photon mode
    // gives on the store without the point light's direct segment.
    PhotonStore withoutDirect = store;
    withoutDirect.paths.erase(withoutDirect.paths.begin());
    for (const IrradianceEstimator estimator :
         {IrradianceEstimator::ImpactCount, IrradianceEstimator::PhotonMap}) {
        std::vector<glm::vec3> expected;
        for (const bool hybrid : {false, true}) {
            PhotonStore& current = registry.ctx().get<PhotonStore>();
            const PhotonStore full = current;
            if (!hybrid) current = withoutDirect;
            DetpSettings settings;
            settings.discRadius = 0.1f;
            settings.photonMapNeighbours = 2;
            settings.estimator = estimator;
            settings.hybrid = hybrid;
            DetpIrradianceSystem system(settings);
            system.build(registry);
            registry.ctx().get<PhotonDelta>().full = true;
            system.update(registry, {});
            const auto& e = irradiance(registry, floor).irradiance;
            if (!hybrid)
                expected.assign(e.begin(), e.end());
            else
                EXPECT_EQ(std::vector<glm::vec3>(e.begin(), e.end()), expected)
                    << irradianceEstimatorName(estimator);
            current = full;
        }
        EXPECT_GT(expected[4].z, 0.f) << irradianceEstimatorName(estimator);
    }
}

// ---- incremental update -------------------------------------------------------------------

/// The test world of the incremental tests: a floor (y = 0, facing up) and a wall (x = 0,
/// facing +x), both static and 20 x 20 quads over the unit square, and a small mobile plate
/// facing up that moves.
struct IncrementalWorld {
    Registry registry;
    Entity floor, wall, plate;
    /// What stops a re-traced head: by default a mobile that is not lit. Labelled as the
    /// plate's instead, the hits (which lie anywhere) tell DETP that the next segment starts on
    /// the plate, a convex mobile whose discs then skip it: the same in full estimates and
    /// deltas, which is what the incremental test checks then.
    Entity blocker, stopper;
    static constexpr float kRadius = 0.06f; // discs overlap: spacing 0.05

    IncrementalWorld() {
        addDetpResources(registry);
        floor = addUnitFloor(registry, 20);
        wall = addReceiverMesh(registry,
                               gridMesh({0.f, 0.f, 0.f}, {0.f, 1.f, 0.f}, {0.f, 0.f, 1.f}, 20),
                               kIdentity, false, "wall");
        plate = addReceiverMesh(
            registry, gridMesh({-0.25f, 0.f, -0.25f}, {0.f, 0.f, 0.5f}, {0.5f, 0.f, 0.f}, 8),
            glm::translate(kIdentity, {0.5f, 0.3f, 0.5f}), true, "plate");
        blocker = stopper = registry.create();
    }
};

glm::vec3 randomUnit(std::mt19937& rng) {
    std::normal_distribution<float> normal;
    glm::vec3 v;
    do {
        v = {normal(rng), normal(rng), normal(rng)};
    } while (glm::dot(v, v) < 1e-6f);
    return glm::normalize(v);
}

/// A random path in the unit box: segments heading down end on the floor plane (where the
/// next one starts, heading up), segments heading up leave the scene. Powers in [0.5, 1.5] W.
std::vector<Segment> randomPath(std::mt19937& rng, const IncrementalWorld& world, glm::vec3 origin,
                                std::uint8_t bounce) {
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::uniform_int_distribution<std::uint32_t> triangle(0, 799);
    std::vector<Segment> path;
    for (;;) {
        Segment seg;
        seg.origin = origin;
        seg.direction = randomUnit(rng);
        if (bounce > 0 && origin.y == 0.f) seg.direction.y = std::abs(seg.direction.y);
        seg.power = glm::vec3(0.5f + unit(rng), 0.5f + unit(rng), 0.5f + unit(rng));
        seg.bounce = bounce++;
        if (seg.direction.y < 0.f) {
            seg.length = origin.y / -seg.direction.y;
            seg.hit = world.floor;
            seg.primitive = triangle(rng);
            path.push_back(seg);
            origin = seg.origin + seg.length * seg.direction;
            origin.y = 0.f;
            if (path.size() < 4) continue;
        } else {
            path.push_back(seg);
        }
        return path;
    }
}

/// `count` random paths from random points in the upper part of the unit box.
void appendRandomPaths(std::mt19937& rng, IncrementalWorld& world, int count) {
    PhotonStore& store = world.registry.ctx().get<PhotonStore>();
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    for (int i = 0; i < count; ++i)
        appendPath(store,
                   randomPath(rng, world, {unit(rng), 0.2f + 0.8f * unit(rng), unit(rng)}, 0));
}

/// A frame of the quasi-static update done by hand: some paths get a new suffix from a random
/// segment on; the delta holds the old and new suffixes; the store gets the re-traced paths at
/// its end (their old ranges become garbage, as in the photon store).
void randomDelta(std::mt19937& rng, IncrementalWorld& world, std::size_t paths) {
    PhotonStore& store = world.registry.ctx().get<PhotonStore>();
    PhotonDelta& delta = world.registry.ctx().get<PhotonDelta>();
    delta = PhotonDelta{};
    delta.oldFirst = {0};
    delta.newFirst = {0};
    std::uniform_int_distribution<std::uint32_t> pickPath(0, std::uint32_t(store.paths.size() - 1));
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    for (std::size_t i = 0; i < paths; ++i) {
        const std::uint32_t p = pickPath(rng);
        if (std::find(delta.paths.begin(), delta.paths.end(), p) != delta.paths.end()) continue;
        const PhotonPath path = store.paths[p];
        const std::uint32_t from =
            std::uniform_int_distribution<std::uint32_t>(0, path.count - 1u)(rng);
        std::vector<Segment> segments;
        for (std::uint32_t k = 0; k < path.count; ++k) {
            const std::size_t s = path.first + k;
            const Segment seg{store.segments.origin[s],    store.segments.direction[s],
                              store.segments.length[s],    store.segments.power[s],
                              store.segments.hitEntity[s], store.segments.hitPrimitive[s],
                              store.segments.bounce[s]};
            if (k >= from) push(delta.oldSegments, seg);
            if (k < from) segments.push_back(seg);
        }
        // The new suffix: the same head ray, now stopped early (by the mobile), then a new
        // random continuation from there.
        Segment head{store.segments.origin[path.first + from],
                     store.segments.direction[path.first + from],
                     0.f,
                     store.segments.power[path.first + from],
                     world.stopper,
                     0,
                     store.segments.bounce[path.first + from]};
        const float oldLength = store.segments.length[path.first + from];
        // Mostly shorter (the mobile moved into its way), sometimes longer (out of its way).
        head.length = (std::isinf(oldLength) ? 2.f : oldLength) * (0.2f + 1.1f * unit(rng));
        segments.push_back(head);
        for (const Segment& seg : randomPath(rng, world, head.origin + head.length * head.direction,
                                             std::uint8_t(head.bounce + 1)))
            segments.push_back(seg);
        if (segments.size() > 6) segments.resize(6);
        for (std::size_t k = from; k < segments.size(); ++k)
            push(delta.newSegments, segments[k]);
        delta.paths.push_back(p);
        delta.oldFirst.push_back(std::uint32_t(delta.oldSegments.size()));
        delta.newFirst.push_back(std::uint32_t(delta.newSegments.size()));
        store.paths[p] = {std::uint32_t(store.segments.size()), std::uint16_t(segments.size()), 0};
        for (const Segment& seg : segments)
            push(store.segments, seg);
    }
}

/// The static vertices whose disc some delta segment crosses (brute force).
std::vector<bool> crossedByDelta(const IncrementalWorld& world, Entity e, float radius) {
    const Mesh& mesh = world.registry.get<Mesh>(e);
    const PhotonDelta& delta = world.registry.ctx().get<PhotonDelta>();
    std::vector<bool> crossed(mesh.positions.size(), false);
    for (const PhotonSegments* s : {&delta.oldSegments, &delta.newSegments})
        for (std::size_t i = 0; i < s->size(); ++i)
            for (std::size_t v = 0; v < crossed.size(); ++v)
                if (crossesDisc(s->origin[i], s->direction[i], s->length[i], mesh.positions[v],
                                mesh.normals[v], radius))
                    crossed[v] = true;
    return crossed;
}

bool bitEqual(const glm::vec3& a, const glm::vec3& b) {
    return std::memcmp(&a, &b, sizeof(glm::vec3)) == 0;
}

bool inDirtyRange(const VertexIrradiance& vi, std::uint32_t v) {
    return std::any_of(vi.dirty.begin(), vi.dirty.end(),
                       [v](const DirtyRange& r) { return r.begin <= v && v < r.end; });
}

/// 100 random deltas, the plate moving now and then, against a full estimate at the end.
void expectIncrementalEqualsFull(bool headsStopOnPlate) {
    IncrementalWorld world;
    if (headsStopOnPlate) world.stopper = world.plate;
    Registry& registry = world.registry;
    std::mt19937 rng(99);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    appendRandomPaths(rng, world, 3000);
    DetpSettings settings;
    settings.discRadius = IncrementalWorld::kRadius;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    registry.clearChanges();
    ASSERT_TRUE(system.lastFrame().full);

    std::size_t segmentsSeen = store.segments.size();
    std::size_t untouchedChecked = 0, touchedChanged = 0, plateIncremental = 0, fromPlate = 0;
    for (int frame = 1; frame <= 100; ++frame) {
        randomDelta(rng, world, 1 + std::size_t(unit(rng) * 40.f));
        const PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
        segmentsSeen += delta.oldSegments.size() + delta.newSegments.size();
        for (std::size_t i = 0; i + 1 < delta.newFirst.size(); ++i)
            for (std::uint32_t k = delta.newFirst[i] + 1; k < delta.newFirst[i + 1]; ++k)
                fromPlate += delta.newSegments.hitEntity[k - 1] == world.plate ? 1 : 0;
        // The plate moves now and then, as the transform system would report it; it stays
        // put over the last frames, where its vertices are updated incrementally.
        const bool moves = frame % 10 == 5;
        if (moves) {
            registry.patch<WorldTransform>(world.plate).matrix =
                glm::translate(kIdentity, {0.25f + 0.5f * unit(rng), 0.1f + 0.4f * unit(rng),
                                           0.25f + 0.5f * unit(rng)});
            registry.ctx().get<PhotonDelta>().movedMobiles = {world.plate};
        }
        const std::vector<glm::vec3> plateBefore =
            registry.get<VertexIrradiance>(world.plate).irradiance;
        std::vector<std::vector<glm::vec3>> before;
        std::vector<std::vector<bool>> crossed;
        for (const Entity e : {world.floor, world.wall}) {
            auto& vi = registry.get<VertexIrradiance>(e);
            vi.dirty.clear(); // as the renderer does after uploading
            before.push_back(vi.irradiance);
            crossed.push_back(crossedByDelta(world, e, IncrementalWorld::kRadius));
        }
        system.update(registry, {});
        registry.clearChanges();
        ASSERT_FALSE(system.lastFrame().full) << "frame " << frame;
        EXPECT_EQ(system.lastFrame().movedMobiles, moves ? 1u : 0u);
        if (!moves) {
            const auto& plate = registry.get<VertexIrradiance>(world.plate).irradiance;
            for (std::size_t v = 0; v < plate.size(); ++v)
                plateIncremental += bitEqual(plate[v], plateBefore[v]) ? 0 : 1;
        }

        for (std::size_t m = 0; m < 2; ++m) {
            const auto& vi = registry.get<VertexIrradiance>(m == 0 ? world.floor : world.wall);
            for (std::uint32_t v = 0; v < vi.irradiance.size(); ++v) {
                if (!crossed[m][v]) {
                    ASSERT_TRUE(bitEqual(vi.irradiance[v], before[m][v]))
                        << "untouched vertex " << v << " changed in frame " << frame;
                    ++untouchedChecked;
                } else if (!bitEqual(vi.irradiance[v], before[m][v])) {
                    ASSERT_TRUE(inDirtyRange(vi, v)) << "vertex " << v << " changed, not dirty";
                    ++touchedChanged;
                }
            }
        }
    }
    EXPECT_GT(untouchedChecked, 10'000u);
    EXPECT_GT(touchedChanged, 1'000u);
    // The still plate took incremental updates too; with heads stopped on it, fewer (the
    // segments that leave it are skipped), but many deltas then start on it.
    if (headsStopOnPlate) {
        EXPECT_GT(fromPlate, 1'000u);
        EXPECT_GT(plateIncremental, 0u);
    } else {
        EXPECT_EQ(fromPlate, 0u);
        EXPECT_GT(plateIncremental, 50u);
    }

    // A fresh system over the final ray set.
    Registry& fresh = registry;
    const std::vector<glm::vec3> floorInc = registry.get<VertexIrradiance>(world.floor).irradiance;
    const std::vector<glm::vec3> wallInc = registry.get<VertexIrradiance>(world.wall).irradiance;
    const std::vector<glm::vec3> plateInc = registry.get<VertexIrradiance>(world.plate).irradiance;
    DetpIrradianceSystem reference(settings);
    reference.build(fresh);
    fresh.ctx().get<PhotonDelta>().full = true;
    reference.update(fresh, {});

    // Tolerance: a sum of n double additions is within (n - 1) 2^-53 T of the exact sum, T the
    // sum of the magnitudes added; both sums here took at most `segmentsSeen` additions of at
    // most 1.5 W a channel, so they differ by at most 2 n^2 1.5 2^-53 W. Each is then rounded
    // once to float (2^-24 relative), so the published values may differ by 2^-23 relative.
    const double n = double(segmentsSeen);
    const double absolute = 2.0 * n * n * 1.5 * std::ldexp(1.0, -53) /
                            (kPi * IncrementalWorld::kRadius * IncrementalWorld::kRadius);
    const auto compare = [&](const std::vector<glm::vec3>& incremental, Entity e) {
        const auto& full = fresh.get<VertexIrradiance>(e).irradiance;
        ASSERT_EQ(incremental.size(), full.size());
        for (std::size_t v = 0; v < full.size(); ++v)
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR(incremental[v][c], full[v][c],
                            std::ldexp(double(std::abs(full[v][c])), -23) + absolute)
                    << registry.get<Name>(e).value << " vertex " << v << " channel " << c;
    };
    compare(floorInc, world.floor);
    compare(wallInc, world.wall);
    compare(plateInc, world.plate);
}

TEST(Detp, IncrementalEqualsFullAfter100RandomUpdates) {
    expectIncrementalEqualsFull(false);
}

TEST(Detp, IncrementalEqualsFullWhenDeltasStartOnAConvexMobile) {
    expectIncrementalEqualsFull(true);
}

/// Two DETP systems over one world: `kept` keeps copies of the segments near moved mobiles
/// (NearSegments, the default), `walked` walks the paths near them at every move.
struct KeptAndWalked {
    DetpIrradianceSystem kept, walked;

    static DetpSettings settings(float margin, bool hybrid) {
        DetpSettings s;
        s.discRadius = IncrementalWorld::kRadius;
        s.nearSegmentMargin = margin;
        s.hybrid = hybrid;
        return s;
    }
    /// Builds both and makes their first (full) estimates.
    explicit KeptAndWalked(Registry& registry, bool hybrid = false)
        : kept(settings(DetpSettings{}.nearSegmentMargin, hybrid)), walked(settings(0.f, hybrid)) {
        kept.build(registry);
        walked.build(registry);
        kept.update(registry, {});
        walked.update(registry, {});
        registry.clearChanges();
    }
    /// A frame of both; whether `mobile`'s irradiance came out the same bit for bit.
    bool update(Registry& registry, Entity mobile) {
        kept.update(registry, {});
        const std::vector<glm::vec3> fromKept = registry.get<VertexIrradiance>(mobile).irradiance;
        walked.update(registry, {});
        const auto& fromWalk = registry.get<VertexIrradiance>(mobile).irradiance;
        registry.clearChanges();
        return std::memcmp(fromKept.data(), fromWalk.data(), fromWalk.size() * sizeof(glm::vec3)) ==
               0;
    }
};

/// See the tests below.
void expectCopiesGiveTheWalksSums(bool hybrid) {
    // The plate drifts a centimetre or two a frame while random deltas re-trace paths all over
    // the box (their heads stopping on the plate, so the segments that leave it are skipped).
    // One system keeps a copy of the segments near the plate and updates it from each delta
    // (NearSegments); the other walks every path at every move. The plate's irradiance must be
    // the same bit for bit at every frame. In hybrid mode the paths' first segments do not
    // count (their light, unlisted in the store, counts as one the renderer draws).
    IncrementalWorld world;
    world.stopper = world.plate;
    Registry& registry = world.registry;
    std::mt19937 rng(41);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    appendRandomPaths(rng, world, 3000);
    KeptAndWalked systems(registry, hybrid);
    const DetpIrradianceSystem& kept = systems.kept;
    const DetpIrradianceSystem& walked = systems.walked;

    glm::vec3 position(0.5f, 0.3f, 0.5f);
    std::size_t moves = 0, rebuilds = 0, fromCopy = 0, crossings = 0;
    for (int frame = 1; frame <= 150; ++frame) {
        randomDelta(rng, world, 1 + std::size_t(unit(rng) * 40.f));
        // Still for 20 frames once (its copy is dropped after kNearIdleFrames), and every
        // seventh frame.
        const bool still = frame % 7 == 0 || (frame > 60 && frame <= 80);
        if (!still) {
            position += glm::vec3(0.02f * unit(rng) - 0.01f, 0.f, 0.02f * unit(rng));
            if (position.z > 0.75f) position.z = 0.25f; // a jump now and then
            registry.patch<WorldTransform>(world.plate).matrix =
                glm::translate(kIdentity, position);
        }
        ASSERT_TRUE(systems.update(registry, world.plate)) << "frame " << frame;
        ASSERT_FALSE(kept.lastFrame().full);
        ASSERT_EQ(kept.lastFrame().movedMobiles, still ? 0u : 1u) << "frame " << frame;
        if (still) continue;
        ++moves;
        rebuilds += kept.lastFrame().mobilesWalked;
        // Without a rebuild no path is walked: the copy alone is read.
        if (kept.lastFrame().mobilesWalked == 0) {
            EXPECT_EQ(kept.lastFrame().candidatePaths, 0u);
            ++fromCopy;
        }
        EXPECT_EQ(walked.lastFrame().mobilesWalked, 1u);
        EXPECT_EQ(walked.lastFrame().candidatePaths, store.pathCount());
        EXPECT_EQ(kept.lastFrame().candidateSegments, walked.lastFrame().candidateSegments);
        crossings += kept.lastFrame().crossings;
    }
    // Most moves read the copy; it was made anew after the plate's jumps, after the still
    // spell, and when the drift took the plate out of it.
    EXPECT_GT(fromCopy, moves / 2);
    EXPECT_GE(rebuilds, 4u);
    EXPECT_GT(crossings, hybrid ? 1'000u : 10'000u); // hybrid: later bounces' crossings only
}

TEST(Detp, AMovingMobilesCopyOfTheSegmentsNearItGivesTheWalksSumsBitForBit) {
    expectCopiesGiveTheWalksSums(false);
}

TEST(Detp, AMovingMobilesCopyGivesTheWalksSumsInHybridModeToo) {
    expectCopiesGiveTheWalksSums(true);
}

TEST(Detp, AMobileWhoseCopyWouldOutgrowItsWalkKeepsNone) {
    // Every path bounces six times straight through the plate's neighbourhood: a copy of the
    // segments near the plate would hold six per path a walk reads, more than it is worth
    // (kNearCopiesPerWalkedPath). The first estimate's walk shows it (from the two boxes'
    // surface areas), and the moves walk the paths without one. The sums stay those of a
    // walk, bit for bit.
    IncrementalWorld world;
    Registry& registry = world.registry;
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    for (int i = 0; i < 2000; ++i) {
        const float x = 0.3f + 0.4f * unit(rng), z = 0.3f + 0.4f * unit(rng);
        std::vector<Segment> path;
        for (std::uint8_t k = 0; k < 6; ++k) {
            const bool down = k % 2 == 0;
            path.push_back({{x, down ? 0.6f : 0.f, z},
                            {0.f, down ? -1.f : 1.f, 0.f},
                            0.6f,
                            glm::vec3(1e-3f),
                            world.floor,
                            0,
                            k});
        }
        appendPath(store, path);
    }
    KeptAndWalked systems(registry);
    const DetpIrradianceSystem& kept = systems.kept;
    ASSERT_TRUE(kept.lastFrame().full);
    EXPECT_EQ(kept.lastFrame().mobilesWalked, 1u);
    EXPECT_EQ(kept.lastFrame().nearSegments, 0u); // a full estimate makes no copies
    for (int frame = 1; frame <= 3; ++frame) {
        registry.patch<WorldTransform>(world.plate).matrix =
            glm::translate(kIdentity, {0.5f + 0.01f * float(frame), 0.3f, 0.5f});
        registry.ctx().get<PhotonDelta>() = PhotonDelta{};
        ASSERT_TRUE(systems.update(registry, world.plate)) << "frame " << frame;
        EXPECT_EQ(kept.lastFrame().mobilesWalked, 1u) << "frame " << frame;
        EXPECT_EQ(kept.lastFrame().candidatePaths, store.pathCount());
        EXPECT_EQ(kept.lastFrame().nearSegments, 0u) << "frame " << frame; // no copy
        EXPECT_GT(kept.lastFrame().crossings, 1000u);
    }
}

TEST(Detp, DriftPolicySchedulesAFullReestimate) {
    // One path lands on the floor's centre vertex, re-traced every frame from another height:
    // each frame subtracts its old segment and adds its new one, two additions to that vertex
    // (its neighbours lie 5 cm away, beyond the 3 cm discs). With a limit of 50 the 25th
    // incremental frame reaches it, so the 26th after a full one is full.
    Registry registry;
    addDetpResources(registry);
    const Entity floor = addUnitFloor(registry, 20);
    const glm::vec3 centre(0.5f, 0.f, 0.5f);
    const auto landing = [&](float height) {
        return Segment{centre + glm::vec3(0.f, height, 0.f),
                       {0.f, -1.f, 0.f},
                       height,
                       glm::vec3(1.f),
                       floor,
                       0,
                       0};
    };
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    appendPath(store, std::vector<Segment>{landing(1.f)});
    DetpSettings settings;
    settings.discRadius = 0.03f;
    settings.maxIncrementalUpdates = 50;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    ASSERT_TRUE(system.lastFrame().full);

    std::vector<int> fullFrames;
    for (int frame = 1; frame <= 60; ++frame) {
        PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
        delta = PhotonDelta{};
        delta.paths = {0};
        push(delta.oldSegments, landing(store.segments.length[0]));
        const Segment next = landing(frame % 2 ? 2.f : 1.f);
        push(delta.newSegments, next);
        delta.oldFirst = {0, 1};
        delta.newFirst = {0, 1};
        store.segments.clear();
        push(store.segments, next);
        system.update(registry, {});
        if (system.lastFrame().full)
            fullFrames.push_back(frame);
        else
            EXPECT_EQ(system.lastFrame().crossings, 2u) << "frame " << frame;
    }
    EXPECT_EQ(fullFrames, (std::vector<int>{26, 52}));
}

TEST(Detp, IncrementalSumsThatCancelNeverPublishNegativeIrradiance) {
    // A bright and a faint photon land on the floor's centre vertex: in double, 1e8 + 1e-9 is
    // 1e8. With plain double sums, taking the bright one away, then the faint one, left -1e-9
    // where the exact sum is 0; the sums now carry their rounding error and reach 0 exactly
    // here. Irradiance is never negative whatever rounding is left: the vertex publishes 0.
    Registry registry;
    addDetpResources(registry);
    const Entity floor = addUnitFloor(registry, 20);
    const glm::vec3 centre(0.5f, 0.f, 0.5f);
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    const auto landing = [&](float power) {
        return Segment{centre + glm::vec3(0.f, 1.f, 0.f),
                       {0.f, -1.f, 0.f},
                       1.f,
                       glm::vec3(power),
                       floor,
                       0,
                       0};
    };
    for (const float power : {1e8f, 1e-9f}) {
        const Segment path[1] = {landing(power)};
        appendPath(store, path);
    }
    DetpSettings settings;
    settings.discRadius = 0.03f;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    const std::uint32_t v = 10 * 21 + 10; // the centre vertex
    EXPECT_GT(irradiance(registry, floor).irradiance[v].x, 0.f);
    for (std::uint32_t p = 0; p < 2; ++p) { // each path now leaves straight up instead
        PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
        delta = PhotonDelta{};
        delta.sequence = p + 1;
        delta.paths = {p};
        push(delta.oldSegments, landing(p == 0 ? 1e8f : 1e-9f));
        const Segment away{
            centre + glm::vec3(0.f, 1.f, 0.f), {0.f, 1.f, 0.f}, kInf, glm::vec3(1.f), {}, 0, 0};
        push(delta.newSegments, away);
        delta.oldFirst = {0, 1};
        delta.newFirst = {0, 1};
        store.segments.direction[p] = away.direction;
        store.segments.length[p] = kInf;
        store.segments.hitEntity[p] = Entity{};
        system.update(registry, {});
        ASSERT_FALSE(system.lastFrame().full);
    }
    EXPECT_EQ(irradiance(registry, floor).irradiance[v], glm::vec3(0.f));
}

TEST(Detp, ABrightPhotonThatComesAndGoesLeavesTheFaintOnesIntact) {
    // A 1e8 W photon and a thousand of 1e-9 W land on the floor's centre vertex; then the
    // bright one leaves. Plain double sums lose every faint photon under the bright one (each
    // addition rounds back to 1e8) and end at 0, checked below; the vertex's sum carries its
    // rounding error (CompensatedSum), so it ends where a fresh estimate of the faint photons
    // does, to the float it is published in.
    constexpr std::uint32_t kFaint = 1000;
    Registry registry;
    addDetpResources(registry);
    const Entity floor = addUnitFloor(registry, 20);
    const glm::vec3 centre(0.5f, 0.f, 0.5f);
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    const Segment bright{
        centre + glm::vec3(0.f, 1.f, 0.f), {0.f, -1.f, 0.f}, 1.f, glm::vec3(1e8f), floor, 0, 0};
    Segment faint = bright;
    faint.power = glm::vec3(1e-9f);
    appendPath(store, std::span(&bright, 1));
    for (std::uint32_t i = 0; i < kFaint; ++i)
        appendPath(store, std::span(&faint, 1));
    double plain = double(bright.power.x);
    for (std::uint32_t i = 0; i < kFaint; ++i)
        plain += double(faint.power.x);
    plain -= double(bright.power.x);
    EXPECT_EQ(plain, 0.0) << "the case does not need compensation";

    DetpSettings settings;
    settings.discRadius = 0.03f;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    // The bright photon now leaves straight up.
    PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
    delta = PhotonDelta{};
    delta.sequence = 1;
    delta.paths = {0};
    push(delta.oldSegments, bright);
    const Segment away{
        centre + glm::vec3(0.f, 1.f, 0.f), {0.f, 1.f, 0.f}, kInf, glm::vec3(1e8f), {}, 0, 0};
    push(delta.newSegments, away);
    delta.oldFirst = {0, 1};
    delta.newFirst = {0, 1};
    store.segments.direction[0] = away.direction;
    store.segments.length[0] = kInf;
    store.segments.hitEntity[0] = Entity{};
    system.update(registry, {});
    ASSERT_FALSE(system.lastFrame().full);
    const std::uint32_t v = 10 * 21 + 10; // the centre vertex
    const float incremental = irradiance(registry, floor).irradiance[v].x;

    DetpIrradianceSystem fresh(settings);
    fresh.build(registry);
    registry.ctx().get<PhotonDelta>().full = true;
    fresh.update(registry, {});
    const float full = irradiance(registry, floor).irradiance[v].x;
    const double exact = double(kFaint) * double(faint.power.x) /
                         (kPi * double(settings.discRadius) * double(settings.discRadius));
    // Full against exact: the compensated double sum (error far below 2^-40 here), the scale
    // 1 / (pi r^2) and the published float, a few roundings of at most 2^-24 each: 4 allowed.
    EXPECT_NEAR(full, exact, exact * 0x1p-22);
    // Both publish nearly the same double as a float: one float step apart at most.
    EXPECT_NEAR(incremental, full, std::ldexp(double(full), -23));
}

TEST(Detp, EachDeltaIsAppliedOnceAndAMissedOneForcesAFullEstimate) {
    IncrementalWorld world;
    Registry& registry = world.registry;
    std::mt19937 rng(12);
    appendRandomPaths(rng, world, 500);
    DetpSettings settings;
    settings.discRadius = IncrementalWorld::kRadius;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    registry.ctx().get<PhotonDelta>().sequence = 1;
    system.update(registry, {});
    registry.clearChanges();
    ASSERT_TRUE(system.lastFrame().full);

    randomDelta(rng, world, 30);
    registry.ctx().get<PhotonDelta>().sequence = 2;
    system.update(registry, {});
    registry.clearChanges();
    EXPECT_FALSE(system.lastFrame().full);
    EXPECT_GT(system.lastFrame().crossings, 0u);
    const std::vector<glm::vec3> once = registry.get<VertexIrradiance>(world.floor).irradiance;
    // The photon update did not run: the same delta again changes nothing.
    system.update(registry, {});
    registry.clearChanges();
    EXPECT_FALSE(system.lastFrame().full);
    EXPECT_EQ(system.lastFrame().crossings, 0u);
    const std::vector<glm::vec3>& again = registry.get<VertexIrradiance>(world.floor).irradiance;
    for (std::size_t v = 0; v < once.size(); ++v)
        ASSERT_TRUE(bitEqual(again[v], once[v])) << v;
    // DETP missed update 3: update 4 is estimated in full.
    randomDelta(rng, world, 30);
    registry.ctx().get<PhotonDelta>().sequence = 4;
    system.update(registry, {});
    registry.clearChanges();
    EXPECT_TRUE(system.lastFrame().full);
}

TEST(Detp, MovedMobileIsReestimatedFromThePathGridAlone) {
    // A 4 m floor with photons all over it and a small plate: the paths near the plate are a
    // small part of the ray set.
    Registry registry;
    addDetpResources(registry);
    const Entity floor =
        addReceiverMesh(registry, gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 4.f}, {4.f, 0.f, 0.f}, 40),
                        kIdentity, false, "floor");
    const Entity plate = addReceiverMesh(
        registry, gridMesh({-0.25f, 0.f, -0.25f}, {0.f, 0.f, 0.5f}, {0.5f, 0.f, 0.f}, 8),
        glm::translate(kIdentity, {1.f, 0.5f, 1.f}), true, "plate");
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    for (int i = 0; i < 40'000; ++i) {
        // Straight down onto the floor, then up and out of the scene.
        const glm::vec3 o(4.f * unit(rng), 0.2f + 1.8f * unit(rng), 4.f * unit(rng));
        glm::vec3 up = randomUnit(rng);
        up.y = std::abs(up.y);
        const Segment path[2] = {{o, {0.f, -1.f, 0.f}, o.y, glm::vec3(1e-3f), floor, 0, 0},
                                 {{o.x, 0.f, o.z}, up, kInf, glm::vec3(5e-4f), {}, 0, 1}};
        appendPath(store, path);
    }
    // A photon skimming in along -x that stops short of the plate's plane (landing on a
    // surface that folds there) and still counts (up to kDiscEndTolerance radii short): it
    // crosses the disc of the plate's edge vertex at (2.75, 0.8, 3) where the plate will be,
    // within a radius of it, but ends more than 1.01 radii out along x. Its path held a segment
    // far from the plate when the grid was built, then was re-traced into this one: the grid
    // finds it by the box of its new segment alone, not by its cells.
    constexpr float r = 0.06f;
    const glm::vec3 skim = glm::normalize(glm::vec3(-1.f, -0.01f, 0.f));
    const glm::vec3 crossing(2.75f + 0.995f * r, 0.8f, 3.f);
    const float shortBy = 0.019f * r, length = 0.5f;
    const glm::vec3 skimOrigin = crossing - length * skim;
    ASSERT_TRUE(crossesDisc(skimOrigin, skim, length - shortBy, {2.75f, 0.8f, 3.f},
                            {0.f, 1.f, 0.f}, r));
    ASSERT_GT(skimOrigin.x + (length - shortBy) * skim.x, 2.75f + 1.01f * r);
    const auto skimPath = std::uint32_t(store.pathCount());
    const Segment farAway[1] = {{{0.5f, 1.5f, 0.5f}, {0.f, -1.f, 0.f}, 1.5f, glm::vec3(1.f), floor}};
    appendPath(store, farAway);

    PhotonPathGrid& grid = registry.ctx().emplace<PhotonPathGrid>();
    grid.build(store, Aabb{{0.f, 0.f, 0.f}, {4.f, 2.f, 4.f}}, 32);
    const std::uint32_t skimSegment = store.paths[skimPath].first;
    store.segments.origin[skimSegment] = skimOrigin;
    store.segments.direction[skimSegment] = skim;
    store.segments.length[skimSegment] = length - shortBy;
    grid.markChanged(store, std::span(&skimPath, 1));

    DetpSettings settings;
    settings.discRadius = r;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    registry.clearChanges();

    registry.patch<WorldTransform>(plate).matrix = glm::translate(kIdentity, {2.5f, 0.8f, 3.f});
    registry.ctx().get<PhotonDelta>() = PhotonDelta{};
    system.update(registry, {});
    EXPECT_EQ(system.lastFrame().movedMobiles, 1u);
    EXPECT_GT(system.lastFrame().crossings, 1000u);
    EXPECT_LT(system.lastFrame().candidatePaths, store.pathCount() / 4);
    const std::vector<glm::vec3> fromGrid = registry.get<VertexIrradiance>(plate).irradiance;
    // The skimmer's watt, over the disc, is most of that vertex's irradiance.
    const auto& plateMesh = registry.get<Mesh>(plate);
    std::size_t edgeVertex = plateMesh.positions.size();
    for (std::size_t v = 0; v < plateMesh.positions.size(); ++v)
        if (glm::distance(plateMesh.positions[v], glm::vec3(0.25f, 0.f, 0.f)) < 1e-6f) edgeVertex = v;
    ASSERT_LT(edgeVertex, plateMesh.positions.size());
    EXPECT_GT(fromGrid[edgeVertex].x, 0.9f / (glm::pi<float>() * r * r));

    // The same plate estimated against every stored segment: the grid's candidates are summed in
    // the same (path) order, so the values are the same bit for bit.
    registry.ctx().erase<PhotonPathGrid>();
    DetpIrradianceSystem reference(settings);
    reference.build(registry);
    reference.update(registry, {});
    EXPECT_EQ(reference.lastFrame().candidatePaths, store.pathCount());
    const auto& fromAll = registry.get<VertexIrradiance>(plate).irradiance;
    ASSERT_EQ(fromGrid.size(), fromAll.size());
    EXPECT_EQ(std::memcmp(fromGrid.data(), fromAll.data(), fromAll.size() * sizeof(glm::vec3)), 0);

    // A grid that does not index the current ray set is not asked: one built before the last
    // full shot (its paths may all have changed since), or one left empty (as the photon update
    // leaves it with PhotonSettings::fullRecompute).
    PhotonPathGrid& stale = registry.ctx().emplace<PhotonPathGrid>();
    stale.build(store, Aabb{{0.f, 0.f, 0.f}, {4.f, 2.f, 4.f}}, 32);
    ++store.generation;
    EXPECT_FALSE(stale.indexes(store));
    DetpIrradianceSystem afterShot(settings);
    afterShot.build(registry);
    afterShot.update(registry, {});
    EXPECT_EQ(afterShot.lastFrame().candidatePaths, store.pathCount());
    stale.build(store, Aabb{{0.f, 0.f, 0.f}, {4.f, 2.f, 4.f}}, 32);
    EXPECT_TRUE(stale.indexes(store));
    stale.clear();
    EXPECT_FALSE(stale.indexes(store));
    EXPECT_EQ(stale.memoryBytes(), 0u); // all of it handed back
    DetpIrradianceSystem afterClear(settings);
    afterClear.build(registry);
    afterClear.update(registry, {});
    EXPECT_EQ(afterClear.lastFrame().candidatePaths, store.pathCount());
    const auto& fromAllAgain = registry.get<VertexIrradiance>(plate).irradiance;
    EXPECT_EQ(std::memcmp(fromGrid.data(), fromAllAgain.data(), fromAll.size() * sizeof(glm::vec3)),
              0);
}

/// A closed cube of side 2 half centred on the origin, each face its own n x n grid facing out
/// (split vertices, face normals): convex with outward normals.
Mesh cubeOfGrids(float half, int n) {
    Mesh cube;
    for (int axis = 0; axis < 3; ++axis)
        for (const float side : {-1.f, 1.f}) {
            glm::vec3 centre(0.f), u(0.f), v(0.f);
            centre[axis] = side * half;
            u[(axis + 1) % 3] = 2.f * half;
            v[(axis + 2) % 3] = 2.f * half;
            if (side < 0.f) std::swap(u, v); // cross(u, v) points out
            const Mesh face = gridMesh(centre - 0.5f * (u + v), u, v, n);
            const auto base = std::uint32_t(cube.positions.size());
            cube.positions.insert(cube.positions.end(), face.positions.begin(),
                                  face.positions.end());
            cube.normals.insert(cube.normals.end(), face.normals.begin(), face.normals.end());
            for (const std::uint32_t i : face.indices)
                cube.indices.push_back(base + i);
        }
    return cube;
}

/// A UV sphere whose normals point out from its centre: smooth, so almost every vertex has a
/// normal of its own. `n` rings of `2 n` segments.
Mesh sphereMesh(float radius, int n) {
    Mesh sphere;
    for (int ring = 0; ring <= n; ++ring)
        for (int segment = 0; segment <= 2 * n; ++segment) {
            const float theta = glm::pi<float>() * float(ring) / float(n);
            const float phi = glm::pi<float>() * float(segment) / float(n);
            const glm::vec3 normal(std::sin(theta) * std::cos(phi), std::cos(theta),
                                   std::sin(theta) * std::sin(phi));
            sphere.positions.push_back(radius * normal);
            sphere.normals.push_back(normal);
        }
    const auto at = [&](int ring, int segment) {
        return std::uint32_t(ring * (2 * n + 1) + segment);
    };
    for (int ring = 0; ring < n; ++ring)
        for (int segment = 0; segment < 2 * n; ++segment)
            for (const std::uint32_t i :
                 {at(ring, segment), at(ring, segment + 1), at(ring + 1, segment + 1),
                  at(ring, segment), at(ring + 1, segment + 1), at(ring + 1, segment)})
                sphere.indices.push_back(i);
    return sphere;
}

TEST(Detp, OnlyConvexMobilesAreCalledConvex) {
    Registry registry;
    addDetpResources(registry);
    const glm::mat4 at = glm::translate(kIdentity, {0.5f, 0.5f, 0.5f});
    const Entity cube = addReceiverMesh(registry, cubeOfGrids(0.2f, 4), at, true);
    const Entity corners = addReceiverMesh(registry, test::boxMesh(glm::vec3(0.2f)), at, true);
    Mesh inward = cubeOfGrids(0.2f, 4);
    for (glm::vec3& normal : inward.normals)
        normal = -normal;
    const Entity room = addReceiverMesh(registry, std::move(inward), at, true);
    const Entity plate = addReceiverMesh(
        registry, gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 4), at, true);
    Mesh fold = gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 4);       // floor, up
    const Mesh back = gridMesh({0.f, 0.f, 0.f}, {1.f, 0.f, 0.f}, {0.f, 1.f, 0.f}, 4); // wall, +z
    for (const std::uint32_t i : back.indices)
        fold.indices.push_back(std::uint32_t(fold.positions.size()) + i);
    fold.positions.insert(fold.positions.end(), back.positions.begin(), back.positions.end());
    fold.normals.insert(fold.normals.end(), back.normals.begin(), back.normals.end());
    const Entity inside = addReceiverMesh(registry, std::move(fold), at, true);
    // Two floors at different heights: every vertex has the same normal, and the lower floor's
    // tangent planes have the upper floor in front of them.
    Mesh steps = gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 4);
    const Mesh upper = gridMesh({1.f, 0.1f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 4);
    for (const std::uint32_t i : upper.indices)
        steps.indices.push_back(std::uint32_t(steps.positions.size()) + i);
    steps.positions.insert(steps.positions.end(), upper.positions.begin(), upper.positions.end());
    steps.normals.insert(steps.normals.end(), upper.normals.begin(), upper.normals.end());
    const Entity stairs = addReceiverMesh(registry, std::move(steps), at, true);
    // A finely refined box: 6 x 121^2 vertices, but 6 distinct normals to test them against.
    const Entity fineBox = addReceiverMesh(registry, cubeOfGrids(0.2f, 120), at, true);
    const Entity ball = addReceiverMesh(registry, sphereMesh(0.2f, 16), at, true);
    // A smooth mesh whose vertices times distinct normals pass the check's limit.
    const Mesh fineSphere = sphereMesh(0.2f, 80);
    ASSERT_GT(std::uint64_t(fineSphere.positions.size()) * (fineSphere.positions.size() / 2),
              ReceiverSet::kConvexCheckPairs);
    const Entity large = addReceiverMesh(registry, fineSphere, at, true);
    const Entity ground = addReceiverMesh(registry, cubeOfGrids(0.2f, 4), at, false);

    ReceiverSet set;
    set.build(registry);
    const auto convex = [&](Entity e) { return set.receivers()[std::size_t(set.find(e))].convex; };
    EXPECT_TRUE(convex(cube));
    EXPECT_TRUE(convex(corners)); // corner normals between the faces' still support it
    EXPECT_TRUE(convex(plate));   // flat: every vertex lies on every tangent plane
    EXPECT_FALSE(convex(room));   // normals pointing in
    EXPECT_FALSE(convex(inside)); // an inside corner: the wall stands in front of the floor
    EXPECT_FALSE(convex(stairs)); // the upper floor stands in front of the lower one
    EXPECT_TRUE(convex(fineBox));
    EXPECT_TRUE(convex(ball));
    EXPECT_FALSE(convex(large));  // not checked
    EXPECT_FALSE(convex(ground)); // static meshes are never skipped over
}

TEST(Detp, SegmentsLeavingAConvexMobileAreSkippedWithoutLosingACrossing) {
    // Photons land on a cube and on an inside corner (both mobile) and leave them; others pass
    // by. Powers are multiples of 2^-10 W, so every sum is exact in any order: the system's
    // estimate, which skips the segments that leave the cube, must equal a brute-force count of
    // every segment against every disc, bit for bit, in a full estimate and after a delta.
    Registry registry;
    addDetpResources(registry);
    const glm::vec3 centre(0.5f, 0.5f, 0.5f);
    constexpr float kHalf = 0.25f, kRadius = 0.07f;
    const Entity cube =
        addReceiverMesh(registry, cubeOfGrids(kHalf, 4), glm::translate(kIdentity, centre), true);
    const Entity corner =
        addReceiverMesh(registry, gridMesh({2.f, 0.f, 0.f}, {0.f, 0.f, 0.5f}, {0.5f, 0.f, 0.f}, 5),
                        kIdentity, true, "corner floor");
    // The corner is one mesh: the floor above and a wall standing on its back edge, facing +z.
    Mesh& fold = registry.get<Mesh>(corner);
    const Mesh wall = gridMesh({2.f, 0.f, 0.f}, {0.5f, 0.f, 0.f}, {0.f, 0.5f, 0.f}, 5);
    for (const std::uint32_t i : wall.indices)
        fold.indices.push_back(std::uint32_t(fold.positions.size()) + i);
    fold.positions.insert(fold.positions.end(), wall.positions.begin(), wall.positions.end());
    fold.normals.insert(fold.normals.end(), wall.normals.begin(), wall.normals.end());

    std::mt19937 rng(17);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::uniform_int_distribution<int> quanta(1, 64);
    const auto power = [&] {
        return glm::vec3(float(quanta(rng)), float(quanta(rng)), float(quanta(rng))) / 1024.f;
    };
    const auto outward = [&](const glm::vec3& normal) { // a random direction in front
        glm::vec3 d = randomUnit(rng);
        return glm::dot(d, normal) < 0.f ? d - 2.f * glm::dot(d, normal) * normal : d;
    };
    // A path that lands on `target` (normal `normal`, on `hit`) from in front and leaves it.
    const auto landAndLeave = [&](const glm::vec3& target, const glm::vec3& normal, Entity hit,
                                  const Segment& next) {
        const glm::vec3 from = target + (0.05f + unit(rng)) * outward(normal);
        const Segment in{
            from, glm::normalize(target - from), glm::length(target - from), power(), hit, 0, 0};
        const Segment path[2] = {in, next};
        return std::vector<Segment>(std::begin(path), std::end(path));
    };
    const auto onCube = [&](glm::vec3& normal) { // a point on a random face, exactly on it
        const int face = std::uniform_int_distribution<int>(0, 5)(rng);
        normal = glm::vec3(0.f);
        normal[face / 2] = face % 2 ? 1.f : -1.f;
        glm::vec3 p = centre + kHalf * normal;
        for (int axis = 0; axis < 3; ++axis)
            if (axis != face / 2) p[axis] += kHalf * (2.f * unit(rng) - 1.f);
        return p;
    };
    const auto leaveCube = [&](const glm::vec3& at, const glm::vec3& normal, std::uint8_t bounce) {
        return Segment{at, outward(normal), kInf, power(), {}, 0, bounce};
    };
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    for (int i = 0; i < 3000; ++i) {
        glm::vec3 normal;
        const glm::vec3 p = onCube(normal);
        appendPath(store, landAndLeave(p, normal, cube, leaveCube(p, normal, 1)));
    }
    for (int i = 0; i < 2000; ++i) { // from the corner's floor onto its wall, or away
        const glm::vec3 p(2.f + 0.5f * unit(rng), 0.f, 0.5f * unit(rng));
        const glm::vec3 toWall =
            glm::vec3(2.f + 0.5f * unit(rng), 0.5f * unit(rng), 0.f) - p; // ends on the wall
        const Segment next =
            i % 2 ? Segment{p, glm::normalize(toWall), glm::length(toWall), power(), corner, 0, 1}
                  : Segment{p, outward({0.f, 1.f, 0.f}), kInf, power(), {}, 0, 1};
        appendPath(store, landAndLeave(p, {0.f, 1.f, 0.f}, corner, next));
    }
    for (int i = 0; i < 2000; ++i) { // passing through the space around both
        const glm::vec3 o(3.f * unit(rng) - 0.25f, 1.2f * unit(rng) - 0.1f,
                          1.2f * unit(rng) - 0.1f);
        const Segment path[1] = {{o, randomUnit(rng), 0.3f + unit(rng), power(), {}, 0, 0}};
        appendPath(store, path);
    }

    // Brute force: every live segment of the store against every disc, in double; with
    // `skipLeaving`, leaving the segments that start on the mesh out.
    const auto bruteForce = [&](Entity e, bool skipLeaving) {
        const Mesh& mesh = registry.get<Mesh>(e);
        const glm::mat4& world = registry.get<WorldTransform>(e).matrix;
        std::vector<glm::vec3> out;
        const double toIrradiance = 1.0 / (kPi * double(kRadius) * double(kRadius));
        for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
            const glm::vec3 c(world * glm::vec4(mesh.positions[v], 1.f));
            glm::dvec3 sum(0.0);
            for (const PhotonPath& path : store.paths)
                for (std::uint32_t s = path.first; s < path.first + path.count; ++s)
                    if (!(skipLeaving && s > path.first && store.segments.hitEntity[s - 1] == e) &&
                        crossesDisc(store.segments.origin[s], store.segments.direction[s],
                                    store.segments.length[s], c, mesh.normals[v], kRadius))
                        sum += glm::dvec3(store.segments.power[s]);
            out.push_back(glm::vec3(sum * toIrradiance));
        }
        return out;
    };
    const auto expectBruteForce = [&](const char* when) {
        for (const Entity e : {cube, corner}) {
            const std::vector<glm::vec3> expected = bruteForce(e, e == cube);
            const auto& got = registry.get<VertexIrradiance>(e).irradiance;
            ASSERT_EQ(got.size(), expected.size());
            std::size_t lit = 0;
            for (std::size_t v = 0; v < got.size(); ++v) {
                ASSERT_TRUE(bitEqual(got[v], expected[v]))
                    << when << ": " << registry.get<Name>(e).value << " vertex " << v;
                lit += expected[v].x > 0.f ? 1 : 0;
            }
            EXPECT_GT(lit, got.size() / 2) << when;
        }
    };

    DetpSettings settings;
    settings.discRadius = kRadius;
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    registry.clearChanges();
    ASSERT_TRUE(system.lastFrame().full);
    expectBruteForce("full estimate");
    // No segment that leaves a face skipped a crossing: without the skip the sums are the same.
    EXPECT_EQ(bruteForce(cube, true), bruteForce(cube, false));

    // A frame in which the cube's photons leave in new directions and some land elsewhere on
    // it: the delta's suffixes start on the cube (the kept prefix's hit) and are skipped too.
    // Some leave from an edge, grazing the next face's plane: crossesDisc counts such a
    // segment for that face's discs at t = 0 (it starts on their plane, heading behind it),
    // though it leaves the cube; skipped, it is not counted, in the delta as in a full estimate.
    PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
    delta = PhotonDelta{};
    delta.sequence = 1;
    delta.oldFirst = {0};
    delta.newFirst = {0};
    for (std::uint32_t p = 0; p < 3000; p += 3) {
        PhotonPath& path = store.paths[p];
        const std::uint32_t first = p % 2 ? 0 : 1; // re-traced from the landing or the leaving
        for (std::uint32_t k = first; k < path.count; ++k)
            push(delta.oldSegments,
                 {store.segments.origin[path.first + k], store.segments.direction[path.first + k],
                  store.segments.length[path.first + k], store.segments.power[path.first + k],
                  store.segments.hitEntity[path.first + k], 0,
                  store.segments.bounce[path.first + k]});
        glm::vec3 normal;
        const glm::vec3 q = onCube(normal);
        std::vector<Segment> fresh = landAndLeave(q, normal, cube, leaveCube(q, normal, 1));
        if (first == 1) { // the same landing, a new way out
            const glm::vec3 at = store.segments.origin[path.first + 1];
            const Segment kept{store.segments.origin[path.first],
                               store.segments.direction[path.first],
                               store.segments.length[path.first],
                               store.segments.power[path.first],
                               cube,
                               0,
                               0};
            glm::vec3 n(0.f);
            const glm::vec3 local = at - centre;
            const int axis = std::abs(local.x) == kHalf ? 0 : std::abs(local.y) == kHalf ? 1 : 2;
            n[axis] = local[axis] > 0.f ? 1.f : -1.f;
            fresh = {kept, leaveCube(at, n, 1)};
        } else if (p % 9 == 0) { // lands on an edge and leaves past the next face
            const int a = int(p / 9) % 3, b = (a + 1) % 3;
            glm::vec3 nF(0.f), nG(0.f), along(0.f);
            nF[a] = 1.f;
            nG[b] = -1.f;
            along[3 - a - b] = kHalf * (2.f * unit(rng) - 1.f);
            const glm::vec3 edge = centre + kHalf * (nF + nG) + along;
            fresh = landAndLeave(edge, glm::normalize(nF - nG), cube,
                                 {edge, glm::normalize(nF - 0.5f * nG), kInf, power(), {}, 0, 1});
        }
        for (std::uint32_t k = first; k < fresh.size(); ++k)
            push(delta.newSegments, fresh[k]);
        delta.paths.push_back(p);
        delta.oldFirst.push_back(std::uint32_t(delta.oldSegments.size()));
        delta.newFirst.push_back(std::uint32_t(delta.newSegments.size()));
        path = {std::uint32_t(store.segments.size()), std::uint16_t(fresh.size()), 0};
        for (const Segment& seg : fresh)
            push(store.segments, seg);
    }
    system.update(registry, {});
    ASSERT_FALSE(system.lastFrame().full);
    EXPECT_EQ(system.lastFrame().movedMobiles, 0u);
    expectBruteForce("after a delta");
    EXPECT_NE(bruteForce(cube, true), bruteForce(cube, false)); // the edge cases were there
    // A full estimate over the same ray set skips them too.
    DetpIrradianceSystem fresh(settings);
    fresh.build(registry);
    fresh.update(registry, {});
    ASSERT_TRUE(fresh.lastFrame().full);
    expectBruteForce("full estimate after the delta");
}

TEST(Detp, SameInputGivesBitIdenticalOutputOnAnyThreadCount) {
    std::vector<std::vector<glm::vec3>> results;
    for (const std::size_t threads : {1u, 2u, 4u}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
        IncrementalWorld world;
        std::mt19937 rng(5);
        appendRandomPaths(rng, world, 20'000);
        DetpSettings settings;
        settings.discRadius = IncrementalWorld::kRadius;
        DetpIrradianceSystem system(settings);
        system.build(world.registry);
        system.update(world.registry, {});
        randomDelta(rng, world, 200);
        system.update(world.registry, {});
        results.push_back(world.registry.get<VertexIrradiance>(world.floor).irradiance);
    }
    for (std::size_t i = 1; i < results.size(); ++i)
        ASSERT_EQ(std::memcmp(results[0].data(), results[i].data(),
                              results[0].size() * sizeof(glm::vec3)),
                  0);
}

// ---- set-up errors ------------------------------------------------------------------------

TEST(Detp, RejectsBadSettings) {
    const auto message = [](DetpSettings s) {
        try {
            DetpIrradianceSystem system(s);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    DetpSettings s;
    s.discRadius = -1.f;
    EXPECT_THAT(message(s), HasSubstr("DetpSettings.discRadius"));
    s = {};
    s.discRadius = std::nanf("");
    EXPECT_THAT(message(s), HasSubstr("DetpSettings.discRadius"));
    s = {};
    s.photonMapNeighbours = 0;
    EXPECT_THAT(message(s), HasSubstr("DetpSettings.photonMapNeighbours"));
    s.photonMapNeighbours = 4'000'000'000u; // asked for gigabytes and failed with bad_alloc
    EXPECT_THAT(message(s), HasSubstr("DetpSettings.photonMapNeighbours"));
    s = {};
    s.estimator = IrradianceEstimator(77); // ran as nothing: every vertex at 0
    EXPECT_THAT(message(s), HasSubstr("DetpSettings.estimator"));
    s = {};
    s.photonMapMaxRadius = kInf;
    EXPECT_THAT(message(s), HasSubstr("DetpSettings.photonMapMaxRadius"));
    s = {};
    s.maxIncrementalUpdates = 0;
    EXPECT_THAT(message(s), HasSubstr("DetpSettings.maxIncrementalUpdates"));
    for (const float margin : {-0.1f, 1.5f, std::nanf("")}) {
        s = {};
        s.nearSegmentMargin = margin;
        EXPECT_THAT(message(s), HasSubstr("DetpSettings.nearSegmentMargin"));
    }
    EXPECT_THROW(parseIrradianceEstimator("kernel"), Error);
    EXPECT_EQ(parseIrradianceEstimator("photonmap"), IrradianceEstimator::PhotonMap);
}

TEST(Detp, DefaultRadiusComesFromTheScene) {
    SceneInfo info;
    info.maxEdgeLength = 0.02f;
    EXPECT_FLOAT_EQ(defaultDiscRadius(info), 0.01f);
    info.maxEdgeLength = 0.f;
    info.bounds.extend(glm::vec3(0.f));
    info.bounds.extend(glm::vec3(3.f, 4.f, 0.f));
    EXPECT_FLOAT_EQ(defaultDiscRadius(info), 0.05f);
    EXPECT_THROW(defaultDiscRadius(SceneInfo{}), Error);
    // Scarce photons widen the disc to about 64 landings of evenly spread photons:
    // 100 m^2 and 10k photons give sqrt(6400 / (pi 10^4)) = 0.451 m.
    EXPECT_NEAR(defaultDiscRadius(info, 100.0, 10'000), std::sqrt(0.64 / kPi), 1e-6);
    // Plenty keep the mesh rule; no area or no photons leave it alone.
    EXPECT_FLOAT_EQ(defaultDiscRadius(info, 100.0, 100'000'000), 0.05f);
    EXPECT_FLOAT_EQ(defaultDiscRadius(info, 0.0, 10'000), 0.05f);
    EXPECT_FLOAT_EQ(defaultDiscRadius(info, 100.0, 0), 0.05f);

    Registry registry;
    addDetpResources(registry);
    addUnitFloor(registry, 2);
    DetpIrradianceSystem system(DetpSettings{});
    EXPECT_THROW(system.build(registry), Error); // radius 0 and no SceneInfo
    SceneInfo& described = registry.ctx().emplace<SceneInfo>();
    described.maxEdgeLength = 0.35f;
    system.build(registry);
    EXPECT_FLOAT_EQ(system.discRadius(), 0.175f);

    // A radius wider than the scene (the unit floor: 1.41 m across) is a mistake.
    described.bounds = {glm::vec3(0.f), {1.f, 0.f, 1.f}};
    DetpSettings wide;
    wide.discRadius = 1.5f;
    DetpIrradianceSystem tooWide(wide);
    try {
        tooWide.build(registry);
        ADD_FAILURE() << "a 1.5 m disc over a 1.41 m scene was accepted";
    } catch (const Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("wider than the whole scene"));
    }
    wide.discRadius = 1.4f;
    DetpIrradianceSystem wideEnough(wide);
    EXPECT_NO_THROW(wideEnough.build(registry));
}

TEST(Detp, AHandChosenRadiusThatCatchesFewPhotonsIsWarnedAbout) {
    // The unit floor (1 m^2) and 10,000 photons: a disc of 1 cm catches about 3 landings, one
    // of 2 cm about 13. Only the first is warned about (fewer than kFewDiscLandings).
    for (const float radius : {0.01f, 0.02f}) {
        Registry registry;
        addDetpResources(registry);
        addUnitFloor(registry, 4);
        DetpSettings settings;
        settings.discRadius = radius;
        settings.photonCount = 10'000;
        DetpIrradianceSystem system(settings);
        ::testing::internal::CaptureStderr();
        system.build(registry);
        const std::string log = ::testing::internal::GetCapturedStderr();
        EXPECT_EQ(log.find("photon landings per disc") != std::string::npos, radius == 0.01f)
            << log;
    }
}

TEST(Detp, ADefaultRadiusWiderThanATenthOfTheSceneIsWarnedAbout) {
    // The unit floor (1 m^2, 1.41 m across) and a 2 cm edge bound: 100 photons widen the
    // default radius to sqrt(64 / (100 pi)) = 0.45 m, a third of the scene; 100,000 give
    // 1.4 cm, 1 %.
    for (const std::uint32_t photons : {100u, 100'000u}) {
        Registry registry;
        addDetpResources(registry);
        addUnitFloor(registry, 4);
        SceneInfo& info = registry.ctx().emplace<SceneInfo>();
        info.bounds = Aabb{{0.f, 0.f, 0.f}, {1.f, 0.f, 1.f}};
        info.maxEdgeLength = 0.02f;
        DetpSettings settings;
        settings.photonCount = photons;
        DetpIrradianceSystem system(settings);
        const ScopedLogLevel verbose(LogLevel::Info); // whatever an earlier test left
        ::testing::internal::CaptureStderr();
        system.build(registry);
        const std::string log = ::testing::internal::GetCapturedStderr();
        EXPECT_EQ(log.find("the default disc radius") != std::string::npos, photons == 100u) << log;
    }
}

TEST(Detp, FlippedNormalsAreNamed) {
    // A floor wound to face up whose normals point down reads dark from above: a warning
    // names it. The same floor with its normals right says nothing.
    for (const bool flipped : {false, true}) {
        Registry registry;
        addDetpResources(registry);
        Mesh floor = gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 4);
        if (flipped)
            for (glm::vec3& n : floor.normals)
                n = -n;
        addReceiverMesh(registry, std::move(floor), kIdentity, false, "floor");
        DetpSettings settings;
        settings.discRadius = 0.1f;
        DetpIrradianceSystem system(settings);
        ::testing::internal::CaptureStderr();
        system.build(registry);
        const std::string log = ::testing::internal::GetCapturedStderr();
        const std::string named = "'floor': Mesh.normals point against the winding of 32 of its 32";
        EXPECT_EQ(log.find(named) != std::string::npos, flipped) << log;
    }
}

TEST(Detp, RejectsMeshesItCannotUse) {
    const auto buildError = [](Mesh mesh) {
        Registry registry;
        addDetpResources(registry);
        addReceiverMesh(registry, std::move(mesh), kIdentity, false, "bad");
        DetpSettings settings;
        settings.discRadius = 0.1f;
        DetpIrradianceSystem system(settings);
        try {
            system.build(registry);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    const Mesh good = gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 1);
    Mesh noNormals = good;
    noNormals.normals.clear();
    EXPECT_THAT(buildError(noNormals), HasSubstr("'bad': Mesh.normals has 0 entries"));
    Mesh zeroNormal = good;
    zeroNormal.normals[2] = glm::vec3(0.f);
    EXPECT_THAT(buildError(zeroNormal), HasSubstr("Mesh.normals[2]"));
    Mesh badIndex = good;
    badIndex.indices[4] = 99;
    EXPECT_THAT(buildError(badIndex), HasSubstr("Mesh.indices[4] = 99"));
    Mesh nanPosition = good;
    nanPosition.positions[1].x = std::nanf("");
    EXPECT_THAT(buildError(nanPosition), HasSubstr("Mesh.positions[1]"));
}

} // namespace
} // namespace qgi
