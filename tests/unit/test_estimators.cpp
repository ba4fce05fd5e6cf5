// The estimators DETP is compared with (seed 000 section 2.6, seed 004 section 4): the photon
// map's kd-tree and k-nearest search, its border bias against DETP, and impact count.
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/detp/ImpactCounter.h"
#include "systems/detp/PhotonKdTree.h"
#include "systems/detp/ReceiverSet.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "systems/photon_update/PhotonStore.h"

#include "test_detp_world.h"
#include "test_meshes.h"

#include <gtest/gtest.h>

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <span>
#include <vector>

namespace qgi {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr double kPi = glm::pi<double>();
const glm::mat4 kIdentity{1.f};
using Photon = PhotonKdTree::Photon;

// ---- kd-tree ------------------------------------------------------------------------------

std::vector<Photon> randomPhotons(std::mt19937& rng, std::size_t n, glm::vec3 extent) {
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::vector<Photon> photons(n);
    for (Photon& p : photons) {
        p.position = glm::vec3(unit(rng), unit(rng), unit(rng)) * extent;
        p.power = glm::vec3(unit(rng));
        p.direction = unit(rng) < 0.5f ? glm::vec3(0.f, -1.f, 0.f) : glm::vec3(0.f, 1.f, 0.f);
    }
    return photons;
}

/// Digest seed 004 section 11.6: for the node of every range [lo, hi], everything on its left
/// is <= it and everything on its right >= it on its split axis, and that axis is the axis of
/// greatest extent of the range's bounding box.
void checkNode(const PhotonKdTree& tree, std::ptrdiff_t lo, std::ptrdiff_t hi, int& nodes) {
    if (hi < lo) return;
    const auto photons = tree.photons();
    const std::ptrdiff_t m = lo + (hi - lo) / 2;
    const int axis = tree.splitAxis(std::size_t(m));
    glm::vec3 low(kInf), high(-kInf);
    for (std::ptrdiff_t i = lo; i <= hi; ++i) {
        low = glm::min(low, photons[std::size_t(i)].position);
        high = glm::max(high, photons[std::size_t(i)].position);
    }
    const glm::vec3 extent = high - low;
    ASSERT_GE(extent[axis], std::max({extent.x, extent.y, extent.z})) << "node " << m;
    const float split = photons[std::size_t(m)].position[axis];
    for (std::ptrdiff_t i = lo; i < m; ++i)
        ASSERT_LE(photons[std::size_t(i)].position[axis], split) << "node " << m;
    for (std::ptrdiff_t i = m + 1; i <= hi; ++i)
        ASSERT_GE(photons[std::size_t(i)].position[axis], split) << "node " << m;
    ++nodes;
    checkNode(tree, lo, m - 1, nodes);
    checkNode(tree, m + 1, hi, nodes);
}

bool lessPosition(const Photon& a, const Photon& b) {
    return std::lexicographical_compare(&a.position.x, &a.position.x + 3, &b.position.x,
                                        &b.position.x + 3);
}

TEST(PhotonKdTree, BalancedLayoutInvariants) {
    std::mt19937 rng(1);
    // A flat box: the split axis must follow the extent, not cycle x, y, z.
    const std::vector<Photon> input = randomPhotons(rng, 5000, {4.f, 0.5f, 2.f});
    PhotonKdTree tree;
    tree.build(input);
    int nodes = 0;
    checkNode(tree, 0, std::ptrdiff_t(input.size()) - 1, nodes);
    EXPECT_EQ(nodes, 5000);

    // A permutation of the input.
    std::vector<Photon> sortedInput = input;
    std::vector<Photon> sortedTree(tree.photons().begin(), tree.photons().end());
    std::sort(sortedInput.begin(), sortedInput.end(), lessPosition);
    std::sort(sortedTree.begin(), sortedTree.end(), lessPosition);
    for (std::size_t i = 0; i < input.size(); ++i)
        ASSERT_EQ(sortedInput[i].position, sortedTree[i].position);
}

TEST(PhotonKdTree, OneDimensionalTreeIsSorted) {
    std::mt19937 rng(2);
    std::vector<Photon> photons = randomPhotons(rng, 1000, {1.f, 0.f, 0.f});
    PhotonKdTree tree;
    tree.build(photons);
    const auto out = tree.photons();
    for (std::size_t i = 1; i < out.size(); ++i)
        ASSERT_LE(out[i - 1].position.x, out[i].position.x);
}

/// The k nearest with squared distance < max2 that `accept` takes, by sorting all of them.
template <typename Accept>
std::vector<std::uint32_t> bruteNearest(std::span<const Photon> photons, const glm::vec3& c,
                                        std::size_t k, float max2, Accept accept) {
    std::vector<std::pair<float, std::uint32_t>> all;
    for (std::uint32_t i = 0; i < photons.size(); ++i) {
        const glm::vec3 d = photons[i].position - c;
        const float d2 = glm::dot(d, d);
        if (d2 < max2 && accept(photons[i])) all.push_back({d2, i});
    }
    std::sort(all.begin(), all.end());
    all.resize(std::min(all.size(), k));
    std::vector<std::uint32_t> out;
    for (const auto& a : all)
        out.push_back(a.second);
    std::sort(out.begin(), out.end());
    return out;
}

TEST(PhotonKdTree, NearestEqualsBruteForce) {
    std::mt19937 rng(3);
    PhotonKdTree tree;
    tree.build(randomPhotons(rng, 5000, {1.f, 1.f, 1.f}));
    std::uniform_real_distribution<float> query(-0.2f, 1.2f);
    const auto any = [](const Photon&) { return true; };
    const auto fromAbove = [](const Photon& p) { return p.direction.y < 0.f; };
    std::vector<PhotonKdTree::Neighbour> found;
    int full = 0, partial = 0;
    for (int q = 0; q < 300; ++q) {
        const glm::vec3 c(query(rng), query(rng), query(rng));
        for (const std::uint32_t k : {1u, 10u, 60u}) {
            for (const float max2 : {kInf, 0.003f}) {
                for (const bool filtered : {false, true}) {
                    const float r2 = filtered ? tree.nearest(c, k, max2, fromAbove, found)
                                              : tree.nearest(c, k, max2, any, found);
                    const auto expected = filtered
                                              ? bruteNearest(tree.photons(), c, k, max2, fromAbove)
                                              : bruteNearest(tree.photons(), c, k, max2, any);
                    std::vector<std::uint32_t> actual;
                    for (const auto& n : found)
                        actual.push_back(n.index);
                    std::sort(actual.begin(), actual.end());
                    ASSERT_EQ(actual, expected) << "query " << q << " k " << k;
                    // The returned radius: the k-th distance, or the cap when fewer were found.
                    if (found.size() == k) {
                        ++full;
                        float farthest = 0.f;
                        for (const auto& n : found)
                            farthest = std::max(farthest, n.distance2);
                        EXPECT_EQ(r2, farthest);
                        EXPECT_EQ(found.front().distance2, farthest); // max-heap head
                    } else {
                        ++partial;
                        EXPECT_EQ(r2, max2);
                    }
                }
            }
        }
    }
    EXPECT_GT(full, 1000);
    EXPECT_GT(partial, 100);
}

// ---- scenes for the estimators -------------------------------------------------------------

using test::addDetpResources;
using test::addReceiverMesh;
using test::gridMesh;

void pushSegment(PhotonSegments& s, glm::vec3 origin, glm::vec3 direction, float length,
                 glm::vec3 power, Entity hit, std::uint32_t primitive, std::uint8_t bounce) {
    s.origin.push_back(origin);
    s.direction.push_back(direction);
    s.length.push_back(length);
    s.power.push_back(power);
    s.hitEntity.push_back(hit);
    s.hitPrimitive.push_back(primitive);
    s.bounce.push_back(bounce);
}

// ---- photon map border bias ---------------------------------------------------------------

TEST(PhotonMap, BorderBiasAgainstDetp) {
    // Collimated light of 1 W/m^2 straight down on a black unit square (10 x 10 quads at y = 0),
    // from a beam over [-0.5, 1.5]^2: photons beside the square pass it and leave the scene.
    constexpr std::size_t kPhotons = 1'000'000;
    constexpr double kIrradiance = 1.0, kBeamArea = 4.0;
    Registry registry;
    addDetpResources(registry);
    const Entity square =
        addReceiverMesh(registry, gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 10),
                        kIdentity, false);
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<float> beam(-0.5f, 1.5f);
    const glm::vec3 power(float(kIrradiance * kBeamArea / double(kPhotons)));
    for (std::size_t i = 0; i < kPhotons; ++i) {
        const glm::vec3 o(beam(rng), 1.f, beam(rng));
        const bool hits = o.x >= 0.f && o.x <= 1.f && o.z >= 0.f && o.z <= 1.f;
        store.paths.push_back({std::uint32_t(i), 1, 0});
        pushSegment(store.segments, o, {0.f, -1.f, 0.f}, hits ? 1.f : kInf, power,
                    hits ? square : Entity{}, 0, 0);
    }
    // Vertex (i, j) of the grid sits at (x, z) = (j / 10, i / 10).
    const std::uint32_t corner = 0, edge = 5, interior = 5 * 11 + 5;

    // k-NN photon map: the k nearest hit points fill a quarter disc at a corner and half a disc
    // on an edge, so the estimate tends to E/4 and E/2. With Poisson hit points, sigma pi r_k^2
    // (sigma the density, over the region's share of the disc) is Gamma(k)-distributed, so the
    // estimate k / (pi r_k^2) has mean (share E) k / (k - 1) and standard deviation
    // (share E) k / ((k - 1) sqrt(k - 2)).
    constexpr std::uint32_t kNeighbours = 400;
    DetpSettings pm;
    pm.estimator = IrradianceEstimator::PhotonMap;
    pm.discRadius = 0.05f;
    pm.photonMapNeighbours = kNeighbours;
    pm.photonMapMaxRadius = 0.3f;
    DetpIrradianceSystem photonMap(pm);
    photonMap.build(registry);
    photonMap.update(registry, {});
    const auto& values = registry.get<VertexIrradiance>(square).irradiance;
    const double k = kNeighbours;
    for (const auto& [vertex, share] :
         {std::pair{corner, 0.25}, std::pair{edge, 0.5}, std::pair{interior, 1.0}}) {
        const double mean = share * kIrradiance * k / (k - 1.0);
        const double sigma = mean / std::sqrt(k - 2.0);
        EXPECT_NEAR(values[vertex].x, mean, 4.0 * sigma) << "vertex " << vertex;
    }

    // DETP with the beam wider than the square: every photon that crosses the disc counts,
    // landed or not. The count is binomial(N, pi r^2 / beam area): E within 4 sigma everywhere.
    DetpSettings detp;
    detp.discRadius = 0.05f;
    DetpIrradianceSystem tangentPlane(detp);
    tangentPlane.build(registry);
    tangentPlane.update(registry, {});
    const double p = kPi * 0.05 * 0.05 / kBeamArea;
    const double sigma = kIrradiance * std::sqrt((1.0 - p) / (double(kPhotons) * p));
    for (const std::uint32_t vertex : {corner, edge, interior})
        EXPECT_NEAR(values[vertex].x, kIrradiance, 4.0 * sigma) << "vertex " << vertex;
}

// ---- impact count -------------------------------------------------------------------------

struct ImpactWorld {
    Registry registry;
    Entity floor, plate, other;
    ReceiverSet receivers;

    ImpactWorld() {
        addDetpResources(registry);
        floor = addReceiverMesh(registry,
                                gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}, 10),
                                kIdentity, false);
        plate = addReceiverMesh(registry,
                                gridMesh({0.f, 0.f, 0.f}, {0.f, 0.f, 0.2f}, {0.2f, 0.f, 0.f}, 4),
                                glm::translate(kIdentity, {0.4f, 0.3f, 0.4f}), true);
        other = registry.create(); // hit by photons but not a receiver: an avatar, say
        receivers.build(registry);
    }

    /// Random segments: 70% hit a receiver triangle, 10% the non-receiver, 20% nothing.
    PhotonSegments randomSegments(std::mt19937& rng, std::size_t n) const {
        std::uniform_real_distribution<float> unit(0.f, 1.f);
        PhotonSegments s;
        for (std::size_t i = 0; i < n; ++i) {
            const float u = unit(rng);
            const glm::vec3 power(unit(rng), unit(rng), unit(rng));
            const auto bounce = std::uint8_t(unit(rng) * 3.f);
            if (u < 0.5f)
                pushSegment(s, {}, {0.f, -1.f, 0.f}, 1.f, power, floor,
                            std::uint32_t(unit(rng) * 199.99f), bounce);
            else if (u < 0.7f)
                pushSegment(s, {}, {0.f, -1.f, 0.f}, 1.f, power, plate,
                            std::uint32_t(unit(rng) * 31.99f), bounce);
            else if (u < 0.8f)
                pushSegment(s, {}, {0.f, -1.f, 0.f}, 1.f, power, other, 0, bounce);
            else
                pushSegment(s, {}, {0.f, 1.f, 0.f}, kInf, power, {}, 0, bounce);
        }
        return s;
    }

    bool isReceiver(Entity e) const { return e == floor || e == plate; }
};

std::vector<std::uint32_t> allIndices(const PhotonSegments& s) {
    std::vector<std::uint32_t> out(s.size());
    std::iota(out.begin(), out.end(), 0u);
    return out;
}

glm::dvec3 totalPower(const ImpactCounter& counter) {
    glm::dvec3 total(0.0);
    for (std::uint32_t t = 0; t < counter.triangleCount(); ++t)
        total += counter.trianglePower(t);
    return total;
}

DetpSettings impactCountSettings() {
    DetpSettings settings;
    settings.estimator = IrradianceEstimator::ImpactCount;
    settings.discRadius = 0.05f;
    return settings;
}

TEST(ImpactCount, EnergyBookkeepingThroughAddAndSubtract) {
    ImpactWorld world;
    std::mt19937 rng(8);
    ImpactCounter counter;
    counter.reset(world.receivers);

    // The current set, as (segment set, index) pairs, and the bookkeeping reference.
    std::vector<PhotonSegments> sets;
    std::vector<std::vector<bool>> alive;
    const auto expected = [&] {
        glm::dvec3 total(0.0);
        for (std::size_t k = 0; k < sets.size(); ++k)
            for (std::size_t s = 0; s < sets[k].size(); ++s)
                if (alive[k][s] && world.isReceiver(sets[k].hitEntity[s]))
                    total += glm::dvec3(sets[k].power[s]);
        return total;
    };
    std::size_t additions = 0;
    // Each side is a sum of at most `additions` terms of magnitude <= 1 W: the two differ by
    // at most 2 x additions^2 x 2^-53 W (the standard bound for recursive summation).
    const auto tolerance = [&] { return 2.0 * double(additions) * double(additions) * 0x1p-53; };

    sets.push_back(world.randomSegments(rng, 5000));
    alive.emplace_back(sets.back().size(), true);
    counter.accumulate(world.receivers, sets.back(), allIndices(sets.back()), 1.0);
    additions += 5000;
    for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(totalPower(counter)[c], expected()[c], tolerance());

    for (int round = 0; round < 20; ++round) {
        // Subtract a random subset of what is alive (the old suffixes), add new segments.
        std::uniform_int_distribution<std::size_t> pickSet(0, sets.size() - 1);
        const std::size_t k = pickSet(rng);
        std::vector<std::uint32_t> removed;
        for (std::uint32_t s = 0; s < sets[k].size(); ++s)
            if (alive[k][s] && rng() % 4 == 0) {
                removed.push_back(s);
                alive[k][s] = false;
            }
        counter.accumulate(world.receivers, sets[k], removed, -1.0);
        sets.push_back(world.randomSegments(rng, 300));
        alive.emplace_back(sets.back().size(), true);
        counter.accumulate(world.receivers, sets.back(), allIndices(sets.back()), 1.0);
        additions += removed.size() + 300;
        for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(totalPower(counter)[c], expected()[c], tolerance()) << "round " << round;
    }
    EXPECT_GT(expected().x, 100.0);
}

TEST(ImpactCount, AMobileTakenOutOfTheLightHoldsExactlyZero) {
    // Impacts of 1, 1e8 and 0.01 W on one plate triangle, subtracted in the order they were
    // added, leave 5.6e-9 W in double. The plate is taken out of the light in that frame
    // (MobileMesh::active): it must read zero, not the rounding.
    ImpactWorld world;
    Registry& registry = world.registry;
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    for (const float power : {1.f, 1e8f, 0.01f}) {
        store.paths.push_back({std::uint32_t(store.segments.size()), 1, 0});
        pushSegment(store.segments, {}, {0.f, -1.f, 0.f}, 1.f, glm::vec3(power), world.plate, 0, 0);
    }
    const DetpSettings settings = impactCountSettings();
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});
    registry.clearChanges();
    const auto& plate = registry.get<VertexIrradiance>(world.plate).irradiance;
    ASSERT_GT(plate[0].x, 0.f); // triangle 0's corner

    // Every path leaves the scene instead, and the plate is out.
    PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
    delta = PhotonDelta{};
    delta.oldFirst = {0};
    delta.newFirst = {0};
    for (std::uint32_t p = 0; p < 3; ++p) {
        delta.paths.push_back(p);
        delta.oldSegments.appendFrom(store.segments, store.paths[p].first);
        pushSegment(delta.newSegments, {}, {0.f, 1.f, 0.f}, kInf, glm::vec3(1.f), {}, 0, 0);
        delta.oldFirst.push_back(p + 1);
        delta.newFirst.push_back(p + 1);
        store.paths[p].first = std::uint32_t(store.segments.size());
        store.segments.appendFrom(delta.newSegments, p);
    }
    delta.movedMobiles = {world.plate};
    registry.patch<MobileMesh>(world.plate).active = false;
    system.update(registry, {});
    ASSERT_FALSE(system.lastFrame().full);
    for (std::size_t v = 0; v < plate.size(); ++v)
        EXPECT_EQ(plate[v], glm::vec3(0.f)) << "vertex " << v;
}

TEST(ImpactCount, VertexIsTheAreaWeightedMeanOfItsTriangles) {
    ImpactWorld world;
    ImpactCounter counter;
    counter.reset(world.receivers);
    PhotonSegments s;
    // Floor triangles 0 and 1 share floor vertex 0's corner cell; each has area 0.005 m^2.
    pushSegment(s, {}, {0.f, -1.f, 0.f}, 1.f, {2.f, 0.f, 0.f}, world.floor, 0, 1);
    pushSegment(s, {}, {0.f, -1.f, 0.f}, 1.f, {0.f, 3.f, 0.f}, world.floor, 1, 2);
    counter.accumulate(world.receivers, s, allIndices(s), 1.0);
    std::vector<std::uint32_t> touched;
    counter.takeTouchedVertices(touched);
    // Triangle 0 = (0, 11, 12), triangle 1 = (0, 12, 1) of the 11 x 11 vertex grid.
    EXPECT_EQ(touched, (std::vector<std::uint32_t>{0, 1, 11, 12}));
    // Vertex 0 touches exactly triangles 0 and 1: (2 + 3 W) over 0.01 m^2.
    EXPECT_FLOAT_EQ(counter.irradiance(0).x, 200.f);
    EXPECT_FLOAT_EQ(counter.irradiance(0).y, 300.f);
    EXPECT_FLOAT_EQ(counter.irradiance(0).z, 0.f);
    // Vertex 12 has six triangles (0.03 m^2) around it, two of them lit.
    EXPECT_FLOAT_EQ(counter.irradiance(12).x, float(2.0 / 0.03));
}

TEST(ImpactCount, SystemIncrementalEqualsFull) {
    ImpactWorld world;
    Registry& registry = world.registry;
    std::mt19937 rng(21);
    PhotonStore& store = registry.ctx().get<PhotonStore>();
    const PhotonSegments initial = world.randomSegments(rng, 4000);
    for (std::uint32_t s = 0; s < initial.size(); ++s) {
        store.paths.push_back({s, 1, 0});
        store.segments.appendFrom(initial, s);
    }
    const DetpSettings settings = impactCountSettings();
    DetpIrradianceSystem system(settings);
    system.build(registry);
    system.update(registry, {});

    std::size_t additions = initial.size();
    for (int frame = 0; frame < 100; ++frame) {
        // Re-trace a few one-segment paths: the old segment out, a new random one in.
        PhotonDelta& delta = registry.ctx().get<PhotonDelta>();
        delta = PhotonDelta{};
        delta.oldFirst = {0};
        delta.newFirst = {0};
        const PhotonSegments fresh = world.randomSegments(rng, 10);
        for (std::uint32_t i = 0; i < fresh.size(); ++i) {
            const auto p = std::uint32_t(rng() % store.paths.size());
            if (std::find(delta.paths.begin(), delta.paths.end(), p) != delta.paths.end()) continue;
            delta.paths.push_back(p);
            delta.oldSegments.appendFrom(store.segments, store.paths[p].first);
            delta.newSegments.appendFrom(fresh, i);
            delta.oldFirst.push_back(std::uint32_t(delta.oldSegments.size()));
            delta.newFirst.push_back(std::uint32_t(delta.newSegments.size()));
            store.paths[p].first = std::uint32_t(store.segments.size());
            store.segments.appendFrom(fresh, i);
        }
        additions += 2 * delta.paths.size();
        system.update(registry, {});
        ASSERT_FALSE(system.lastFrame().full);
    }
    const auto floorInc = registry.get<VertexIrradiance>(world.floor).irradiance;
    const auto plateInc = registry.get<VertexIrradiance>(world.plate).irradiance;
    DetpIrradianceSystem reference(settings);
    reference.build(registry);
    reference.update(registry, {});
    ASSERT_TRUE(reference.lastFrame().full);

    // Per triangle, the two double sums differ by at most 2 n^2 2^-53 W (n additions of at
    // most 1 W); a vertex divides the sum over at most 6 triangles by its ring's area, at least
    // one plate triangle (0.00125 m^2), then rounds to float (2^-24 relative each way).
    const double n = double(additions);
    const double absolute = 6.0 * 2.0 * n * n * 0x1p-53 / 0.00125;
    for (const auto& [incremental, e] :
         {std::pair{&floorInc, world.floor}, std::pair{&plateInc, world.plate}}) {
        const auto& full = registry.get<VertexIrradiance>(e).irradiance;
        for (std::size_t v = 0; v < full.size(); ++v)
            for (int c = 0; c < 3; ++c)
                ASSERT_NEAR((*incremental)[v][c], full[v][c],
                            std::ldexp(double(std::abs(full[v][c])), -23) + absolute)
                    << "vertex " << v;
    }
}

} // namespace
} // namespace qgi
