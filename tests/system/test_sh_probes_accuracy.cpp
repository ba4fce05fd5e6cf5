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
// Off the nodes the reference is what a correct interpolation of correct probes gives: the
// gather at the 8 corner nodes of the point's cell, blended with trilinear weights the test
// works out itself from (x - origin) / spacing. A blend with wrong weights (a wrong t, swapped
// axes, the nearest node alone) is off by a share of the corners' differences, and those are
// far larger than the bounds here (the light changes by up to a quarter across one spacing).
// The corners' range, taken as a tolerance, holds any such blend (weights that add to 1 stay
// inside it), so it catches one only where the light at the point lies far from its corners'.
// With the x and y weights swapped, 320 comparisons at the four off-node points fail (held to
// the corners' range, none does); with y and z swapped, 367; with the nearest corner alone, 298;
// with x's weights mirrored (1 - t for t), 215. How far the trilinear blend is from the light
// at the point itself (a direct gather there) is the interpolation's own error, set by the
// probe spacing and not a fault of the code: printed and recorded (RecordProperty), not
// bounded.
//
// The probes reach the points the way they reach avatars: an Avatar at each point, lit by
// ShProbeSystem::lightAvatars, which computes its cell's visibility masks before it
// interpolates. The cells must come out open (every lattice point sees all 8 corners), which
// leaves the trilinear weights as they are; blending by partial visibility would need a
// visibility model of the test's own and is tests/unit/test_sh_probes.cpp's to check.
//
// Error terms, each bounded separately:
//  - probe quadrature: raysPerProbe directions of a spherical Fibonacci set under a uniformly
//    random rotation. Every direction of such a set is uniform on the sphere, so the
//    projection is unbiased over rotations; kReplicates independent rotations (probe seeds)
//    give a mean and its standard error, held to Student's t with kReplicates - 1 degrees of
//    freedom (kProbeT). Off the nodes each replicate is the avatar's blend, so its standard
//    error holds the corners' quadrature noise as the blend weighs it;
//  - the gather: independent directions (kSphereSamples per point, kCornerSamples per corner
//    node that is not one of the points, kGatherSamples per node and normal), mean and
//    standard error; off the nodes the corners' estimates are independent, so the blend's
//    standard error is sqrt(sum_c w_c^2 SE_c^2). Held to kGatherZ standard errors (normal);
//  - for irradiance along a normal n only, the order-2 truncation: at most 3/32 of the
//    integral of L over the sphere for any non-negative radiance
//    (runtime/math/SphericalHarmonics.h, kDirectionalMaxError); off the nodes, at each
//    corner, so 3/32 of the blended integral.
// Checks:
//  1. per point, each of the nine SH coefficients, the integral of L Y_i over the sphere
//     (uniform directions; 4 pi mean L Y_i, the harmonics written out in double), which
//     truncation leaves exact: quadrature and the basis constants' six digits only.
//     At the nodes the bound on L00 is 4-12 % of it (the rotations' and the gather's standard
//     errors): a probe system 5 % too bright fails at the brightest node (L00 and L20),
//     besides 388 order-2 irradiances; one whose x terms (L11, L2-2, L21) change sign fails
//     all 24 comparisons of each, besides 961 irradiances;
//  2. per point and each of kNormals normals, the order-2 irradiance: what a perfect
//     projection gives (the gather weighs each direction by the cosine's Legendre terms up
//     to order 2), so no truncation allowance: quadrature and basis constants only;
//  3. per point and normal, the true irradiance E(n), truncation included: how far an
//     avatar's light may be from the real one. At the nodes from cosine-weighted directions
//     (pi mean L); off them the blend of the corners' integral of L max(0, n . w), from the
//     uniform directions of check 1;
//  4. summed over the nodes, L00 and one order-2 irradiance: a brightness error common to
//     every node, too small for any single comparison, fails here (a 3 % one does).
// About 1800 comparisons; with a false-alarm rate of 5.7e-7 per term and comparison the whole
// test has about three chances in a thousand of failing a correct system (the seeds are
// fixed, so a given build passes or fails every time).
#include "components/Avatar.h"
#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/PointLight.h"
#include "components/ShLighting.h"
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
#include <string>
#include <utility>
#include <vector>

namespace qgi {
namespace {

constexpr std::uint32_t kVertexSamples = 64; // reference paths per vertex: the input
constexpr std::uint32_t kReplicates = 32;    // probe projections under independent rotations
constexpr double kProbeT = 6.27;             // Student t, 31 degrees of freedom, two-sided 5.7e-7
constexpr std::uint32_t kGatherSamples = 1u << 15; // directions per (point, normal)
constexpr std::uint32_t kSphereSamples = 1u << 20; // per point: the integral's check is tight
// Per corner node that is not itself a point. The blend's standard error is
// sqrt(sum_c w_c^2 SE_c^2), and its heaviest corner, the nearest node, is a point with all the
// directions: a quarter of them at the other 7 (twice the error) leaves the blend's at 0.7-0.9
// times a point's at these four points, and keeps the 28 extra corners cheap.
constexpr std::uint32_t kCornerSamples = 1u << 18;
constexpr double kGatherZ = 5.0; // normal, two-sided 5.7e-7
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
        std::vector<Estimate> orderTwo;   ///< per normal
        std::vector<Estimate> irradiance; ///< per normal, the true one
    };

    /// The nine SH coefficients of L around x, integral of L Y_i over the sphere: 4 pi mean of
    /// L Y_i over uniform directions, with the real harmonics written out here in double
    /// (the engine's order: Y00; Y1-1, Y10, Y11 ~ y, z, x; Y2-2, Y2-1, Y20, Y21, Y22). From
    /// the same directions, for each of `normals`, the order-2 irradiance the nine give, by
    /// the addition theorem the integral of L K(n . w) with K(t) = 1/4 + t/2 + 5 (3t^2 - 1)/32
    /// (the cosine's Legendre terms up to order 2: the irradiance a perfect projection gives),
    /// and the true irradiance, the integral of L max(0, n . w) (noisier than from
    /// cosine-weighted directions, but it costs no rays).
    Projection projection(const glm::vec3& x, std::span<const glm::vec3> normals,
                          std::uint32_t samples, std::uint64_t key) const {
        const double pi = glm::pi<double>();
        const double y0 = 0.5 / std::sqrt(pi), y1 = std::sqrt(3.0 / (4.0 * pi)),
                     y2 = std::sqrt(15.0 / (4.0 * pi)), y20 = std::sqrt(5.0 / (16.0 * pi)),
                     y22 = std::sqrt(15.0 / (16.0 * pi));
        std::uint64_t state = key * 0x2545f4914f6cdd1dull + 17;
        std::array<glm::dvec3, sh::kCoefficientCount> sum{}, sum2{};
        std::vector<glm::dvec3> kernelSum(normals.size()), kernelSum2(normals.size());
        std::vector<glm::dvec3> cosineSum(normals.size()), cosineSum2(normals.size());
        for (std::uint32_t i = 0; i < samples; ++i) {
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
                const glm::dvec3 e = L * std::max(0.0, t);
                cosineSum[k] += e;
                cosineSum2[k] += e * e;
            }
        }
        Projection out;
        for (int k = 0; k < sh::kCoefficientCount; ++k)
            out.coefficients[k] = meanAndError(sum[k], sum2[k], samples);
        for (std::size_t k = 0; k < normals.size(); ++k) {
            out.orderTwo.push_back(meanAndError(kernelSum[k], kernelSum2[k], samples));
            out.irradiance.push_back(meanAndError(cosineSum[k], cosineSum2[k], samples));
        }
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
    // Where the gather runs: each point, with kSphereSamples directions, and each corner node
    // of an off-node point's cell that is not itself a point, with kCornerSamples. `key` picks
    // the random numbers.
    struct Site {
        glm::vec3 x;
        std::uint32_t samples = 0;
        std::uint64_t key = 0;
    };
    struct Point {
        glm::vec3 x;
        bool node = false;
        std::size_t site = 0;                 // its own gather
        std::array<std::size_t, 8> corners{}; // off the nodes: the corners' gathers (sites)
        std::array<double, 8> weights{};      // and their trilinear weights
        Entity avatar;
        std::vector<sh::ShRgb> probe; // the avatar's SH, per replicate
    };
    // Per point one projection and kNormals irradiances; the keys follow that layout, and the
    // corners' come after the points'.
    const std::size_t perPoint = 1 + kNormals;
    std::vector<Site> sites;
    std::vector<Point> points;
    for (std::uint32_t r = 0; r < kReplicates; ++r) {
        settings.seed = 1 + r;
        ShProbeSystem system(settings);
        system.build(world);
        system.projectAll(world);
        const ProbeVolume& volume = world.ctx().get<ProbeVolume>();
        const ProbeGrid& grid = volume.grid();
        if (r == 0) {
            std::vector<std::size_t> siteOfProbe(grid.probeCount(), sites.max_size());
            for (const glm::vec3& b : bases) {
                // The point's cell and its place in it, from the lattice's layout alone.
                const glm::dvec3 g =
                    (glm::dvec3(b) - glm::dvec3(grid.origin)) / double(grid.spacing);
                const glm::ivec3 cell(glm::floor(g));
                const glm::dvec3 t = g - glm::dvec3(cell);
                ASSERT_TRUE(glm::all(glm::greaterThanEqual(cell, glm::ivec3(0))) &&
                            glm::all(glm::lessThan(cell, grid.counts - 1)));
                Point off{b, false, sites.size(), {}, {}, {}, {}};
                sites.push_back({b, kSphereSamples, points.size() * perPoint});
                const std::uint32_t nearest = grid.probeIndex(cell + glm::ivec3(glm::round(t)));
                ASSERT_TRUE(volume.enabled(nearest));
                Point node{grid.position(nearest), true, sites.size(), {}, {}, {}, {}};
                siteOfProbe[nearest] = sites.size();
                sites.push_back({node.x, kSphereSamples, (points.size() + 1) * perPoint});
                points.push_back(off);
                points.push_back(node);
            }
            for (Point& p : points) {
                if (p.node) continue;
                const glm::dvec3 g =
                    (glm::dvec3(p.x) - glm::dvec3(grid.origin)) / double(grid.spacing);
                const glm::ivec3 cell(glm::floor(g));
                const glm::dvec3 t = g - glm::dvec3(cell);
                for (int c = 0; c < 8; ++c) {
                    const glm::ivec3 o(c & 1, (c >> 1) & 1, (c >> 2) & 1);
                    p.weights[c] =
                        (o.x ? t.x : 1.0 - t.x) * (o.y ? t.y : 1.0 - t.y) * (o.z ? t.z : 1.0 - t.z);
                    const std::uint32_t probe = grid.probeIndex(cell + o);
                    // A disabled corner would be dropped and the others' weights scaled up.
                    ASSERT_TRUE(volume.enabled(probe));
                    if (siteOfProbe[probe] == sites.max_size()) {
                        siteOfProbe[probe] = sites.size();
                        sites.push_back({grid.position(probe), kCornerSamples,
                                         points.size() * perPoint + sites.size()});
                    }
                    p.corners[c] = siteOfProbe[probe];
                }
            }
            for (Point& p : points) {
                p.avatar = world.create();
                world.emplace<Avatar>(p.avatar);
                world.emplace<WorldTransform>(p.avatar).matrix[3] = glm::vec4(p.x, 1.f);
            }
        }
        // Every avatar blended from its cell's corners, with the cell's masks computed and open:
        // the trilinear weights, untouched by visibility (the scene's own avatar is lit too).
        system.lightAvatars(world);
        for (Point& p : points) {
            glm::ivec3 cell;
            glm::vec3 t;
            grid.locate(p.x, cell, t);
            ASSERT_TRUE(volume.visibilityOpen(grid.cellIndex(cell)))
                << "a corner is hidden somewhere in the cell of " << p.x.x << "," << p.x.y << ","
                << p.x.z;
            p.probe.push_back(world.get<ShLighting>(p.avatar).coefficients);
        }
    }

    const Gather gather(world, scene);
    std::vector<glm::vec3> normals;
    for (std::uint32_t k = 0; k < kNormals; ++k)
        normals.push_back(sh::fibonacciDirection(k, kNormals));
    // Per site the projection; per node and normal the irradiance from cosine-weighted
    // directions (off the nodes it comes from the corners' projections).
    std::vector<Gather::Projection> projected(sites.size());
    std::vector<Estimate> gathered(points.size() * kNormals);
    tbb::parallel_for(std::size_t(0), sites.size() + gathered.size(), [&](std::size_t i) {
        if (i < sites.size()) {
            projected[i] = gather.projection(sites[i].x, normals, sites[i].samples, sites[i].key);
            return;
        }
        const std::size_t j = i - sites.size(), point = j / kNormals, k = j % kNormals;
        if (points[point].node)
            gathered[j] = gather.irradiance(points[point].x, normals[k], point * perPoint + 1 + k);
    });

    // Off the nodes, the corners' gathers blended with the test's trilinear weights: their
    // estimates are independent, so the variances add with the weights squared.
    const auto blend = [&](const Point& p, auto estimate) {
        Estimate out;
        glm::dvec3 variance(0.0);
        for (int c = 0; c < 8; ++c) {
            const Estimate e = estimate(projected[p.corners[c]]);
            out.mean += p.weights[c] * e.mean;
            variance += p.weights[c] * p.weights[c] * e.standardError * e.standardError;
        }
        out.standardError = glm::sqrt(variance);
        return out;
    };
    // The gather at a node, the corners' blend off the nodes.
    const auto referenceAt = [&](const Point& p, auto estimate) {
        return p.node ? estimate(projected[p.site]) : blend(p, estimate);
    };

    // A quantity of the SH (integral or irradiance along n) through its replicates, against
    // the reference's estimate of it. `worst` keeps the largest |difference| / bound.
    double worst = 0.0;
    const auto compare = [&](const Point& p, const Estimate& reference, auto quantity,
                             bool truncated, const char* what) {
        std::vector<glm::dvec3> values;
        for (const sh::ShRgb& L : p.probe)
            values.push_back(glm::dvec3(quantity(L)));
        const Estimate probe = replicateMean(values);
        glm::dvec3 integral(0.0);
        for (const sh::ShRgb& L : p.probe)
            integral += glm::dvec3(sh::integral(L));
        integral /= double(p.probe.size());
        const glm::dvec3 truncation =
            truncated ? double(sh::kDirectionalMaxError) * integral : glm::dvec3(0.0);
        for (int c = 0; c < 3; ++c) {
            const double bound = kProbeT * probe.standardError[c] +
                                 kGatherZ * reference.standardError[c] + truncation[c] +
                                 kBasisRounding * integral[c];
            worst = std::max(worst, std::abs(probe.mean[c] - reference.mean[c]) / bound);
            EXPECT_NEAR(probe.mean[c], reference.mean[c], bound)
                << what << " at " << p.x.x << "," << p.x.y << "," << p.x.z
                << (p.node ? " (node)" : " (corners' blend)") << " channel " << c
                << ": probe standard error " << probe.standardError[c] << ", reference "
                << reference.standardError[c] << ", truncation " << truncation[c];
        }
        return probe;
    };

    static const char* const kNames[sh::kCoefficientCount] = {"L00",  "L1-1", "L10", "L11", "L2-2",
                                                              "L2-1", "L20",  "L21", "L22"};
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Point& p = points[i];
        worst = 0.0;
        std::printf("point (%.3f %.3f %.3f)%s, green, probe (%s):", p.x.x, p.x.y, p.x.z,
                    p.node ? " node" : "     ", p.node ? "gather" : "corners' gather blended");
        Estimate l00Probe, l00Reference;
        for (int k = 0; k < sh::kCoefficientCount; ++k) {
            const Estimate ref =
                referenceAt(p, [k](const Gather::Projection& s) { return s.coefficients[k]; });
            const Estimate probe = compare(
                p, ref, [k](const sh::ShRgb& L) { return L[k]; }, false, kNames[k]);
            std::printf(" %s %.3f (%.3f)", kNames[k], probe.mean.g, ref.mean.g);
            if (k == 0) {
                l00Probe = probe;
                l00Reference = ref;
            }
        }
        std::printf("\n");
        double irradianceInterpolation = 0.0; // largest share, green, over the normals
        for (std::uint32_t k = 0; k < kNormals; ++k) {
            const glm::vec3 n = normals[k];
            const auto irradiance = [n](const sh::ShRgb& L) { return sh::irradiance(L, n); };
            // What the nine coefficients should give, with no truncation allowance; and the
            // true irradiance, with it.
            compare(p, referenceAt(p, [k](const Gather::Projection& s) { return s.orderTwo[k]; }),
                    irradiance, false, "order-2 irradiance");
            const Estimate trueIrradiance =
                p.node ? gathered[i * kNormals + k]
                       : blend(p, [k](const Gather::Projection& s) { return s.irradiance[k]; });
            compare(p, trueIrradiance, irradiance, true, "irradiance");
            if (!p.node) {
                const Estimate& direct = projected[p.site].irradiance[k];
                irradianceInterpolation =
                    std::max(irradianceInterpolation,
                             std::abs(direct.mean.g - trueIrradiance.mean.g) / direct.mean.g);
            }
        }
        std::printf("  largest |probe - reference| / bound %.2f\n", worst);
        if (p.node) continue;

        // The interpolation's own error: the light at the point (direct gather) against the
        // trilinear blend of the light at the corners. A figure, not a check.
        std::printf("  interpolation, green, direct gather - corners' blend:");
        for (int k = 0; k < sh::kCoefficientCount; ++k) {
            const Estimate blended =
                blend(p, [k](const Gather::Projection& s) { return s.coefficients[k]; });
            std::printf(" %s %+.3f", kNames[k],
                        projected[p.site].coefficients[k].mean.g - blended.mean.g);
        }
        std::printf("; irradiance up to %.1f %% over the normals\n",
                    100.0 * irradianceInterpolation);
        const double error = l00Probe.mean.g - l00Reference.mean.g;
        const double sigma = std::sqrt(l00Probe.standardError.g * l00Probe.standardError.g +
                                       l00Reference.standardError.g * l00Reference.standardError.g);
        const double interpolation = projected[p.site].coefficients[0].mean.g - l00Reference.mean.g;
        std::printf("  L00 green: probe - corners' blend %+.3f, standard error %.3f; interpolation "
                    "%+.3f (%+.1f %% of the direct gather)\n",
                    error, sigma, interpolation,
                    100.0 * interpolation / projected[p.site].coefficients[0].mean.g);
        const std::string name = "offNode" + std::to_string(i / 2) + "_";
        ::testing::Test::RecordProperty(name + "L00Error", std::to_string(error));
        ::testing::Test::RecordProperty(name + "L00StandardError", std::to_string(sigma));
        ::testing::Test::RecordProperty(name + "L00Interpolation", std::to_string(interpolation));
        ::testing::Test::RecordProperty(name + "IrradianceInterpolationShare",
                                        std::to_string(irradianceInterpolation));
        ::testing::Test::RecordProperty(name + "WorstErrorOverBound", std::to_string(worst));
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
            const Estimate& reference = normal == 0 ? projected[p.site].coefficients[0]
                                                    : projected[p.site].orderTwo[normal];
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
