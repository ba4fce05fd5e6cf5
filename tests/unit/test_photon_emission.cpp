// Photon emission: the distribution of every light kind against its closed form, and the
// photons' share of power among lights.
#include "systems/photon_update/PhotonEmitter.h"
#include "systems/photon_update/PhotonSampling.h"

#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/SpotLight.h"
#include "runtime/core/Log.h"
#include "test_photon_scenes.h"

#include <gtest/gtest.h>

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtx/quaternion.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <vector>

namespace qgi {
namespace {

constexpr std::uint64_t kSeed = 77;
constexpr double kPi = 3.14159265358979323846;

/// One-sample Kolmogorov-Smirnov distance between the samples and a CDF.
double ksDistance(std::vector<double> samples, const std::function<double(double)>& cdf) {
    std::sort(samples.begin(), samples.end());
    const double n = double(samples.size());
    double d = 0.0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const double f = cdf(samples[i]);
        d = std::max({d, std::abs(f - double(i) / n), std::abs(f - double(i + 1) / n)});
    }
    return d;
}

/// The KS critical distance at significance 0.001 for n samples (asymptotic: 1.95 / sqrt n).
double ksCritical(std::size_t n) {
    return 1.95 / std::sqrt(double(n));
}

PhotonEmitter prepared(const Registry& registry, PhotonEmitter emitter, std::uint32_t photons,
                       const Aabb& box = {glm::vec3(-1.f), glm::vec3(1.f)}) {
    prepareEmitter(registry, box, emitter);
    emitter.firstPhoton = 0;
    emitter.photonCount = photons;
    return emitter;
}

/// A world matrix whose -Z axis points along `direction`, placed at `at`.
glm::mat4 aimedAlong(const glm::vec3& direction, const glm::vec3& at) {
    const glm::quat q = glm::rotation(glm::vec3(0.f, 0.f, -1.f), glm::normalize(direction));
    return test::translation(at) * glm::mat4_cast(q);
}

/// Two unit vectors orthogonal to unit n and to each other (the test's own frame).
std::pair<glm::dvec3, glm::dvec3> tangents(const glm::dvec3& n) {
    const glm::dvec3 helper = std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    const glm::dvec3 t = glm::normalize(glm::cross(helper, n));
    return {t, glm::cross(n, t)};
}

TEST(PhotonEmission, PointLightIsUniformOnTheSphere) {
    Registry registry;
    PhotonEmitter light;
    light.kind = EmitterKind::Point;
    light.world = test::translation({1.f, 2.f, 3.f});
    light.radiant = {1.f, 2.f, 3.f};
    constexpr std::uint32_t n = 20'000;
    light = prepared(registry, light, n);
    EXPECT_NEAR(light.power.y, 4.0 * kPi * 2.0, 1e-5);

    std::vector<double> cosTheta, phi;
    glm::dvec3 secondMoments(0.0);
    for (std::uint32_t i = 0; i < n; ++i) {
        const PhotonHead h = emitPhoton(light, i, kSeed);
        ASSERT_EQ(h.origin, glm::vec3(1.f, 2.f, 3.f));
        ASSERT_NEAR(glm::length(h.direction), 1.f, 1e-5f);
        ASSERT_EQ(h.power, light.power / float(n));
        ASSERT_EQ(h.photon, i);
        cosTheta.push_back(h.direction.z);
        phi.push_back(std::atan2(double(h.direction.y), double(h.direction.x)));
        secondMoments += glm::dvec3(h.direction) * glm::dvec3(h.direction);
    }
    EXPECT_LT(ksDistance(cosTheta, [](double c) { return (c + 1.0) / 2.0; }), ksCritical(n));
    EXPECT_LT(ksDistance(phi, [](double p) { return (p + kPi) / (2.0 * kPi); }), ksCritical(n));
    // E[x^2] = 1/3 per axis; x^2 has variance 1/5 - 1/9 = 4/45.
    for (int a = 0; a < 3; ++a)
        EXPECT_NEAR(secondMoments[a] / n, 1.0 / 3.0, 4.5 * std::sqrt(4.0 / 45.0 / n));
}

// Quasi-random emission: the photons of a light fill its directions far more evenly than
// independent samples could. For boxes in (cos theta, azimuth), whose share of the sphere is p,
// N independent photons put Np +- sqrt(Np(1 - p)) in each; the emitter's Halton points must
// miss by less than half that in every one of 24 boxes. Independent photons would pass all 24
// about once in 10^10 runs (P(|Z| < 0.5) = 0.38 each), and the same boxes filled by a
// pseudo-random generator are checked to fail.
TEST(PhotonEmission, PointLightPhotonsAreQuasiRandomNotIndependent) {
    Registry registry;
    PhotonEmitter light;
    light.kind = EmitterKind::Point;
    light.radiant = glm::vec3(1.f);
    constexpr std::uint32_t n = 20'000;
    light = prepared(registry, light, n);
    std::vector<glm::vec3> emitted, independent;
    std::mt19937 rng(kSeed);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    for (std::uint32_t i = 0; i < n; ++i) {
        emitted.push_back(emitPhoton(light, i, kSeed).direction);
        const float u1 = unit(rng);
        const float u2 = unit(rng); // (the order of a call's arguments is unspecified)
        independent.push_back(photon::sampleSphere(u1, u2));
    }
    struct Box {
        double z0, z1, phi0, phi1;
    };
    std::vector<Box> boxes;
    std::mt19937 pick(5);
    std::uniform_real_distribution<double> any(0.0, 1.0);
    while (boxes.size() < 24) {
        const double z0 = -1.0 + 2.0 * any(pick), z1 = -1.0 + 2.0 * any(pick);
        const double phi0 = kPi * (2.0 * any(pick) - 1.0), phi1 = kPi * (2.0 * any(pick) - 1.0);
        if (z1 - z0 > 0.2 && phi1 - phi0 > 0.6) boxes.push_back({z0, z1, phi0, phi1});
    }
    const auto worstDeviation = [&](const std::vector<glm::vec3>& directions) {
        double worst = 0.0;
        for (const Box& b : boxes) {
            const double p = (b.z1 - b.z0) / 2.0 * (b.phi1 - b.phi0) / (2.0 * kPi);
            std::size_t inside = 0;
            for (const glm::vec3& d : directions) {
                const double phi = std::atan2(double(d.y), double(d.x));
                inside += d.z >= b.z0 && d.z < b.z1 && phi >= b.phi0 && phi < b.phi1 ? 1 : 0;
            }
            worst =
                std::max(worst, std::abs(double(inside) - n * p) / std::sqrt(n * p * (1.0 - p)));
        }
        return worst;
    };
    EXPECT_LT(worstDeviation(emitted), 0.5);
    EXPECT_GT(worstDeviation(independent), 0.5) << "the test cannot tell the two apart";
}

/// The renderer's spot falloff (shaders/common/lighting.glsl), written out again.
double rendererFalloff(double c, double cosInner, double cosOuter) {
    const double t = std::clamp((c - cosOuter) / std::max(1e-3, cosInner - cosOuter), 0.0, 1.0);
    return t * t;
}

TEST(PhotonEmission, SpotFillsATrueConeDistributedAsTheRenderersFalloff) {
    Registry registry;
    const double inner = 10.0 * kPi / 180.0, outer = 30.0 * kPi / 180.0;
    const glm::dvec3 axis = glm::normalize(glm::dvec3(0.3, -1.0, 0.4));
    PhotonEmitter spot;
    spot.kind = EmitterKind::Spot;
    spot.world = aimedAlong(glm::vec3(axis), {0.f, 3.f, 0.f});
    spot.radiant = {5.f, 2.5f, 1.25f};
    spot.innerAngle = float(inner);
    spot.outerAngle = float(outer);
    constexpr std::uint32_t n = 20'000;
    spot = prepared(registry, spot, n);

    // Power and CDF of cos(angle) by numerical integration of the renderer's falloff.
    const double ci = std::cos(double(spot.innerAngle)), co = std::cos(double(spot.outerAngle));
    constexpr int kSteps = 200'000;
    std::vector<double> cumulative(kSteps + 1, 0.0);
    const double dc = (1.0 - co) / kSteps;
    for (int i = 0; i < kSteps; ++i) {
        const double c = co + (i + 0.5) * dc;
        cumulative[i + 1] = cumulative[i] + rendererFalloff(c, ci, co) * dc;
    }
    const double integral = cumulative.back();
    EXPECT_NEAR(spot.power.x, 5.0 * 2.0 * kPi * integral, 1e-4 * spot.power.x);
    const auto cdf = [&](double c) {
        const double x = std::clamp((c - co) / dc, 0.0, double(kSteps));
        const std::size_t i = std::min(std::size_t(x), std::size_t(kSteps - 1));
        return (cumulative[i] + (x - double(i)) * (cumulative[i + 1] - cumulative[i])) / integral;
    };

    const auto [t, b] = tangents(axis);
    std::vector<double> cosines, azimuths;
    for (std::uint32_t i = 0; i < n; ++i) {
        const glm::dvec3 d(emitPhoton(spot, i, kSeed).direction);
        const double c = glm::dot(d, axis);
        ASSERT_GE(c, co - 1e-6) << "photon " << i << " leaves the cone";
        cosines.push_back(c);
        azimuths.push_back(std::atan2(glm::dot(d, b), glm::dot(d, t)));
    }
    EXPECT_LT(ksDistance(cosines, cdf), ksCritical(n));
    // A uniform azimuth over the whole circle: seed 004's misprinted wedge would fail this.
    EXPECT_LT(ksDistance(azimuths, [](double p) { return (p + kPi) / (2.0 * kPi); }),
              ksCritical(n));
}

TEST(PhotonEmission, DirectionalLightCoversTheSceneBoxWithItsIrradiance) {
    Registry registry;
    const Aabb box{{-1.f, -2.f, -3.f}, {2.f, 1.f, 0.5f}};
    const glm::vec3 axis = glm::normalize(glm::vec3(-0.3f, -1.f, 0.2f));
    PhotonEmitter sun;
    sun.kind = EmitterKind::Directional;
    sun.world = aimedAlong(axis, {0.f, 30.f, 0.f});
    sun.radiant = glm::vec3(3.f);
    constexpr std::uint32_t n = 40'000;
    sun = prepared(registry, sun, n, box);
    const glm::vec3 u = sun.footprintU, v = sun.footprintV;
    EXPECT_NEAR(sun.power.x, 3.f * glm::length(u) * glm::length(v), 1e-3f);
    EXPECT_NEAR(glm::dot(u, axis), 0.f, 1e-4f);
    EXPECT_NEAR(glm::dot(v, axis), 0.f, 1e-4f);
    EXPECT_NEAR(glm::dot(u, v), 0.f, 1e-3f);

    // Every point of the box lies in the beam: traced back, it meets the rectangle.
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    float nearestCorner = std::numeric_limits<float>::max();
    for (int i = 0; i < 8; ++i)
        nearestCorner = std::min(nearestCorner, glm::dot(glm::vec3(i & 1 ? box.max.x : box.min.x,
                                                                   i & 2 ? box.max.y : box.min.y,
                                                                   i & 4 ? box.max.z : box.min.z),
                                                         axis));
    for (int i = 0; i < 2'000; ++i) {
        const glm::vec3 q = box.min + glm::vec3(unit(rng), unit(rng), unit(rng)) * box.extent();
        const glm::vec3 onPlane = q - glm::dot(q - sun.footprintCorner, axis) * axis;
        const glm::vec3 rel = onPlane - sun.footprintCorner;
        EXPECT_GE(glm::dot(rel, u) / glm::dot(u, u), -1e-5f);
        EXPECT_LE(glm::dot(rel, u) / glm::dot(u, u), 1.f + 1e-5f);
        EXPECT_GE(glm::dot(rel, v) / glm::dot(v, v), -1e-5f);
        EXPECT_LE(glm::dot(rel, v) / glm::dot(v, v), 1.f + 1e-5f);
    }
    // Photons start in front of the box and travel along the light, and a window of area a
    // across the beam inside the box receives E a. The origins are a Halton set over the
    // footprint shifted (mod 1) by an offset drawn from the seed, so each origin is uniform
    // over the footprint: every seed's flux through the window is unbiased, and seeds give
    // independent estimates. The set is far more even than independent photons (its spread
    // over seeds is about 8 times below the binomial one), so that spread judges the mean over
    // kSeeds seeds: within the two-sided 1e-3 quantile of Student's t with 15 degrees of
    // freedom times its standard error, plus the power's float rounding (the product of two
    // lengths and the radiance, within 8 u).
    const glm::vec3 centre = box.center();
    const auto [t, b] = tangents(glm::dvec3(axis));
    const float side = 0.8f;
    constexpr int kSeeds = 16;
    constexpr double kStudentT = 4.073;
    std::vector<double> flux;
    for (int s = 0; s < kSeeds; ++s) {
        std::size_t through = 0;
        for (std::uint32_t i = 0; i < n; ++i) {
            const PhotonHead h = emitPhoton(sun, i, kSeed + std::uint64_t(s));
            ASSERT_EQ(h.direction, sun.axis);
            ASSERT_LT(glm::dot(h.origin, axis), nearestCorner);
            const glm::vec3 hit = h.origin + glm::dot(centre - h.origin, axis) * axis;
            const glm::vec3 rel = hit - centre;
            if (std::abs(glm::dot(rel, glm::vec3(t))) < side / 2 &&
                std::abs(glm::dot(rel, glm::vec3(b))) < side / 2)
                ++through;
        }
        flux.push_back(double(through) * sun.power.x / n);
    }
    double mean = 0.0, variance = 0.0;
    for (double x : flux)
        mean += x / kSeeds;
    for (double x : flux)
        variance += (x - mean) * (x - mean) / (kSeeds - 1);
    const double expected = 3.0 * side * side;
    EXPECT_NEAR(mean, expected,
                kStudentT * std::sqrt(variance / kSeeds) + 8.0 * 0x1p-24 * expected);
}

/// Index of the sub-triangle (of 16 equal ones, each edge cut in 4) holding barycentric (a, b).
int subTriangle(double a, double b) {
    const double x = std::clamp(a * 4.0, 0.0, 3.999999), y = std::clamp(b * 4.0, 0.0, 3.999999);
    const int i = int(x), j = int(y);
    const bool upper = (x - i) + (y - j) > 1.0;
    // Row j holds 2 (4 - j) - 1 cells; i + j < 4.
    int cell = 0;
    for (int r = 0; r < j; ++r)
        cell += 2 * (4 - r) - 1;
    return cell + 2 * i + (upper ? 1 : 0);
}

void expectTriangleEmitter(const glm::mat4& world) {
    Registry registry;
    Mesh mesh;
    mesh.positions = {{0.f, 0.f, 0.f}, {1.f, 0.f, 0.f}, {0.2f, 0.9f, 0.f}};
    mesh.indices = {0, 1, 2};
    Material material;
    material.emission = {2.f, 1.f, 0.5f};
    const Entity e = test::addMesh(registry, mesh, world, material, false, "emitter");
    PhotonEmitter lamp;
    lamp.kind = EmitterKind::Surface;
    lamp.entity = e;
    lamp.world = world;
    lamp.radiant = material.emission;
    constexpr std::uint32_t n = 16'000;
    lamp = prepared(registry, lamp, n);

    glm::dvec3 w[3];
    for (int i = 0; i < 3; ++i)
        w[i] = glm::dvec3(glm::dmat4(world) * glm::dvec4(glm::dvec3(mesh.positions[i]), 1.0));
    const glm::dvec3 cross = glm::cross(w[1] - w[0], w[2] - w[0]);
    const double area = 0.5 * glm::length(cross);
    // The front side: counter-clockwise in object space, whatever the matrix does to it.
    const double mirror = glm::determinant(glm::dmat3(glm::dmat4(world))) < 0.0 ? -1.0 : 1.0;
    const glm::dvec3 front = mirror * glm::normalize(cross);
    EXPECT_NEAR(lamp.power.x, kPi * 2.0 * area, 1e-5 * lamp.power.x);

    const auto [t, b] = tangents(front);
    std::vector<int> cells(16, 0);
    double sumCos = 0.0, sumCos2 = 0.0, sumT = 0.0;
    for (std::uint32_t i = 0; i < n; ++i) {
        const PhotonHead h = emitPhoton(lamp, i, kSeed);
        const glm::dvec3 o(h.origin);
        const double height = glm::dot(o - w[0], front);
        ASSERT_GT(height, 0.0); // just off the front of the surface
        ASSERT_LT(height, 1e-3);
        // Barycentrics of the point projected onto the plane.
        const glm::dvec3 p = o - height * front;
        const glm::dvec3 e1 = w[1] - w[0], e2 = w[2] - w[0], r = p - w[0];
        const double d11 = glm::dot(e1, e1), d12 = glm::dot(e1, e2), d22 = glm::dot(e2, e2);
        const double det = d11 * d22 - d12 * d12;
        const double a = (d22 * glm::dot(r, e1) - d12 * glm::dot(r, e2)) / det;
        const double bb = (d11 * glm::dot(r, e2) - d12 * glm::dot(r, e1)) / det;
        ASSERT_GE(a, -1e-5);
        ASSERT_GE(bb, -1e-5);
        ASSERT_LE(a + bb, 1.0 + 1e-5);
        ++cells[subTriangle(a, bb)];
        const glm::dvec3 d(h.direction);
        const double c = glm::dot(d, front);
        ASSERT_GT(c, 0.0);
        sumCos += c;
        sumCos2 += c * c;
        sumT += glm::dot(d, t);
    }
    // Uniform over the triangle: chi-square over 16 equal cells, 15 degrees of freedom,
    // critical value 37.70 at significance 0.001.
    double chi2 = 0.0;
    for (const int count : cells)
        chi2 += (count - n / 16.0) * (count - n / 16.0) / (n / 16.0);
    EXPECT_LT(chi2, 37.70);
    // Cosine-weighted: cos(theta) has mean 2/3 and variance 1/18; cos^2 is uniform (mean 1/2,
    // variance 1/12); a tangent component has mean 0 and variance 1/4.
    EXPECT_NEAR(sumCos / n, 2.0 / 3.0, 4.5 * std::sqrt(1.0 / 18.0 / n));
    EXPECT_NEAR(sumCos2 / n, 0.5, 4.5 * std::sqrt(1.0 / 12.0 / n));
    EXPECT_NEAR(sumT / n, 0.0, 4.5 * std::sqrt(0.25 / n));
}

TEST(PhotonEmission, EmissiveTriangleIsUniformInPositionAndCosineInDirection) {
    expectTriangleEmitter(test::translation({0.5f, 2.f, -1.f}) *
                          glm::mat4_cast(glm::angleAxis(0.7f, glm::normalize(glm::vec3(1, 2, 3)))) *
                          glm::scale(glm::mat4(1.f), {2.f, 0.5f, 1.f}));
}

TEST(PhotonEmission, MirroredEmissiveTriangleStillEmitsFromItsFront) {
    expectTriangleEmitter(glm::scale(glm::mat4(1.f), {-1.5f, 1.f, 1.f}));
}

TEST(PhotonEmission, EmissiveMeshPicksTrianglesInProportionToArea) {
    Registry registry;
    Mesh mesh; // a 1 x 1 and a 3 x 1 rectangle's lower-left triangles, side by side
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {2, 0, 0}, {5, 0, 0}, {2, 1, 0}};
    mesh.indices = {0, 1, 2, 3, 4, 5};
    Material material;
    material.emission = glm::vec3(1.f);
    PhotonEmitter lamp;
    lamp.kind = EmitterKind::Surface;
    lamp.entity = test::addMesh(registry, mesh, glm::mat4(1.f), material, false, "two");
    lamp.radiant = glm::vec3(1.f);
    constexpr std::uint32_t n = 8'000;
    lamp = prepared(registry, lamp, n);
    EXPECT_NEAR(lamp.power.x, kPi * 2.0, 1e-5);
    std::size_t onLarge = 0;
    for (std::uint32_t i = 0; i < n; ++i)
        onLarge += emitPhoton(lamp, i, kSeed).origin.x > 1.5f ? 1 : 0;
    EXPECT_NEAR(double(onLarge), 0.75 * n, 4.5 * std::sqrt(n * 0.75 * 0.25));
}

TEST(PhotonEmission, InvalidLightsEmitNothingAndDoNotStopTheFrame) {
    Registry registry;
    const auto expectDark = [&](PhotonEmitter light) {
        prepareEmitter(registry, {glm::vec3(-1.f), glm::vec3(1.f)}, light);
        EXPECT_EQ(light.power, glm::vec3(0.f));
    };
    PhotonEmitter bad;
    bad.kind = EmitterKind::Point;
    bad.radiant = {1.f, -1.f, 1.f};
    expectDark(bad);
    bad.radiant = glm::vec3(NAN);
    expectDark(bad);
    bad.radiant = glm::vec3(1e21f); // finite, past kMaxLightRadiance
    expectDark(bad);
    bad.kind = EmitterKind::Spot;
    bad.radiant = glm::vec3(1.f);
    bad.innerAngle = 0.5f;
    bad.outerAngle = 0.4f;
    expectDark(bad);
    bad.outerAngle = 2.f;
    expectDark(bad);
    // Past kMaxPoseReach from the origin (Embree aborts on rays from 1.8e18 m): dark. Just
    // inside it, a light still shines.
    // A light of `kind` shining with radiant 1 (a spot's cones 0.2 and 0.4 rad) from `world`.
    const auto shining = [](EmitterKind kind, const glm::mat4& world) {
        PhotonEmitter light;
        light.kind = kind;
        light.radiant = glm::vec3(1.f);
        light.innerAngle = 0.2f;
        light.outerAngle = 0.4f;
        light.world = world;
        return light;
    };
    for (const EmitterKind kind : {EmitterKind::Point, EmitterKind::Spot}) {
        PhotonEmitter far =
            shining(kind, glm::translate(glm::mat4(1.f), glm::vec3(0.f, 0.9e7f, 0.f)));
        PhotonEmitter near = far;
        prepareEmitter(registry, {glm::vec3(-1.f), glm::vec3(1.f)}, near);
        EXPECT_GT(near.power.x, 0.f);
        for (const glm::vec3 at : {glm::vec3(0.f, 2e7f, 0.f), glm::vec3(-1e20f, 0.f, 0.f)}) {
            far.world = glm::translate(glm::mat4(1.f), at);
            expectDark(far);
        }
    }
    bad.kind = EmitterKind::Directional;
    bad.world = glm::mat4(0.f);
    expectDark(bad);
    bad.world = glm::scale(glm::mat4(1.f), glm::vec3(1.f, 1.f, 0.f)); // -Z collapsed
    expectDark(bad);
    // A huge scale keeps the axis (its length is taken in double, where float's overflowed
    // and the light went dark as if it had none).
    for (const EmitterKind kind : {EmitterKind::Spot, EmitterKind::Directional}) {
        PhotonEmitter huge = shining(kind, aimedAlong({0.f, -1.f, 0.f}, {0.f, 2.f, 0.f}) *
                                               glm::scale(glm::mat4(1.f), glm::vec3(1e20f)));
        prepareEmitter(registry, {glm::vec3(-1.f), glm::vec3(1.f)}, huge);
        EXPECT_GT(huge.power.x, 0.f);
        EXPECT_NEAR(huge.axis.y, -1.f, 1e-6f);
    }
}

// ---- the system's share of photons among lights ---------------------------------------------

TEST(PhotonEmission, StandInLightsShootNoPhotons) {
    // A bulb standing in for a lamp's diffuser (LightStandIn) is drawn by the shader only; the
    // diffuser's photons carry the light, so counting the bulb too would double the lamp.
    Registry registry;
    test::addMesh(registry, test::boxMesh({3.f, 2.f, 3.f}, true, true), glm::mat4(1.f),
                  test::grey(0.6f), false, "open room");
    const Entity bulb = test::addPointLight(registry, {0.f, 1.f, 0.f}, 5.f);
    registry.emplace<LightStandIn>(bulb);
    test::addPointLight(registry, {0.5f, 1.f, 0.f}, 3.f);
    test::buildRayScene(registry);
    PhotonSettings settings;
    settings.photonCount = 1000;
    PhotonUpdateSystem system(settings);
    test::firstUpdate(registry, system);
    const PhotonStore& store = registry.ctx().get<PhotonStore>();
    ASSERT_EQ(store.lights.size(), 1u);
    EXPECT_NE(store.lights[0].entity, bulb);
    EXPECT_NEAR(store.emittedPower.x, 4.0 * kPi * 3.0, 1e-4);
}

TEST(PhotonEmission, AStandInMarksItsSurfaceAsDrawnByTheRendererInHybridMode) {
    // Two emissive panels under a ceiling; a stand-in bulb 2 cm below the first only. Hybrid
    // mode's renderer draws the first lamp (through the bulb), so its photons' first segments
    // must not count; the second has nobody to draw it. Point lights are always drawn.
    Registry registry;
    test::addMesh(registry, test::boxMesh({3.f, 2.f, 3.f}, true, true), glm::mat4(1.f),
                  test::grey(0.6f), false, "open room");
    Material glow = test::grey(0.f);
    glow.emission = glm::vec3(2.f);
    const Entity lamp = test::addMesh(registry, test::gridMesh({-0.2f, 1.9f, -0.2f}, {0.4f, 0.f, 0.f},
                                                               {0.f, 0.f, 0.4f}, 1),
                                      glm::mat4(1.f), glow, false, "lamp");
    const Entity panel = test::addMesh(registry, test::gridMesh({1.f, 1.9f, 1.f}, {0.4f, 0.f, 0.f},
                                                                {0.f, 0.f, 0.4f}, 1),
                                       glm::mat4(1.f), glow, false, "panel");
    registry.emplace<LightStandIn>(test::addPointLight(registry, {0.f, 1.88f, 0.f}, 5.f));
    const Entity bulb = test::addPointLight(registry, {-1.5f, 1.f, 0.f}, 3.f);
    test::buildRayScene(registry);
    PhotonSettings settings;
    settings.photonCount = 1000;
    PhotonUpdateSystem system(settings);
    test::firstUpdate(registry, system);
    const PhotonStore& store = registry.ctx().get<PhotonStore>();
    ASSERT_EQ(store.lights.size(), 3u);
    for (const PhotonLight& light : store.lights) {
        if (light.entity == bulb) EXPECT_TRUE(light.directDrawn);
        else if (light.entity == lamp) EXPECT_TRUE(light.directDrawn);
        else if (light.entity == panel) EXPECT_FALSE(light.directDrawn);
        else ADD_FAILURE() << "unexpected light";
    }
}

TEST(PhotonEmission, PhotonCountsFollowPowerAndEveryPhotonCarriesItsShare) {
    Registry registry;
    test::addMesh(registry, test::boxMesh({3.f, 2.f, 3.f}, true, true), glm::mat4(1.f),
                  test::grey(0.6f), false, "open room");
    test::addPointLight(registry, {0.f, 1.f, 0.f}, 3.f, {1.f, 0.8f, 0.6f});
    const Entity spot = registry.create();
    registry.emplace<WorldTransform>(spot, aimedAlong({0.f, -1.f, 0.2f}, {1.f, 1.5f, 0.f}));
    registry.emplace<SpotLight>(spot, SpotLight{glm::vec3(1.f), 40.f, 0.2f, 0.5f});
    const Entity sun = registry.create();
    registry.emplace<WorldTransform>(sun, aimedAlong({0.2f, -1.f, 0.1f}, {0.f, 10.f, 0.f}));
    registry.emplace<DirectionalLight>(sun, DirectionalLight{{1.f, 0.9f, 0.8f}, 0.5f});
    Material panel;
    panel.emission = glm::vec3(4.f);
    Mesh quad;
    quad.positions = {
        {-0.5f, 1.9f, -0.5f}, {0.5f, 1.9f, -0.5f}, {0.5f, 1.9f, 0.5f}, {-0.5f, 1.9f, 0.5f}};
    quad.indices = {0, 2, 1, 0, 3, 2}; // facing down
    test::addMesh(registry, quad, glm::mat4(1.f), panel, false, "panel");
    test::buildRayScene(registry);

    PhotonSettings settings;
    settings.photonCount = 10'007;
    PhotonUpdateSystem system(settings);
    test::firstUpdate(registry, system);
    const PhotonStore& store = registry.ctx().get<PhotonStore>();
    ASSERT_EQ(store.lights.size(), 4u);
    EXPECT_NEAR(store.lights[0].power.x, 4.0 * kPi * 3.0, 1e-4);
    EXPECT_NEAR(store.lights[3].power.x, kPi * 4.0 * 1.0, 1e-4); // pi L A, A = 1 m^2

    const auto weight = [](const glm::vec3& p) { return double(p.x) + p.y + p.z; };
    double total = 0.0;
    glm::dvec3 emitted(0.0);
    for (const PhotonLight& light : store.lights) {
        total += weight(light.power);
        emitted += glm::dvec3(light.power);
    }
    std::uint32_t photons = 0;
    for (const PhotonLight& light : store.lights) {
        EXPECT_LT(std::abs(light.photonCount - settings.photonCount * weight(light.power) / total),
                  1.0);
        photons += light.photonCount;
    }
    EXPECT_EQ(photons, settings.photonCount);
    EXPECT_NEAR(glm::length(glm::dvec3(store.emittedPower) - emitted), 0.0,
                1e-5 * glm::length(emitted));

    // Every path starts with its light's power over its light's photon count; together the
    // heads carry exactly what the lights emit.
    glm::dvec3 heads(0.0);
    for (const PhotonPath& path : store.paths) {
        const PhotonLight& light = store.lights[path.light];
        ASSERT_GT(path.count, 0);
        ASSERT_EQ(store.segments.power[path.first], light.power / float(light.photonCount));
        ASSERT_EQ(store.segments.bounce[path.first], 0);
        heads += glm::dvec3(store.segments.power[path.first]);
    }
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(heads[c], emitted[c], 1e-5 * emitted[c]);
}

} // namespace
} // namespace qgi
