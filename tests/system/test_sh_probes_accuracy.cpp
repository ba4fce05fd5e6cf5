// SH probe irradiance in the built-in cornell scene (photon mode) against an independent
// brute-force quadrature of the same light, at eight points in free space: four avatar
// positions taken as given (off the probe nodes) and the nodes nearest to them.
//
// What is compared. A probe turns the radiance the scene shows around a point into order-2 SH,
// and the avatar reads irradiance from it. That radiance is the engine's (ShProbeSystem.h):
// at a triangle's front face, emission + albedo / pi x the triangle's VertexIrradiance
// interpolated at the hit; nothing at a back face; the environment on a miss. The test fills
// VertexIrradiance from the path-traced reference (tests/reference: realistic, noisy values)
// and then integrates that same radiance field by plain Monte Carlo, with its own rays and
// random numbers (Gather below). Both sides read the same input, so the difference measures
// the probe system alone: its quadrature, its SH truncation and its interpolation between
// probes, and no allowance for the input's own error is needed.
//
// Error terms, each bounded separately:
//  - probe quadrature: raysPerProbe directions of a spherical Fibonacci set under a uniformly
//    random rotation. Every direction of such a set is uniform on the sphere, so the
//    projection is unbiased over rotations; kReplicates independent rotations (probe seeds)
//    give a mean and its standard error, held to Student's t with kReplicates - 1 degrees of
//    freedom (kProbeT);
//  - the gather: independent directions (kSphereSamples or kGatherSamples per estimate), mean
//    and standard error, held to kGatherZ standard errors (normal);
//  - off the probe nodes, the spread (max - min) over the 8 corner probes (their replicate
//    means): trilinear interpolation returns a weighted mean of the corners, and light that
//    is monotone across a cell lies within their range;
//  - for irradiance along a normal n only, the order-2 truncation: at most 3/32 of the
//    integral of L over the sphere for any non-negative radiance
//    (runtime/math/SphericalHarmonics.h, kDirectionalMaxError).
// Checks:
//  1. per point, each of the nine SH coefficients, the integral of L Y_i over the sphere
//     (uniform directions; 4 pi mean L Y_i, the harmonics written out in double), which
//     truncation leaves exact: quadrature, spread and the basis constants' six digits only.
//     At the nodes the bound on L00 is 4-12 % of it (the rotations' and the gather's standard
//     errors): a probe system 5 % too bright fails at the brightest node (L00 and L20); one
//     whose x terms (L11, L2-2, L21) change sign fails 21 comparisons of each, besides 170
//     irradiances;
//  2. per point and each of kNormals normals, the order-2 irradiance: what a perfect
//     projection gives (the gather weighs each direction by the cosine's Legendre terms up
//     to order 2), so no truncation allowance: quadrature, spread and basis constants only;
//  3. per point and normal, the true irradiance E(n) (cosine-weighted directions; pi mean
//     L), truncation included: how far an avatar's light may be from the real one;
//  4. summed over the nodes, L00 and one order-2 irradiance: a brightness error common to
//     every node, too small for any single comparison, fails here (a 3 % one does).
// About 1800 comparisons; with a false-alarm rate of 5.7e-7 per term and comparison the whole
// test has about three chances in a thousand of failing a correct system (the seeds are
// fixed, so a given build passes or fails every time).
#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/math/SphericalHarmonics.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/sh_probes/ProbeVolume.h"
#include "systems/sh_probes/ShProbeSystem.h"
#include "tests/reference/IrradianceReference.h"

#include <glm/gtc/constants.hpp>
#include <glm/mat3x3.hpp>
#include <gtest/gtest.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <span>
#include <utility>
#include <vector>

namespace qgi {
namespace {

constexpr std::uint32_t kVertexSamples = 64; // reference paths per vertex: the input
constexpr std::uint32_t kReplicates = 32;    // probe projections under independent rotations
constexpr double kProbeT = 6.27;             // Student t, 31 degrees of freedom, two-sided 5.7e-7
constexpr std::uint32_t kGatherSamples = 1u << 15; // directions per (point, normal)
constexpr std::uint32_t kSphereSamples = 1u << 20; // per point: the integral's check is tight
constexpr double kGatherZ = 5.0;                   // normal, two-sided 5.7e-7
constexpr std::uint32_t kNormals = 32;
// The engine's basis constants have six digits (1.6e-6 relative at most), the test's are
// exact: a coefficient differs by at most that share of sum |L Y_i| <= 1.1 x the integral of L.
constexpr double kBasisRounding = 2e-6;

void fillVertexIrradianceFromReference(Registry& world, const RayScene& scene) {
    reference::ReferenceSettings settings;
    settings.samplesPerPoint = kVertexSamples;
    settings.seed = 11;
    const reference::IrradianceReference ref(world, scene, settings);
    std::vector<Entity> entities;
    world.view<const Mesh, const WorldTransform>().each(
        [&](Entity e, const Mesh&, const WorldTransform&) {
            if (world.has<StaticMesh>(e) || world.has<MobileMesh>(e)) entities.push_back(e);
        });
    for (const Entity e : entities) {
        const Mesh& mesh = world.get<Mesh>(e);
        const glm::mat4& m = world.get<WorldTransform>(e).matrix;
        const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(m)));
        std::vector<glm::vec3> xs, ns;
        for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
            const glm::vec3 n = glm::normalize(normalMatrix * mesh.normals[v]);
            // Just off the surface on its front side, where the estimate is well defined.
            xs.push_back(glm::vec3(m * glm::vec4(mesh.positions[v], 1.f)) + 1e-4f * n);
            ns.push_back(n);
        }
        const auto estimates = ref.estimate(xs, ns);
        VertexIrradiance& vi = world.emplaceOrReplace<VertexIrradiance>(e);
        vi.irradiance.clear();
        for (const auto& est : estimates)
            vi.irradiance.push_back(glm::vec3(est.mean));
    }
}

/// A mean and its standard error, per channel.
struct Estimate {
    glm::dvec3 mean{0.0}, standardError{0.0};
};

/// Monte Carlo integrals of the radiance the engine's surfaces show (the file comment), with
/// its own random numbers: splitmix64 keyed by the estimate's index.
class Gather {
public:
    Gather(const Registry& world, const RayScene& scene) : mScene(scene) {
        mEnvironment = world.ctx().get<SceneInfo>().environment;
        world.view<const Mesh, const Material>().each(
            [&](Entity e, const Mesh& mesh, const Material& material) {
                if (e.index >= mSurfaces.size()) mSurfaces.resize(e.index + 1);
                Surface& s = mSurfaces[e.index];
                s.mesh = &mesh;
                s.albedo = material.baseColor;
                s.emission = material.emission;
                s.irradiance = world.tryGet<VertexIrradiance>(e);
            });
    }

    struct Projection {
        std::array<Estimate, sh::kCoefficientCount> coefficients;
        std::vector<Estimate> orderTwo; ///< per normal
    };

    /// The nine SH coefficients of L around x, integral of L Y_i over the sphere: 4 pi mean of
    /// L Y_i over uniform directions, with the real harmonics written out here in double
    /// (the engine's order: Y00; Y1-1, Y10, Y11 ~ y, z, x; Y2-2, Y2-1, Y20, Y21, Y22). From
    /// the same directions, for each of `normals`, the order-2 irradiance the nine give, by
    /// the addition theorem the integral of L K(n . w) with K(t) = 1/4 + t/2 + 5 (3t^2 - 1)/32
    /// (the cosine's Legendre terms up to order 2: the irradiance a perfect projection gives).
    Projection projection(const glm::vec3& x, std::span<const glm::vec3> normals,
                          std::uint64_t key) const {
        const double pi = glm::pi<double>();
        const double y0 = 0.5 / std::sqrt(pi), y1 = std::sqrt(3.0 / (4.0 * pi)),
                     y2 = std::sqrt(15.0 / (4.0 * pi)), y20 = std::sqrt(5.0 / (16.0 * pi)),
                     y22 = std::sqrt(15.0 / (16.0 * pi));
        std::uint64_t state = key * 0x2545f4914f6cdd1dull + 17;
        std::array<glm::dvec3, sh::kCoefficientCount> sum{}, sum2{};
        std::vector<glm::dvec3> kernelSum(normals.size()), kernelSum2(normals.size());
        for (std::uint32_t i = 0; i < kSphereSamples; ++i) {
            const double u1 = uniform(state), u2 = uniform(state);
            const double z = 1.0 - 2.0 * u1, r = std::sqrt(std::max(0.0, 1.0 - z * z));
            const double phi = glm::two_pi<double>() * u2;
            const glm::dvec3 d(r * std::cos(phi), r * std::sin(phi), z);
            const glm::dvec3 L =
                4.0 * pi *
                radiance(Ray{x, 0.f, glm::vec3(d), std::numeric_limits<float>::infinity()});
            const double y[sh::kCoefficientCount] = {y0,
                                                     y1 * d.y,
                                                     y1 * d.z,
                                                     y1 * d.x,
                                                     y2 * d.x * d.y,
                                                     y2 * d.y * d.z,
                                                     y20 * (3.0 * d.z * d.z - 1.0),
                                                     y2 * d.x * d.z,
                                                     y22 * (d.x * d.x - d.y * d.y)};
            for (int k = 0; k < sh::kCoefficientCount; ++k) {
                sum[k] += L * y[k];
                sum2[k] += L * y[k] * L * y[k];
            }
            for (std::size_t k = 0; k < normals.size(); ++k) {
                const double t = glm::dot(glm::dvec3(normals[k]), d);
                const glm::dvec3 v = L * (0.25 + 0.5 * t + 5.0 * (3.0 * t * t - 1.0) / 32.0);
                kernelSum[k] += v;
                kernelSum2[k] += v * v;
            }
        }
        Projection out;
        for (int k = 0; k < sh::kCoefficientCount; ++k)
            out.coefficients[k] = meanAndError(sum[k], sum2[k], kSphereSamples);
        for (std::size_t k = 0; k < normals.size(); ++k)
            out.orderTwo.push_back(meanAndError(kernelSum[k], kernelSum2[k], kSphereSamples));
        return out;
    }

    /// Irradiance at x over the hemisphere of unit n: pi mean L over cosine-weighted directions.
    Estimate irradiance(const glm::vec3& x, const glm::vec3& n, std::uint64_t key) const {
        const glm::dvec3 w(n);
        const glm::dvec3 a = std::abs(w.x) > 0.5 ? glm::dvec3(0, 1, 0) : glm::dvec3(1, 0, 0);
        const glm::dvec3 t = glm::normalize(glm::cross(a, w)), b = glm::cross(w, t);
        return integrate(x, key, kGatherSamples, [&](double u1, double u2, glm::dvec3& d) {
            const double r = std::sqrt(u1), phi = glm::two_pi<double>() * u2;
            d = r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(1.0 - u1) * w;
            return glm::pi<double>();
        });
    }

private:
    struct Surface {
        const Mesh* mesh = nullptr;
        glm::vec3 albedo{0.f}, emission{0.f};
        const VertexIrradiance* irradiance = nullptr;
    };

    static std::uint64_t next(std::uint64_t& state) {
        std::uint64_t z = (state += 0x9e3779b97f4a7c15ull);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
        return z ^ (z >> 31);
    }
    static double uniform(std::uint64_t& state) { return double(next(state) >> 11) * 0x1p-53; }

    glm::dvec3 radiance(const Ray& ray) const {
        const std::optional<Hit> hit = mScene.intersect(ray);
        if (!hit) return glm::dvec3(mEnvironment);
        if (glm::dot(hit->normal, ray.direction) >= 0.f) return glm::dvec3(0.0); // back face
        const Surface& s = mSurfaces.at(hit->entity.index);
        glm::dvec3 e(0.0);
        if (s.irradiance && !s.irradiance->irradiance.empty()) {
            const std::uint32_t* corner = &s.mesh->indices.at(3 * std::size_t(hit->primitive));
            const double u = hit->barycentrics.x, v = hit->barycentrics.y;
            const auto& E = s.irradiance->irradiance;
            e = (1.0 - u - v) * glm::dvec3(E.at(corner[0])) + u * glm::dvec3(E.at(corner[1])) +
                v * glm::dvec3(E.at(corner[2]));
        }
        return glm::dvec3(s.emission) + glm::dvec3(s.albedo) / glm::pi<double>() * e;
    }

    template <typename Direction>
    Estimate integrate(const glm::vec3& x, std::uint64_t key, std::uint32_t samples,
                       Direction direction) const {
        std::uint64_t state = key * 0x2545f4914f6cdd1dull + 17;
        glm::dvec3 sum(0.0), sum2(0.0);
        for (std::uint32_t i = 0; i < samples; ++i) {
            const double u1 = uniform(state), u2 = uniform(state);
            glm::dvec3 d;
            const double scale = direction(u1, u2, d);
            const glm::dvec3 value = scale * radiance(Ray{x, 0.f, glm::vec3(glm::normalize(d)),
                                                          std::numeric_limits<float>::infinity()});
            sum += value;
            sum2 += value * value;
        }
        return meanAndError(sum, sum2, samples);
    }

    static Estimate meanAndError(const glm::dvec3& sum, const glm::dvec3& sum2,
                                 std::uint32_t samples) {
        const double m = samples;
        Estimate out;
        out.mean = sum / m;
        const glm::dvec3 variance = glm::max(sum2 / m - out.mean * out.mean, glm::dvec3(0.0));
        out.standardError = glm::sqrt(variance / (m - 1.0));
        return out;
    }

    const RayScene& mScene;
    glm::vec3 mEnvironment{0.f};
    std::vector<Surface> mSurfaces; // by entity index
};

/// Mean and standard error of the mean over the replicates, per channel.
Estimate replicateMean(const std::vector<glm::dvec3>& values) {
    Estimate out;
    for (const glm::dvec3& v : values)
        out.mean += v;
    out.mean /= double(values.size());
    glm::dvec3 squares(0.0);
    for (const glm::dvec3& v : values)
        squares += (v - out.mean) * (v - out.mean);
    const double k = double(values.size());
    out.standardError = glm::sqrt(squares / (k - 1.0) / k);
    return out;
}

TEST(ShProbesAccuracy, CornellProbesAgreeWithABruteForceGatherOfTheSameLight) {
    Registry world;
    buildBuiltinScene(world, "cornell",
                      SceneOptions{0.04f}); // 4 cm triangles: a quarter of the vertices
    RayScene& scene = world.ctx().emplace<RayScene>();
    scene.build(world);
    fillVertexIrradianceFromReference(world, scene);

    // Photon mode: every punctual light of the scene must be a stand-in, which probes skip
    // (ShProbeSystem.h), so the surfaces' radiance is all the light there is.
    world.view<const PointLight>().each(
        [&](Entity e, const PointLight&) { ASSERT_TRUE(world.has<LightStandIn>(e)); });
    ASSERT_TRUE(world.view<const SpotLight>().entities().empty());
    ASSERT_TRUE(world.view<const DirectionalLight>().entities().empty());

    ShProbeSettings settings;
    settings.spacing = 0.07f; // about the avatar's size
    settings.raysPerProbe = 2048;
    settings.hybrid = false; // photon mode: the luminaire's light arrives as emission

    // Sphere centres in free space: above the short block, high in the middle, low in the
    // front-left corner where the scene's avatar walks, behind the short block. Each is taken
    // as given (off the nodes) and at its nearest probe node.
    const glm::vec3 bases[] = {{0.09f, 0.30f, -0.17f},
                               {0.f, 0.40f, -0.28f},
                               {-0.20f, 0.10f, -0.10f},
                               {0.20f, 0.25f, -0.40f}};
    struct Point {
        glm::vec3 x;
        bool node = false;
        ProbeBlend blend;
        std::vector<sh::ShRgb> probe;                // interpolated SH, per replicate
        std::vector<std::vector<sh::ShRgb>> corners; // per corner, per replicate
    };
    std::vector<Point> points;
    for (std::uint32_t r = 0; r < kReplicates; ++r) {
        settings.seed = 1 + r;
        ShProbeSystem system(settings);
        system.build(world);
        system.projectAll(world);
        const ProbeVolume& volume = world.ctx().get<ProbeVolume>();
        if (r == 0)
            for (const glm::vec3& b : bases) {
                points.push_back({b, false, {}, {}, {}});
                glm::ivec3 cell;
                glm::vec3 t;
                volume.grid().locate(b, cell, t);
                const std::uint32_t node =
                    volume.grid().probeIndex(cell + glm::ivec3(glm::round(t)));
                ASSERT_TRUE(volume.enabled(node));
                points.push_back({volume.grid().position(node), true, {}, {}, {}});
            }
        for (Point& p : points) {
            sh::ShRgb L;
            ProbeBlend blend;
            ASSERT_TRUE(volume.interpolate(p.x, L, &blend));
            if (r == 0) {
                p.blend = blend;
                p.corners.resize(8);
            }
            // Blending depends on geometry only: the same corners and weights every time.
            for (int c = 0; c < 8; ++c) {
                ASSERT_EQ(blend.probes[c], p.blend.probes[c]);
                ASSERT_EQ(blend.weights[c], p.blend.weights[c]);
                p.corners[c].push_back(volume.coefficients(blend.probes[c]));
            }
            p.probe.push_back(L);
        }
    }

    const Gather gather(world, scene);
    std::vector<glm::vec3> normals;
    for (std::uint32_t k = 0; k < kNormals; ++k)
        normals.push_back(sh::fibonacciDirection(k, kNormals));
    // Per point: the projection, then one irradiance per normal.
    const std::size_t perPoint = 1 + kNormals;
    std::vector<Gather::Projection> projected(points.size());
    std::vector<Estimate> gathered(points.size() * perPoint);
    tbb::parallel_for(std::size_t(0), gathered.size(), [&](std::size_t i) {
        const Point& p = points[i / perPoint];
        const std::size_t j = i % perPoint;
        if (j == 0)
            projected[i / perPoint] = gather.projection(p.x, normals, i);
        else
            gathered[i] = gather.irradiance(p.x, normals[j - 1], i);
    });

    // A quantity of the SH (integral or irradiance along n) through its replicates and through
    // the corners' replicate means, against the gather's estimate of it.
    const auto compare = [&](const Point& p, const Estimate& reference, auto quantity,
                             bool truncated, const char* what) {
        std::vector<glm::dvec3> values;
        for (const sh::ShRgb& L : p.probe)
            values.push_back(glm::dvec3(quantity(L)));
        const Estimate probe = replicateMean(values);
        glm::dvec3 lo(1e300), hi(-1e300);
        for (int c = 0; c < 8; ++c) {
            if (p.node || p.blend.weights[c] <= 0.f) continue;
            std::vector<glm::dvec3> corner;
            for (const sh::ShRgb& L : p.corners[c])
                corner.push_back(glm::dvec3(quantity(L)));
            const glm::dvec3 m = replicateMean(corner).mean;
            lo = glm::min(lo, m);
            hi = glm::max(hi, m);
        }
        const glm::dvec3 spread = p.node ? glm::dvec3(0.0) : hi - lo;
        glm::dvec3 integral(0.0);
        for (const sh::ShRgb& L : p.probe)
            integral += glm::dvec3(sh::integral(L));
        integral /= double(p.probe.size());
        const glm::dvec3 truncation =
            truncated ? double(sh::kDirectionalMaxError) * integral : glm::dvec3(0.0);
        for (int c = 0; c < 3; ++c) {
            const double bound = kProbeT * probe.standardError[c] +
                                 kGatherZ * reference.standardError[c] + spread[c] + truncation[c] +
                                 kBasisRounding * integral[c];
            EXPECT_NEAR(probe.mean[c], reference.mean[c], bound)
                << what << " at " << p.x.x << "," << p.x.y << "," << p.x.z
                << (p.node ? " (node)" : "") << " channel " << c << ": probe standard error "
                << probe.standardError[c] << ", gather " << reference.standardError[c]
                << ", spread " << spread[c] << ", truncation " << truncation[c];
        }
        return probe;
    };

    static const char* const kNames[sh::kCoefficientCount] = {"L00",  "L1-1", "L10", "L11", "L2-2",
                                                              "L2-1", "L20",  "L21", "L22"};
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Point& p = points[i];
        std::printf("point (%.3f %.3f %.3f)%s, green, probe (gather):", p.x.x, p.x.y, p.x.z,
                    p.node ? " node" : "     ");
        for (int k = 0; k < sh::kCoefficientCount; ++k) {
            const Estimate& ref = projected[i].coefficients[k];
            const Estimate probe = compare(
                p, ref, [k](const sh::ShRgb& L) { return L[k]; }, false, kNames[k]);
            std::printf(" %s %.3f (%.3f)", kNames[k], probe.mean.g, ref.mean.g);
        }
        std::printf("\n");
        for (std::uint32_t k = 0; k < kNormals; ++k) {
            const glm::vec3 n = normals[k];
            const auto irradiance = [n](const sh::ShRgb& L) { return sh::irradiance(L, n); };
            // What the nine coefficients should give, with no truncation allowance; and the
            // true irradiance, with it.
            compare(p, projected[i].orderTwo[k], irradiance, false, "order-2 irradiance");
            compare(p, gathered[i * perPoint + 1 + k], irradiance, true, "irradiance");
        }
    }

    // Pooled over the nodes: a brightness error common to all of them, too small to fail any
    // one comparison, shows in the sum of the differences, held to kGatherZ of its standard
    // error (the replicates' and the gather's, independent).
    // Two quantities: L00 (normal 0 stands for it) and the order-2 irradiance along one normal.
    for (const auto& [normal, name] :
         {std::pair{0, "L00"}, std::pair{int(kNormals / 2), "order-2 irradiance"}}) {
        glm::dvec3 difference(0.0), variance(0.0), integral(0.0);
        for (std::size_t i = 0; i < points.size(); ++i) {
            const Point& p = points[i];
            if (!p.node) continue;
            std::vector<glm::dvec3> values;
            for (const sh::ShRgb& L : p.probe) {
                values.push_back(normal == 0 ? glm::dvec3(L[0])
                                             : glm::dvec3(sh::irradiance(L, normals[normal])));
                integral += glm::dvec3(sh::integral(L)) / double(p.probe.size());
            }
            const Estimate probe = replicateMean(values);
            const Estimate& reference =
                normal == 0 ? projected[i].coefficients[0] : projected[i].orderTwo[normal];
            difference += probe.mean - reference.mean;
            variance += probe.standardError * probe.standardError +
                        reference.standardError * reference.standardError;
        }
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(difference[c], 0.0,
                        kGatherZ * std::sqrt(variance[c]) + kBasisRounding * integral[c])
                << name << " summed over the nodes, channel " << c;
        std::printf("%s summed over the nodes, green: probe - gather %.4f, standard error %.4f\n",
                    name, difference.g, std::sqrt(variance.g));
    }
}

} // namespace
} // namespace qgi
