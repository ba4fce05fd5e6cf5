// The Monte Carlo irradiance reference against closed forms. Punctual and directional light at
// a point is exact (no sampling), so those cases allow only float rounding; sampled cases allow
// 4 standard errors, the estimate's own spread (a false alarm rate of 6e-5 per channel).

#include "test_detp_world.h"
#include "tests/reference/IrradianceReference.h"

#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace qgi::reference {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = glm::pi<double>();
constexpr double kSigmas = 4.0;
/// Relative error of the exact (unsampled) light paths: a few dozen float operations with
/// 6e-8 rounding each.
constexpr double kFloatTolerance = 1e-5;
const glm::vec3 kUp(0.f, 1.f, 0.f);
const glm::vec3 kBlack(0.f);

/// A quad centred on `center` with half-axes u and v, facing along cross(u, v): the corners
/// c - u - v, c + u - v, c + u + v, c - u + v run counter-clockwise seen from that side.
Mesh quad(const glm::vec3& center, const glm::vec3& u, const glm::vec3& v) {
    Mesh mesh;
    mesh.positions = {center - u - v, center + u - v, center + u + v, center - u + v};
    mesh.normals.assign(4, glm::normalize(glm::cross(u, v)));
    mesh.indices = {0, 1, 2, 0, 2, 3};
    return mesh;
}

/// A horizontal quad over [x0, x1] x [z0, z1] at height y, facing up (or down).
Mesh horizontal(float x0, float x1, float z0, float z1, float y, bool facingDown = false) {
    const glm::vec3 center(0.5f * (x0 + x1), y, 0.5f * (z0 + z1));
    const glm::vec3 u(0.f, 0.f, 0.5f * (z1 - z0)), v(0.5f * (x1 - x0), 0.f, 0.f);
    return facingDown ? quad(center, v, u) : quad(center, u, v); // cross(z, x) = +y
}

Material material(const glm::vec3& albedo, const glm::vec3& emission = glm::vec3(0.f)) {
    Material m;
    m.baseColor = albedo;
    m.emission = emission;
    return m;
}

/// An object-to-world matrix at `position` whose local -Z axis points along `direction`.
glm::mat4 aimedAlong(const glm::vec3& position, const glm::vec3& direction) {
    const glm::vec3 z = -glm::normalize(direction);
    const glm::vec3 helper = std::abs(z.y) < 0.9f ? kUp : glm::vec3(1.f, 0.f, 0.f);
    const glm::vec3 x = glm::normalize(glm::cross(helper, z));
    const glm::vec3 y = glm::cross(z, x);
    return glm::mat4(glm::vec4(x, 0.f), glm::vec4(y, 0.f), glm::vec4(z, 0.f),
                     glm::vec4(position, 1.f));
}

/// A registry of hand-built meshes and lights, with its ray scene.
struct TestScene {
    Registry registry;
    RayScene rays;

    Entity addMesh(Mesh mesh, const Material& m, const glm::mat4& world = glm::mat4(1.f),
                   bool mobile = false) {
        const Entity e = test::addReceiverMesh(registry, std::move(mesh), world, mobile, "mesh");
        registry.emplace<Material>(e, m);
        return e;
    }
    template <typename Light> Entity addLight(const Light& light, const glm::mat4& world) {
        const Entity e = registry.create();
        registry.emplace<Light>(e, light);
        registry.emplace<WorldTransform>(e, world);
        return e;
    }
    void setEnvironment(const glm::vec3& radiance) {
        registry.ctx().emplaceOrReplace<SceneInfo>().environment = radiance;
    }
    std::vector<IrradianceEstimate> estimate(const std::vector<glm::vec3>& x,
                                             const std::vector<glm::vec3>& n,
                                             const ReferenceSettings& settings) {
        rays.build(registry);
        return IrradianceReference(registry, rays, settings).estimate(x, n);
    }
    IrradianceEstimate estimate(const glm::vec3& x, const glm::vec3& n,
                                const ReferenceSettings& settings) {
        rays.build(registry);
        return estimateIrradiance(registry, rays, x, n, settings);
    }
};

ReferenceSettings samples(std::uint32_t count) {
    ReferenceSettings settings;
    settings.samplesPerPoint = count;
    return settings;
}

/// Exact light: every sample is zero, so the standard error is zero, and the mean matches to
/// float rounding.
void expectExact(const IrradianceEstimate& estimate, const glm::dvec3& expected,
                 double relative = kFloatTolerance) {
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(estimate.mean[c], expected[c], relative * std::abs(expected[c]) + 1e-12)
            << "channel " << c;
        EXPECT_EQ(estimate.standardError[c], 0.0) << "channel " << c;
    }
}

/// Sampled light: within kSigmas standard errors, and precise enough (relative standard error
/// under `maxRelativeError`) that the comparison means something.
void expectWithinError(const IrradianceEstimate& estimate, const glm::dvec3& expected,
                       double maxRelativeError = 0.02) {
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(estimate.mean[c], expected[c], kSigmas * estimate.standardError[c])
            << "channel " << c << ", standard error " << estimate.standardError[c];
        EXPECT_GT(estimate.standardError[c], 0.0) << "channel " << c;
        EXPECT_LT(estimate.standardError[c], maxRelativeError * expected[c]) << "channel " << c;
    }
}

// ---- point, directional and spot lights over a black plane ------------------------------------

/// A black plane y = 0 large enough to be infinite for every point tested.
void addBlackFloor(TestScene& scene) {
    scene.addMesh(horizontal(-100.f, 100.f, -100.f, 100.f, 0.f), material(kBlack));
}

TEST(Reference, PointLightOverBlackPlaneFallsOffAsCosOverDistanceSquared) {
    TestScene scene;
    addBlackFloor(scene);
    const double h = 1.5;
    const glm::dvec3 intensity = 3.0 * glm::dvec3(1.0, 0.5, 0.25); // W/sr
    scene.addLight(PointLight{glm::vec3(1.f, 0.5f, 0.25f), 3.f},
                   glm::translate(glm::mat4(1.f), glm::vec3(0.f, float(h), 0.f)));

    const std::vector<glm::vec3> x{
        {0.f, 0.f, 0.f}, {0.5f, 0.f, 0.f}, {0.f, 0.f, -1.f}, {1.8f, 0.f, 1.4f}};
    const std::vector<IrradianceEstimate> e = scene.estimate(x, {x.size(), kUp}, samples(64));
    // At the foot: I / h^2. Off axis at distance rho: I cos / d^2 = I h / (h^2 + rho^2)^1.5.
    expectExact(e[0], intensity / (h * h));
    for (std::size_t i = 1; i < x.size(); ++i) {
        const double rho2 = double(x[i].x) * x[i].x + double(x[i].z) * x[i].z;
        expectExact(e[i], intensity * h / std::pow(h * h + rho2, 1.5));
    }
    // The same point facing down sees nothing of a light above it.
    expectExact(scene.estimate(glm::vec3(0.f), -kUp, samples(64)), glm::dvec3(0.0));
}

TEST(Reference, StandInLightsAddNoLight) {
    // LightStandIn marks a bulb that duplicates an emissive surface for the shader's direct
    // light; physically the surface is the light, so the reference ignores the bulb.
    TestScene scene;
    addBlackFloor(scene);
    const Entity bulb = scene.addLight(PointLight{glm::vec3(1.f), 3.f},
                                       glm::translate(glm::mat4(1.f), glm::vec3(0.f, 1.f, 0.f)));
    scene.registry.emplace<LightStandIn>(bulb);
    expectExact(scene.estimate(glm::vec3(0.f), kUp, samples(64)), glm::dvec3(0.0));
}

TEST(Reference, DirectionalLightGivesIrradianceTimesCosine) {
    TestScene scene;
    addBlackFloor(scene);
    const double theta = glm::radians(40.0);
    const glm::vec3 travel(float(std::sin(theta)), -float(std::cos(theta)), 0.f);
    scene.addLight(DirectionalLight{glm::vec3(1.f, 0.8f, 0.6f), 2.f},
                   aimedAlong(glm::vec3(0.f, 5.f, 0.f), travel));
    const glm::dvec3 irradiance = 2.0 * glm::dvec3(1.0, 0.8, 0.6); // W/m^2 facing the light

    expectExact(scene.estimate(glm::vec3(0.f), kUp, samples(64)), irradiance * std::cos(theta));
    // A surface facing the light receives the full irradiance; one facing away nothing.
    expectExact(scene.estimate(glm::vec3(0.f), -travel, samples(64)), irradiance);
    expectExact(scene.estimate(glm::vec3(0.f), glm::vec3(1.f, 0.f, 0.f), samples(64)),
                glm::dvec3(0.0)); // the light arrives from -x
}

TEST(Reference, SpotLightFollowsTheRenderersConeFalloff) {
    TestScene scene;
    addBlackFloor(scene);
    // The cone angles the light holds (floats).
    const double h = 1.0, inner = double(float(glm::radians(20.0))),
                 outer = double(float(glm::radians(35.0)));
    scene.addLight(SpotLight{glm::vec3(1.f), 2.f, float(inner), float(outer)},
                   aimedAlong(glm::vec3(0.f, float(h), 0.f), -kUp));

    // A floor point at angle alpha off the axis: d = h / cos alpha, so E = I cos^3 alpha / h^2
    // times the glTF falloff: 1 inside the inner cone, 0 outside the outer one, and between
    // them t^2, t = (cos alpha - cos outer) / (cos inner - cos outer).
    const std::vector<double> angles{0.0, 10.0, 24.0, 31.0, 34.0, 36.0, 50.0};
    std::vector<glm::vec3> x;
    for (double degrees : angles)
        x.push_back({float(h * std::tan(glm::radians(degrees))), 0.f, 0.f});
    const std::vector<IrradianceEstimate> e = scene.estimate(x, {x.size(), kUp}, samples(64));
    const double cosInner = std::cos(inner), cosOuter = std::cos(outer);
    const double width = cosInner - cosOuter;
    for (std::size_t i = 0; i < angles.size(); ++i) {
        const double alpha = std::atan2(double(x[i].x), h); // the angle of the float point
        const double cosAlpha = std::cos(alpha);
        const double t = std::clamp((cosAlpha - cosOuter) / width, 0.0, 1.0);
        const double expected = 2.0 * std::pow(cosAlpha, 3.0) / (h * h) * t * t;
        // The reference's t in float (u = 2^-24), each rounding with its share of the error dt:
        // - cos inner, cos outer within an ulp (u, both in [0.5, 1)): at most u / width;
        //   their difference is exact (Sterbenz);
        // - scale = 1 / width, rounded: u t;
        // - cos alpha from the float direction to the light, within 3u relative (squared
        //   distance, root, division): 3u cos alpha / width;
        // - cos alpha * scale, rounded: u cos alpha / width; offset = -cos outer * scale,
        //   rounded: u cos outer / width; their sum, rounded: u t (fused: less).
        // So dt = 2u t + (4 cos alpha + cos outer + 1) u / width: the terms of size 1 / width ~ 8
        // cancel to t, so their roundings are not relative to t. t^2 is within 2 dt / t +
        // (dt / t)^2 relative. A clamped t (0 or 1, here far from the cone's edges) is exact.
        // The rest of the light path is exact to kFloatTolerance.
        double tolerance = kFloatTolerance;
        if (t > 0.0 && t < 1.0) {
            const double dt = 0x1p-24 * (2.0 * t + (4.0 * cosAlpha + cosOuter + 1.0) / width);
            tolerance += 2.0 * dt / t + (dt / t) * (dt / t);
        }
        SCOPED_TRACE(angles[i]);
        expectExact(e[i], glm::dvec3(expected), tolerance);
    }
}

TEST(Reference, OccluderCastsAHardShadow) {
    TestScene scene;
    addBlackFloor(scene);
    const double h = 2.0;
    scene.addLight(PointLight{glm::vec3(1.f), 4.f},
                   glm::translate(glm::mat4(1.f), glm::vec3(0.f, float(h), 0.f)));
    scene.addLight(DirectionalLight{glm::vec3(1.f), 1.f}, aimedAlong(glm::vec3(0.f), -kUp));
    // A black 0.2 m square at half height over the origin: its shadow of the point light has a
    // 0.2 m half width on the floor, of the directional light exactly the square's 0.1 m.
    scene.addMesh(horizontal(-0.1f, 0.1f, -0.1f, 0.1f, 1.f), material(kBlack));

    const std::vector<glm::vec3> x{{0.f, 0.f, 0.f}, {0.15f, 0.f, 0.f}, {0.5f, 0.f, 0.5f}};
    const std::vector<IrradianceEstimate> e = scene.estimate(x, {x.size(), kUp}, samples(64));
    expectExact(e[0], glm::dvec3(0.0));
    // (0.15, 0): outside the square, inside the point light's 0.2 m shadow.
    expectExact(e[1], glm::dvec3(1.0));
    const double rho2 = 0.5;
    expectExact(e[2], glm::dvec3(4.0 * h / std::pow(h * h + rho2, 1.5) + 1.0));
}

// ---- a rectangular Lambertian emitter ---------------------------------------------------------

/// Form factor from a small patch facing up to a parallel rectangle at height h with one
/// corner straight above it, extending a * h and b * h (the standard closed form). It is odd
/// in a and in b, so rectangles anywhere combine corner rectangles with signs.
double cornerFormFactor(double a, double b) {
    const double sa = std::sqrt(1.0 + a * a), sb = std::sqrt(1.0 + b * b);
    return (a / sa * std::atan(b / sa) + b / sb * std::atan(a / sb)) / (2.0 * kPi);
}

/// Form factor from a patch at the origin facing up to the rectangle [x0, x1] x [z0, z1] at
/// height h.
double rectangleFormFactor(double x0, double x1, double z0, double z1, double h) {
    const auto f = [h](double x, double z) { return cornerFormFactor(x / h, z / h); };
    return f(x1, z1) - f(x0, z1) - f(x1, z0) + f(x0, z0);
}

TEST(Reference, FormFactorClosedFormIsSane) {
    // A huge rectangle covers the hemisphere; a quadrant of it a quarter.
    EXPECT_NEAR(rectangleFormFactor(-1e6, 1e6, -1e6, 1e6, 1.0), 1.0, 1e-5);
    EXPECT_NEAR(rectangleFormFactor(0.0, 1e6, 0.0, 1e6, 1.0), 0.25, 1e-5);
    // A small patch of area A at height h straight above: F ~ A / (pi h^2).
    EXPECT_NEAR(rectangleFormFactor(-1e-3, 1e-3, -1e-3, 1e-3, 1.0), 4e-6 / kPi, 1e-10);
}

TEST(Reference, RectangularEmitterMatchesTheFormFactor) {
    const float h = 0.5f;
    const float x0 = -0.2f, x1 = 0.4f, z0 = -0.15f, z1 = 0.25f; // 0.6 x 0.4 m
    const glm::vec3 radiance(2.f, 1.f, 0.5f);                   // W/(m^2 sr)
    const glm::vec3 center(0.5f * (x0 + x1), h, 0.5f * (z0 + z1));

    // The same downward-facing emitter three ways: static; mobile, as an upward object-space
    // quad turned over by its pose; static under a mirroring matrix, which reverses the
    // winding of an upward quad while the object's front side turns down with the mirror.
    enum class Build { Static, MobileTurned, StaticMirrored };
    for (Build build : {Build::Static, Build::MobileTurned, Build::StaticMirrored}) {
        SCOPED_TRACE(int(build));
        TestScene scene;
        const Material emitter = material(kBlack, radiance);
        if (build == Build::Static) {
            scene.addMesh(horizontal(x0, x1, z0, z1, h, true), emitter);
        } else if (build == Build::MobileTurned) {
            const glm::mat4 pose = glm::rotate(glm::translate(glm::mat4(1.f), center),
                                               glm::pi<float>(), glm::vec3(1.f, 0.f, 0.f));
            const float hx = 0.5f * (x1 - x0), hz = 0.5f * (z1 - z0);
            scene.addMesh(horizontal(-hx, hx, -hz, hz, 0.f), emitter, pose, true);
        } else {
            const glm::mat4 mirror = glm::scale(glm::mat4(1.f), glm::vec3(1.f, -1.f, 1.f));
            scene.addMesh(horizontal(x0, x1, z0, z1, -h), emitter, mirror);
        }
        // Under the emitter, and off to the side of it (a signed sum of corner rectangles).
        const std::vector<glm::vec3> x{{0.f, 0.f, 0.f}, {-0.7f, 0.f, 0.4f}};
        const std::vector<IrradianceEstimate> e = scene.estimate(x, {2, kUp}, samples(1 << 14));
        for (std::size_t i = 0; i < x.size(); ++i) {
            const double f =
                rectangleFormFactor(x0 - x[i].x, x1 - x[i].x, z0 - x[i].z, z1 - x[i].z, h);
            // A Lambertian emitter of radiance L: E = pi L F.
            expectWithinError(e[i], kPi * glm::dvec3(radiance) * f);
        }
    }
}

TEST(Reference, EmittersShineFromTheirFrontSideOnly) {
    TestScene scene;
    scene.addMesh(horizontal(-0.3f, 0.3f, -0.3f, 0.3f, 0.5f), material(kBlack, glm::vec3(1.f)));
    expectExact(scene.estimate(glm::vec3(0.f), kUp, samples(1024)), glm::dvec3(0.0));
}

TEST(Reference, BlockedEmitterGivesNoLight) {
    TestScene scene;
    scene.addMesh(horizontal(-0.3f, 0.3f, -0.3f, 0.3f, 0.5f, true),
                  material(kBlack, glm::vec3(1.f)));
    // A black square between the point and the whole emitter (it spans the emitter's cone).
    scene.addMesh(horizontal(-0.2f, 0.2f, -0.2f, 0.2f, 0.25f), material(kBlack));
    expectExact(scene.estimate(glm::vec3(0.f), kUp, samples(1024)), glm::dvec3(0.0));
}

// ---- the environment, and the standard error ---------------------------------------------------

TEST(Reference, StandardErrorIsTheBinomialOneAndShrinksAsOneOverRootN) {
    // Sky radiance L over a black square: a sample is pi L when its ray escapes, probability
    // p = 1 - F, and 0 otherwise. The mean is pi L p and the standard error exactly
    // pi L sqrt(p^ (1 - p^) / (N - 1)) for the observed fraction p^.
    TestScene scene;
    const double sky = 1.5;
    scene.setEnvironment(glm::vec3(float(sky)));
    const float h = 0.5f;
    scene.addMesh(horizontal(-0.3f, 0.5f, -0.4f, 0.4f, h, true), material(kBlack));
    const double p = 1.0 - rectangleFormFactor(-0.3, 0.5, -0.4, 0.4, h);
    ASSERT_GT(p, 0.2);
    ASSERT_LT(p, 0.8);

    for (std::uint32_t n : {1024u, 16384u}) {
        SCOPED_TRACE(n);
        const IrradianceEstimate e = scene.estimate(glm::vec3(0.f), kUp, samples(n));
        const double trueError = kPi * sky * std::sqrt(p * (1.0 - p) / n);
        const double observed = e.mean.x / (kPi * sky);
        EXPECT_NEAR(e.mean.x, kPi * sky * p, kSigmas * trueError);
        EXPECT_NEAR(e.standardError.x,
                    kPi * sky * std::sqrt(observed * (1.0 - observed) / (n - 1.0)),
                    1e-6 * e.standardError.x); // float rounding of the sample value pi L
        // So the error falls as 1 / sqrt(N): with p^ within 4 sigma of p, p^ (1 - p^) differs
        // from p (1 - p) by at most |1 - 2p| 4 sigma_p + (4 sigma_p)^2, relatively half that in
        // the standard error.
        const double sigmaP = kSigmas * std::sqrt(p * (1.0 - p) / n);
        const double relative =
            0.5 * (std::abs(1.0 - 2.0 * p) * sigmaP + sigmaP * sigmaP) / (p * (1.0 - p));
        EXPECT_NEAR(e.standardError.x, trueError, (relative + 1.0 / n) * trueError);
    }

    ReferenceSettings noSky = samples(256);
    noSky.includeEnvironment = false;
    expectExact(scene.estimate(glm::vec3(0.f), kUp, noSky), glm::dvec3(0.0));
}

// ---- the white furnace --------------------------------------------------------------------------

/// A closed cube of side 1 m around the origin, every face facing in, with albedo rho and
/// emitted radiance le.
void addFurnace(TestScene& scene, const glm::vec3& rho, const glm::vec3& le) {
    const glm::vec3 ex(0.5f, 0.f, 0.f), ey(0.f, 0.5f, 0.f), ez(0.f, 0.f, 0.5f);
    const Material m = material(rho, le);
    // Each face's half-axes are ordered so cross(u, v) points into the cube.
    scene.addMesh(quad(-ey, ez, ex), m); // floor, facing +y
    scene.addMesh(quad(ey, ex, ez), m);  // ceiling, facing -y
    scene.addMesh(quad(-ex, ey, ez), m); // facing +x
    scene.addMesh(quad(ex, ez, ey), m);  // facing -x
    scene.addMesh(quad(-ez, ex, ey), m); // facing +z
    scene.addMesh(quad(ez, ey, ex), m);  // facing -z
}

const glm::vec3 kFurnaceAlbedo(0.3f, 0.5f, 0.7f);
const glm::vec3 kFurnaceEmission(0.8f);

/// Points anywhere in the furnace, with any orientation: the centre, on the floor, in a
/// corner, on a wall by an edge.
const std::vector<glm::vec3> kFurnacePoints{
    {0.f, 0.f, 0.f}, {0.1f, -0.5f, -0.2f}, {-0.49f, -0.49f, -0.49f}, {0.5f, 0.3f, 0.499f}};
const std::vector<glm::vec3> kFurnaceNormals{
    {1.f, 2.f, 3.f}, {0.f, 1.f, 0.f}, {1.f, 1.f, 1.f}, {-1.f, 0.f, 0.f}};

/// Light arriving after at most `maxBounces` reflections, from the `first`-th on: every
/// direction sees radiance Le plus what the walls reflect, so
/// E = pi Le sum_{k = first}^{maxBounces} rho^k.
glm::dvec3 furnaceIrradiance(std::uint32_t first, std::uint32_t maxBounces) {
    const glm::dvec3 rho(kFurnaceAlbedo);
    const glm::dvec3 sum =
        (glm::pow(rho, glm::dvec3(first)) - glm::pow(rho, glm::dvec3(maxBounces + 1.0))) /
        (1.0 - rho);
    return kPi * glm::dvec3(kFurnaceEmission) * sum;
}

TEST(Reference, WhiteFurnaceIsPiLeOverOneMinusAlbedo) {
    TestScene scene;
    addFurnace(scene, kFurnaceAlbedo, kFurnaceEmission);
    const ReferenceSettings settings = samples(1 << 13);
    const std::vector<IrradianceEstimate> e =
        scene.estimate(kFurnacePoints, kFurnaceNormals, settings);
    for (std::size_t i = 0; i < e.size(); ++i) {
        SCOPED_TRACE(i);
        expectWithinError(e[i], furnaceIrradiance(0, settings.maxBounces));
    }
}

TEST(Reference, WithoutDirectLightOnlyReflectedLightRemains) {
    ReferenceSettings settings = samples(1 << 13);
    settings.includeDirect = false;
    TestScene furnace;
    addFurnace(furnace, kFurnaceAlbedo, kFurnaceEmission);
    const std::vector<IrradianceEstimate> e =
        furnace.estimate(kFurnacePoints, kFurnaceNormals, settings);
    for (std::size_t i = 0; i < e.size(); ++i) {
        SCOPED_TRACE(i);
        expectWithinError(e[i], furnaceIrradiance(1, settings.maxBounces));
    }
    // A point light over a black plane gives direct light only.
    TestScene plane;
    addBlackFloor(plane);
    plane.addLight(PointLight{}, glm::translate(glm::mat4(1.f), kUp));
    expectExact(plane.estimate(glm::vec3(0.f), kUp, settings), glm::dvec3(0.0));
}

TEST(Reference, BounceCapTruncatesTheSeries) {
    TestScene scene;
    addFurnace(scene, kFurnaceAlbedo, kFurnaceEmission);
    ReferenceSettings settings = samples(1 << 13);
    settings.maxBounces = 2; // roulette starts later, so this is plain truncation
    const std::vector<IrradianceEstimate> e =
        scene.estimate(kFurnacePoints, kFurnaceNormals, settings);
    for (std::size_t i = 0; i < e.size(); ++i) {
        SCOPED_TRACE(i);
        expectWithinError(e[i], furnaceIrradiance(0, 2));
    }
}

// ---- one reflection off a Lambertian floor ---------------------------------------------------
//
// The white furnace checks reflected light only where radiance is uniform, which a wrong
// bounce-direction density or weight can still get right. Here the reflected radiance varies
// over the floor, and the answers come from a 1D quadrature and from a closed form.

/// Composite Simpson's rule for f over [a, b] with n (even) intervals.
template <typename F> double simpson(F&& f, double a, double b, int n) {
    const double step = (b - a) / n;
    double sum = f(a) + f(b);
    for (int i = 1; i < n; ++i)
        sum += (i % 2 ? 4.0 : 2.0) * f(a + i * step);
    return sum * step / 3.0;
}

TEST(Reference, PointLightReflectedByAFloorMatchesQuadrature) {
    // A point light of intensity I at height h over a Lambertian floor of albedo rho; a point
    // at height H < h on the light's axis faces down, so it sees only the floor. At distance s
    // from the axis the floor receives I h / (h^2 + s^2)^1.5 and shows radiance rho / pi times
    // that; the point receives radiance L from dA with cos cos / d^2 = H^2 / (H^2 + s^2)^2, so
    //   E = 2 rho I h H^2 int_0^inf s ds / ((h^2 + s^2)^1.5 (H^2 + s^2)^2),
    // integrated here over s = H tan(phi). (The floor ends at 100 m: the integrand falls as
    // s^-6, so the rest is below 1e-10 of the value.)
    const glm::vec3 rho(0.8f, 0.5f, 0.2f);
    const double h = 1.2, intensity = 2.0;
    for (const double height : {0.3, 0.9}) {
        SCOPED_TRACE(height);
        TestScene scene;
        scene.addMesh(horizontal(-100.f, 100.f, -100.f, 100.f, 0.f), material(rho));
        scene.addLight(PointLight{glm::vec3(1.f), float(intensity)},
                       glm::translate(glm::mat4(1.f), glm::vec3(0.f, float(h), 0.f)));
        const double hh = height * height;
        const double integral = simpson(
            [&](double phi) {
                const double s = height * std::tan(phi);
                const double ds = height / (std::cos(phi) * std::cos(phi));
                return s * ds / (std::pow(h * h + s * s, 1.5) * (hh + s * s) * (hh + s * s));
            },
            0.0, std::atan(100.0 / height), 20000);
        const glm::dvec3 expected = 2.0 * glm::dvec3(rho) * intensity * h * hh * integral;
        const glm::vec3 x(0.f, float(height), 0.f);
        // Everything it receives has reflected once, so it is the same without direct light.
        for (const bool direct : {true, false}) {
            ReferenceSettings settings = samples(1 << 14);
            settings.includeDirect = direct;
            expectWithinError(scene.estimate(x, -kUp, settings), expected);
        }
    }
}

TEST(Reference, EmitterReflectedByAFloorIsPiRhoLe) {
    // A black ceiling emitting Le downwards over a floor of albedo rho, both 200 m wide and
    // 1 m apart: the floor receives pi Le and shows radiance rho Le everywhere near the
    // centre, so a point between them facing down receives pi rho Le (and facing up, the
    // ceiling's pi Le directly). The finite size takes about (1 m / 100 m)^2 = 1e-4 off both.
    const glm::vec3 rho(0.8f, 0.5f, 0.2f), le(1.5f, 1.f, 0.5f);
    TestScene scene;
    scene.addMesh(horizontal(-100.f, 100.f, -100.f, 100.f, 0.f), material(rho));
    scene.addMesh(horizontal(-100.f, 100.f, -100.f, 100.f, 1.f, true), material(kBlack, le));
    const std::vector<glm::vec3> x{{0.f, 0.5f, 0.f}, {0.3f, 0.1f, -0.2f}};
    for (const bool direct : {true, false}) {
        SCOPED_TRACE(direct);
        ReferenceSettings settings = samples(1 << 14);
        settings.includeDirect = direct;
        const std::vector<IrradianceEstimate> down = scene.estimate(x, {2, -kUp}, settings);
        for (const IrradianceEstimate& e : down)
            expectWithinError(e, kPi * glm::dvec3(rho) * glm::dvec3(le));
        // Facing up: the ceiling directly, and nothing that reflected (the ceiling is black).
        const std::vector<IrradianceEstimate> up = scene.estimate(x, {2, kUp}, settings);
        for (const IrradianceEstimate& e : up) {
            if (direct)
                expectWithinError(e, kPi * glm::dvec3(le));
            else
                expectExact(e, glm::dvec3(0.0));
        }
    }
}

// ---- determinism ------------------------------------------------------------------------------

TEST(Reference, SameSeedGivesIdenticalResultsOnAnyThreadCount) {
    TestScene scene;
    addFurnace(scene, kFurnaceAlbedo, kFurnaceEmission);
    scene.rays.build(scene.registry);
    const ReferenceSettings settings = samples(1000); // not a multiple of the block size
    const IrradianceReference reference(scene.registry, scene.rays, settings);
    const std::vector<IrradianceEstimate> first =
        reference.estimate(kFurnacePoints, kFurnaceNormals);
    std::vector<IrradianceEstimate> serial;
    tbb::task_arena(1).execute(
        [&] { serial = reference.estimate(kFurnacePoints, kFurnaceNormals); });
    for (std::size_t i = 0; i < first.size(); ++i) {
        EXPECT_EQ(first[i].mean, serial[i].mean);
        EXPECT_EQ(first[i].standardError, serial[i].standardError);
    }
    // A single point uses the streams of point 0.
    const IrradianceEstimate single = reference.estimate(kFurnacePoints[0], kFurnaceNormals[0]);
    EXPECT_EQ(single.mean, first[0].mean);

    // Another seed draws other samples of the same distribution.
    ReferenceSettings other = settings;
    other.seed = 2;
    const std::vector<IrradianceEstimate> reseeded =
        IrradianceReference(scene.registry, scene.rays, other)
            .estimate(kFurnacePoints, kFurnaceNormals);
    for (std::size_t i = 0; i < first.size(); ++i) {
        EXPECT_NE(first[i].mean, reseeded[i].mean);
        for (int c = 0; c < 3; ++c) {
            const double spread =
                std::hypot(first[i].standardError[c], reseeded[i].standardError[c]);
            EXPECT_NEAR(first[i].mean[c], reseeded[i].mean[c], kSigmas * spread);
        }
    }
}

// ---- bad input --------------------------------------------------------------------------------

template <typename Fn> std::string errorOf(Fn&& fn) {
    try {
        fn();
    } catch (const Error& error) {
        return error.what();
    }
    return "no error";
}

TEST(Reference, BadInputIsReportedByName) {
    TestScene scene;
    addBlackFloor(scene);
    scene.rays.build(scene.registry);
    EXPECT_THAT(errorOf([&] { IrradianceReference(scene.registry, scene.rays, samples(1)); }),
                HasSubstr("samplesPerPoint"));
    ReferenceSettings deep;
    deep.maxBounces = 1u << 20;
    EXPECT_THAT(errorOf([&] { IrradianceReference(scene.registry, scene.rays, deep); }),
                HasSubstr("maxBounces"));

    const IrradianceReference reference(scene.registry, scene.rays, samples(16));
    const float nan = std::numeric_limits<float>::quiet_NaN();
    EXPECT_THAT(errorOf([&] { reference.estimate(glm::vec3(nan), kUp); }),
                HasSubstr("point 0 is not finite"));
    EXPECT_THAT(errorOf([&] { reference.estimate(glm::vec3(0.f), glm::vec3(0.f)); }),
                HasSubstr("normal 0"));
    const std::vector<glm::vec3> two(2, kUp), one(1, kUp);
    EXPECT_THAT(errorOf([&] { reference.estimate(two, one); }), HasSubstr("2 points but 1"));

    const auto failure = [](auto&& edit) {
        TestScene bad;
        const Entity mesh = bad.addMesh(horizontal(-1.f, 1.f, -1.f, 1.f, 0.f), material(kBlack));
        edit(bad, mesh);
        bad.rays.build(bad.registry);
        return errorOf([&] { IrradianceReference(bad.registry, bad.rays, samples(16)); });
    };
    EXPECT_THAT(
        failure([](TestScene& s, Entity e) { s.registry.get<Material>(e).baseColor.y = 1.5f; }),
        HasSubstr("Material.baseColor"));
    EXPECT_THAT(
        failure([](TestScene& s, Entity e) { s.registry.get<Material>(e).emission.x = -1.f; }),
        HasSubstr("Material.emission"));
    EXPECT_THAT(failure([](TestScene& s, Entity e) { s.registry.remove<Material>(e); }),
                HasSubstr("has no Material"));
    EXPECT_THAT(failure([](TestScene& s, Entity) {
                    s.addLight(SpotLight{glm::vec3(1.f), 1.f, 0.6f, 0.5f}, glm::mat4(1.f));
                }),
                HasSubstr("SpotLight.innerConeAngle"));
    EXPECT_THAT(
        failure([](TestScene& s, Entity) { s.registry.emplace<PointLight>(s.registry.create()); }),
        HasSubstr("has no WorldTransform"));
}

} // namespace
} // namespace qgi::reference
