#include "systems/detp/DiscIndex.h"

#include "runtime/core/Error.h"
#include "runtime/raytrace/EmbreeDevice.h"
#include "systems/detp/DiscCrossing.h"
#include "systems/photon_update/PhotonStore.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

namespace qgi {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

glm::vec3 randomUnit(std::mt19937& rng) {
    std::normal_distribution<float> normal;
    glm::vec3 v;
    do {
        v = {normal(rng), normal(rng), normal(rng)};
    } while (glm::dot(v, v) < 1e-6f);
    return glm::normalize(v);
}

void addSegment(PhotonSegments& s, const glm::vec3& origin, const glm::vec3& direction,
                float length, std::uint8_t bounce) {
    s.origin.push_back(origin);
    s.direction.push_back(direction);
    s.length.push_back(length);
    s.power.push_back(glm::vec3(1.f));
    s.hitEntity.push_back(std::isinf(length) ? Entity{} : Entity{0, 0});
    s.hitPrimitive.push_back(0);
    s.bounce.push_back(bounce);
}

struct Discs {
    std::vector<glm::vec3> centers;
    std::vector<glm::vec3> normals;
};

Discs randomDiscs(std::mt19937& rng, std::size_t n) {
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    Discs discs;
    for (std::size_t i = 0; i < n; ++i) {
        discs.centers.push_back({unit(rng), unit(rng), unit(rng)});
        discs.normals.push_back(randomUnit(rng));
    }
    return discs;
}

/// Three kinds, a third each: segments that left the scene (length +inf), segments of random
/// length, and segments that end on a disc's plane near the disc (as a photon landing on the
/// vertex's own surface does), from either side.
PhotonSegments randomSegments(std::mt19937& rng, const Discs& discs, float radius, std::size_t n) {
    std::uniform_real_distribution<float> box(-0.2f, 1.2f);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::uniform_int_distribution<std::size_t> pick(0, discs.centers.size() - 1);
    std::uniform_int_distribution<int> bounce(0, 2);
    PhotonSegments segments;
    for (std::size_t i = 0; i < n; ++i) {
        const auto b = std::uint8_t(bounce(rng));
        if (i % 3 == 0) {
            addSegment(segments, {box(rng), box(rng), box(rng)}, randomUnit(rng), kInf, b);
        } else if (i % 3 == 1) {
            addSegment(segments, {box(rng), box(rng), box(rng)}, randomUnit(rng), 1.5f * unit(rng),
                       b);
        } else {
            const std::size_t j = pick(rng);
            // A point of the disc's plane within 1.2 r of its centre: inside and just outside.
            const glm::vec3 tangent = glm::normalize(glm::cross(discs.normals[j], randomUnit(rng)));
            const glm::vec3 end =
                discs.centers[j] + (1.2f * radius * std::sqrt(unit(rng))) * tangent;
            const glm::vec3 d = randomUnit(rng);
            const float length = 0.1f + unit(rng);
            addSegment(segments, end - length * d, d, length, b);
        }
    }
    return segments;
}

std::vector<DiscCrossing> bruteForce(const PhotonSegments& segments,
                                     const std::vector<std::uint32_t>& indices, const Discs& discs,
                                     float radius) {
    std::vector<DiscCrossing> out;
    for (const std::uint32_t s : indices) {
        for (std::uint32_t d = 0; d < discs.centers.size(); ++d)
            if (crossesDisc(segments.origin[s], segments.direction[s], segments.length[s],
                            discs.centers[d], discs.normals[d], radius))
                out.push_back({s, d});
    }
    return out;
}

bool operator==(const DiscCrossing& a, const DiscCrossing& b) {
    return a.segment == b.segment && a.disc == b.disc;
}

void expectSamePairs(const std::vector<DiscCrossing>& actual,
                     const std::vector<DiscCrossing>& expected) {
    ASSERT_EQ(actual.size(), expected.size());
    for (std::size_t i = 0; i < actual.size(); ++i)
        ASSERT_TRUE(actual[i] == expected[i])
            << "pair " << i << ": index (" << actual[i].segment << ", " << actual[i].disc
            << "), brute force (" << expected[i].segment << ", " << expected[i].disc << ")";
}

TEST(DetpCrossing, CountsOnlySegmentsFromTheFront) {
    const glm::vec3 center(0.f), up(0.f, 0.f, 1.f);
    // Straight down through the centre: from the front. Straight up: from behind.
    EXPECT_TRUE(crossesDisc({0.f, 0.f, 1.f}, {0.f, 0.f, -1.f}, 2.f, center, up, 0.1f));
    EXPECT_FALSE(crossesDisc({0.f, 0.f, -1.f}, {0.f, 0.f, 1.f}, 2.f, center, up, 0.1f));
    // Parallel to the plane, in it: never a crossing.
    EXPECT_FALSE(crossesDisc({-1.f, 0.f, 0.f}, {1.f, 0.f, 0.f}, 2.f, center, up, 0.1f));
}

TEST(DetpCrossing, SegmentRangeAndRadius) {
    const glm::vec3 center(0.f), up(0.f, 0.f, 1.f), down(0.f, 0.f, -1.f);
    // Escaped segments count; a segment that stops short of the plane does not.
    EXPECT_TRUE(crossesDisc({0.f, 0.f, 1.f}, down, kInf, center, up, 0.1f));
    EXPECT_FALSE(crossesDisc({0.f, 0.f, 1.f}, down, 0.9f, center, up, 0.1f));
    // Landing on the plane counts, with the documented slack past the end but no more.
    EXPECT_TRUE(crossesDisc({0.f, 0.f, 1.f}, down, 1.f, center, up, 0.1f));
    EXPECT_TRUE(crossesDisc({0.f, 0.f, 1.f}, down, 1.f - 0.5f * kDiscEndTolerance * 0.1f, center,
                            up, 0.1f));
    EXPECT_FALSE(
        crossesDisc({0.f, 0.f, 1.f}, down, 1.f - 2.f * kDiscEndTolerance * 0.1f, center, up, 0.1f));
    // A segment that starts below the plane never reaches it.
    EXPECT_FALSE(crossesDisc({0.f, 0.f, -0.5f}, down, kInf, center, up, 0.1f));
    // A length that is not a number is no segment: never a crossing.
    EXPECT_FALSE(crossesDisc({0.f, 0.f, 1.f}, down, std::nanf(""), center, up, 0.1f));
    // Radius: inclusive at r, exclusive beyond.
    EXPECT_TRUE(crossesDisc({0.0999f, 0.f, 1.f}, down, 2.f, center, up, 0.1f));
    EXPECT_FALSE(crossesDisc({0.1001f, 0.f, 1.f}, down, 2.f, center, up, 0.1f));
}

TEST(DetpDiscIndex, FrontSideRuleThroughEmbree) {
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    const std::vector<glm::vec3> centers{{0.f, 0.f, 0.f}};
    const std::vector<glm::vec3> normals{{0.f, 0.f, 1.f}};
    index.build(centers, normals, 0.1f);
    PhotonSegments segments;
    addSegment(segments, {0.f, 0.f, 1.f}, {0.f, 0.f, -1.f}, kInf, 1);  // from the front
    addSegment(segments, {0.f, 0.f, -1.f}, {0.f, 0.f, 1.f}, kInf, 1);  // from behind
    addSegment(segments, {0.05f, 0.f, 1.f}, {0.f, 0.f, -1.f}, 1.f, 1); // lands on the disc
    const std::vector<std::uint32_t> indices{0, 1, 2};
    std::vector<DiscCrossing> out;
    index.collectCrossings(segments, indices, out);
    ASSERT_EQ(out.size(), 2u);
    EXPECT_EQ(out[0].segment, 0u);
    EXPECT_EQ(out[1].segment, 2u);
}

TEST(DiscIndexVsBruteForce, SamePairsInTheSameOrder) {
    std::mt19937 rng(20240611);
    constexpr float kRadius = 0.05f;
    const Discs discs = randomDiscs(rng, 3000);
    const PhotonSegments segments = randomSegments(rng, discs, kRadius, 6000);
    // A shuffled subset of the segments: the index must map positions back to segments.
    std::vector<std::uint32_t> indices(segments.size());
    std::iota(indices.begin(), indices.end(), 0u);
    std::shuffle(indices.begin(), indices.end(), rng);
    indices.resize(5000);

    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    std::vector<DiscCrossing> actual;
    index.collectCrossings(segments, indices, actual);
    const std::vector<DiscCrossing> expected = bruteForce(segments, indices, discs, kRadius);
    expectSamePairs(actual, expected);

    // The comparison covers every kind of segment: escaped ones and landings on a disc plane.
    std::size_t escaped = 0, landed = 0;
    for (const DiscCrossing& c : expected) {
        if (std::isinf(segments.length[c.segment])) ++escaped;
        if (c.segment % 3 == 2) ++landed;
    }
    EXPECT_GT(escaped, 100u);
    EXPECT_GT(landed, 100u);
}

TEST(DetpDiscIndex, CrossingsBeyondALengthAreThoseACutCopyMisses) {
    std::mt19937 rng(31);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    constexpr float kRadius = 0.05f;
    const Discs discs = randomDiscs(rng, 2000);
    const PhotonSegments segments = randomSegments(rng, discs, kRadius, 6000);
    std::vector<std::uint32_t> indices(segments.size());
    std::iota(indices.begin(), indices.end(), 0u);
    // Cut lengths: none (-inf), inside the segment, and right at its end.
    std::vector<float> beyond(segments.size());
    for (std::size_t s = 0; s < beyond.size(); ++s) {
        const float length = std::isinf(segments.length[s]) ? 2.f : segments.length[s];
        beyond[s] = s % 3 == 0 ? -kInf : s % 3 == 1 ? length * unit(rng) : segments.length[s];
    }
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    std::vector<DiscCrossing> actual;
    index.collectCrossings(segments, indices, actual, beyond);

    std::vector<DiscCrossing> expected;
    std::size_t cut = 0;
    for (const DiscCrossing& c : bruteForce(segments, indices, discs, kRadius)) {
        const std::uint32_t s = c.segment;
        if (crossesDisc(segments.origin[s], segments.direction[s], beyond[s], discs.centers[c.disc],
                        discs.normals[c.disc], kRadius)) {
            ++cut;
            continue;
        }
        expected.push_back(c);
    }
    EXPECT_GT(cut, 200u);
    expectSamePairs(actual, expected);
}

TEST(DetpDiscIndex, MovedDiscsMatchBruteForce) {
    std::mt19937 rng(7);
    constexpr float kRadius = 0.04f;
    Discs discs = randomDiscs(rng, 500);
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Moving);
    index.build(discs.centers, discs.normals, kRadius);
    for (int step = 0; step < 3; ++step) {
        for (glm::vec3& c : discs.centers)
            c += glm::vec3(0.1f, -0.05f, 0.02f);
        for (glm::vec3& n : discs.normals)
            n = randomUnit(rng);
        index.move(discs.centers, discs.normals);
        const PhotonSegments segments = randomSegments(rng, discs, kRadius, 3000);
        std::vector<std::uint32_t> indices(segments.size());
        std::iota(indices.begin(), indices.end(), 0u);
        std::vector<DiscCrossing> actual;
        index.collectCrossings(segments, indices, actual);
        const auto expected = bruteForce(segments, indices, discs, kRadius);
        EXPECT_GT(expected.size(), 500u);
        expectSamePairs(actual, expected);
    }
}

/// Discs of architecture: a floor lattice with a hole (z = 0, up), a wall (x = 0.6, facing
/// -x), the two faces of a slab (z = 0.4: up and down, the same coordinate), a plane with too
/// few discs to become a patch, and tilted discs among them.
Discs axisAlignedDiscs(std::mt19937& rng) {
    std::uniform_real_distribution<float> jitter(-0.01f, 0.01f), unit(0.f, 1.f);
    Discs discs;
    const auto add = [&](const glm::vec3& c, const glm::vec3& n) {
        discs.centers.push_back(c);
        discs.normals.push_back(n);
    };
    for (int i = 0; i < 30; ++i)
        for (int j = 0; j < 30; ++j) {
            const float x = -0.2f + 0.04f * float(i), y = -0.2f + 0.04f * float(j);
            if (x > 0.3f && x < 0.6f && y > 0.3f && y < 0.6f) continue; // the hole
            add({x + jitter(rng), y + jitter(rng), 0.f}, {0.f, 0.f, 1.f});
        }
    for (int i = 0; i < 400; ++i)
        add({0.6f, unit(rng), unit(rng)}, {-1.f, 0.f, 0.f});
    for (int i = 0; i < 300; ++i) {
        add({unit(rng), unit(rng), 0.4f}, {0.f, 0.f, 1.f});
        add({unit(rng), unit(rng), 0.4f}, {0.f, 0.f, -1.f});
    }
    for (int i = 0; i < 5; ++i)
        add({unit(rng), 0.9f, unit(rng)}, {0.f, 1.f, 0.f});
    for (int i = 0; i < 300; ++i)
        add({unit(rng), unit(rng), unit(rng)}, randomUnit(rng));
    return discs;
}

TEST(DetpDiscIndex, AxisAlignedPlanesMatchBruteForce) {
    std::mt19937 rng(77);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    constexpr float kRadius = 0.05f;
    const Discs discs = axisAlignedDiscs(rng);
    PhotonSegments segments = randomSegments(rng, discs, kRadius, 9000);
    // Grazing landings on the planes (the crossing point is most sensitive to rounding there),
    // landings right at a rim, and segments from a light 300 m away.
    std::uniform_int_distribution<std::size_t> pick(0, discs.centers.size() - 1);
    for (int i = 0; i < 3000; ++i) {
        const std::size_t j = pick(rng);
        const glm::vec3 n = discs.normals[j];
        const glm::vec3 tangent = glm::normalize(glm::cross(n, randomUnit(rng)));
        if (i % 3 == 0) {
            const glm::vec3 end = discs.centers[j] + (1.1f * kRadius * unit(rng)) * tangent;
            const glm::vec3 d = glm::normalize(tangent - (1e-3f + 1e-2f * unit(rng)) * n);
            addSegment(segments, end - 0.5f * d, d, 0.5f, 1);
        } else if (i % 3 == 1) {
            const glm::vec3 end = discs.centers[j] + kRadius * tangent;
            const glm::vec3 d = glm::normalize(-n + 0.5f * randomUnit(rng));
            addSegment(segments, end - 0.3f * d, d, 0.3f, 1);
        } else {
            const glm::vec3 d = glm::normalize(-n + 0.3f * randomUnit(rng));
            addSegment(segments, discs.centers[j] - 300.f * d, d, kInf, 1);
        }
    }
    std::vector<std::uint32_t> indices(segments.size());
    std::iota(indices.begin(), indices.end(), 0u);
    std::shuffle(indices.begin(), indices.end(), rng);

    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    // Floor, wall and the two faces of the slab are patches; the five discs and the tilted
    // ones stay points.
    EXPECT_EQ(index.planeCount(), 4u);
    EXPECT_EQ(index.planarDiscCount(), discs.centers.size() - 305);
    std::vector<DiscCrossing> actual;
    index.collectCrossings(segments, indices, actual);
    const std::vector<DiscCrossing> expected = bruteForce(segments, indices, discs, kRadius);
    EXPECT_GT(expected.size(), 20000u);
    expectSamePairs(actual, expected);

    // Cut copies: the crossings beyond a length, on the planes too.
    std::vector<float> beyond(indices.size());
    for (std::size_t k = 0; k < indices.size(); ++k) {
        const float length = segments.length[indices[k]];
        beyond[k] = k % 2 == 0 ? -kInf : (std::isinf(length) ? 2.f : length) * unit(rng);
    }
    index.collectCrossings(segments, indices, actual, beyond);
    std::vector<DiscCrossing> cutExpected;
    for (const DiscCrossing& c : expected) {
        const std::size_t k =
            std::size_t(std::find(indices.begin(), indices.end(), c.segment) - indices.begin());
        if (!crossesDisc(segments.origin[c.segment], segments.direction[c.segment], beyond[k],
                         discs.centers[c.disc], discs.normals[c.disc], kRadius))
            cutExpected.push_back(c);
    }
    EXPECT_LT(cutExpected.size(), expected.size());
    expectSamePairs(actual, cutExpected);
}

// Segments from 10 and 30 km away (200,000 and 600,000 radii): Embree traces them from where
// they enter the discs' box and the plane lookup's margin covers the rule's rounding, so the
// result is still the brute-force set. (Point discs have only Embree's 1% widening to spare:
// they are exact up to about ten thousand radii, as the test above checks at 300 m.)
TEST(DetpDiscIndex, PlanePatchesStayExactForSegmentsFromFarAway) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    constexpr float kRadius = 0.05f;
    Discs discs;
    for (int i = 0; i < 600; ++i) {
        discs.centers.push_back({unit(rng), unit(rng), 0.f});
        discs.normals.push_back({0.f, 0.f, 1.f});
        discs.centers.push_back({0.f, unit(rng), unit(rng)});
        discs.normals.push_back({1.f, 0.f, 0.f});
    }
    PhotonSegments segments;
    for (int i = 0; i < 4000; ++i) {
        const std::size_t j = std::size_t(i) % discs.centers.size();
        const glm::vec3 d = glm::normalize(-discs.normals[j] + 0.3f * randomUnit(rng));
        const float distance = i % 2 == 0 ? 1e4f : 3e4f;
        addSegment(segments, discs.centers[j] - distance * d, d, i % 3 == 0 ? distance : kInf, 1);
    }
    std::vector<std::uint32_t> indices(segments.size());
    std::iota(indices.begin(), indices.end(), 0u);
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    ASSERT_EQ(index.planarDiscCount(), discs.centers.size());
    ASSERT_TRUE(index.direct()); // through the plane sieve
    std::vector<DiscCrossing> actual;
    index.collectCrossings(segments, indices, actual);
    const std::vector<DiscCrossing> expected = bruteForce(segments, indices, discs, kRadius);
    EXPECT_GT(expected.size(), 4000u);
    expectSamePairs(actual, expected);
}

/// Discs on tilted planes as a refined mesh gives them: centres computed in float on the plane
/// (so off it by rounding) and normals that differ from the face's in their last bits. A
/// block turned about two axes (five faces; the bottom is left out) and a wall parallel to one
/// of its faces 2 cm behind it; with `rough`, also a face too noisy to be a plane (normals 1e-3
/// apart).
constexpr std::size_t kTiltedPlanarDiscs = 6 * 15 * 15; // listed first

Discs tiltedDiscs(std::mt19937& rng, const glm::vec3& origin, const glm::mat3& turn, bool rough,
                  float normalNoise = 2e-7f) {
    std::uniform_real_distribution<float> noise(-1.f, 1.f);
    Discs discs;
    const auto face = [&](const glm::vec3& corner, const glm::vec3& a, const glm::vec3& b,
                          int steps, float spread) {
        const glm::vec3 n = glm::normalize(glm::cross(a, b));
        for (int i = 0; i <= steps; ++i)
            for (int j = 0; j <= steps; ++j) {
                const float fi = float(i) / float(steps), fj = float(j) / float(steps);
                discs.centers.push_back(origin + turn * (corner + fi * a + fj * b));
                const glm::vec3 jitter(noise(rng), noise(rng), noise(rng));
                discs.normals.push_back(glm::normalize(turn * n + spread * jitter));
            }
    };
    const glm::vec3 x(0.3f, 0.f, 0.f), y(0.f, 0.3f, 0.f), z(0.f, 0.f, 0.3f);
    face({0.f, 0.f, 0.3f}, x, y, 14, normalNoise);   // +z
    face({0.f, 0.f, 0.f}, y, x, 14, normalNoise);    // -z
    face({0.3f, 0.f, 0.f}, y, z, 14, normalNoise);   // +x
    face({0.f, 0.f, 0.f}, z, y, 14, normalNoise);    // -x
    face({0.f, 0.3f, 0.f}, z, x, 14, normalNoise);   // +y
    face({0.f, 0.f, -0.02f}, y, x, 14, normalNoise); // the wall behind -z, facing the same way
    if (rough) face({-0.3f, 0.f, 0.f}, z, y, 6, 1e-3f);
    return discs;
}

glm::mat3 turned(float a, float b) {
    const glm::mat3 ry(std::cos(a), 0.f, -std::sin(a), 0.f, 1.f, 0.f, std::sin(a), 0.f,
                       std::cos(a));
    const glm::mat3 rx(1.f, 0.f, 0.f, 0.f, std::cos(b), std::sin(b), 0.f, -std::sin(b),
                       std::cos(b));
    return rx * ry;
}

/// Random segments, plus what strains a tilted plane's lookup, aimed at the planes' discs:
/// landings on a disc's plane at |cos| from 1e-5 to 1e-1 (on both sides of the planes' minimum
/// cosine), segments nearly in a plane passing over its discs, landings at a rim, and segments
/// from 100 m (5,000 radii) away.
PhotonSegments tiltedSegments(std::mt19937& rng, const Discs& discs, float radius) {
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::uniform_int_distribution<std::size_t> pick(0, kTiltedPlanarDiscs - 1);
    PhotonSegments segments = randomSegments(rng, discs, radius, 6000);
    for (int i = 0; i < 8000; ++i) {
        const std::size_t j = pick(rng);
        const glm::vec3 n = discs.normals[j];
        const glm::vec3 tangent = glm::normalize(glm::cross(n, randomUnit(rng)));
        const float grazing = std::pow(10.f, -5.f + 4.f * unit(rng));
        if (i % 4 == 0) {
            const glm::vec3 end = discs.centers[j] + (1.1f * radius * unit(rng)) * tangent;
            const glm::vec3 d = glm::normalize(tangent - grazing * n);
            addSegment(segments, end - 0.4f * d, d, 0.4f, 1);
        } else if (i % 4 == 1) {
            const glm::vec3 over = discs.centers[j] + (grazing * radius * (unit(rng) - 0.3f)) * n;
            const glm::vec3 d = glm::normalize(tangent - grazing * (unit(rng) - 0.5f) * n);
            addSegment(segments, over - 0.2f * d, d, i % 8 == 1 ? kInf : 0.4f, 1);
        } else if (i % 4 == 2) {
            const glm::vec3 end = discs.centers[j] + radius * tangent;
            const glm::vec3 d = glm::normalize(-n + 0.5f * randomUnit(rng));
            addSegment(segments, end - 0.3f * d, d, 0.3f, 1);
        } else {
            const glm::vec3 d = glm::normalize(-n + 0.3f * randomUnit(rng));
            addSegment(segments, discs.centers[j] - 100.f * d, d, kInf, 1);
        }
    }
    return segments;
}

void expectBruteForce(DiscIndex& index, const Discs& discs, const PhotonSegments& segments,
                      float radius, std::mt19937& rng, std::size_t atLeast) {
    std::vector<std::uint32_t> indices(segments.size());
    std::iota(indices.begin(), indices.end(), 0u);
    std::shuffle(indices.begin(), indices.end(), rng);
    std::vector<DiscCrossing> actual;
    index.collectCrossings(segments, indices, actual);
    const std::vector<DiscCrossing> expected = bruteForce(segments, indices, discs, radius);
    EXPECT_GT(expected.size(), atLeast);
    expectSamePairs(actual, expected);

    // Cut copies: the crossings beyond a length.
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::vector<float> beyond(indices.size());
    for (std::size_t k = 0; k < indices.size(); ++k) {
        const float length = segments.length[indices[k]];
        beyond[k] = k % 2 == 0 ? -kInf : (std::isinf(length) ? 2.f : length) * unit(rng);
    }
    std::vector<std::size_t> position(segments.size());
    for (std::size_t k = 0; k < indices.size(); ++k)
        position[indices[k]] = k;
    std::vector<DiscCrossing> cut;
    for (const DiscCrossing& c : expected)
        if (!crossesDisc(segments.origin[c.segment], segments.direction[c.segment],
                         beyond[position[c.segment]], discs.centers[c.disc], discs.normals[c.disc],
                         radius))
            cut.push_back(c);
    EXPECT_LT(cut.size(), expected.size());
    index.collectCrossings(segments, indices, actual, beyond);
    expectSamePairs(actual, cut);
}

// A few planes, every disc in one: queried plane by plane, tilted planes and all.
TEST(DetpDiscIndex, DirectQueriesOfTiltedPlanesMatchBruteForce) {
    std::mt19937 rng(31);
    constexpr float kRadius = 0.02f;
    const Discs discs = tiltedDiscs(rng, {0.4f, 0.2f, -0.1f}, turned(0.5f, 0.3f), false);
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    EXPECT_TRUE(index.direct());
    EXPECT_EQ(index.planeCount(), 6u);
    EXPECT_EQ(index.tiltedPlaneCount(), 6u);
    EXPECT_EQ(index.planarDiscCount(), kTiltedPlanarDiscs);
    expectBruteForce(index, discs, tiltedSegments(rng, discs, kRadius), kRadius, rng, 5000);
}

// What the plane sieve of a direct query works at the edge of: landings on the rims of discs
// (at the edge of each plane's box for its outermost discs), at |cos| on both sides of the
// sieve's 0.01 floor and of the tilted planes' grazing limits, from 1 m to 100 m away (float
// rounding of the crossing grows with the distance), whole and cut.
TEST(DetpDiscIndex, PlaneSieveKeepsEveryCrossingAtItsMargins) {
    std::mt19937 rng(41);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    constexpr float kRadius = 0.02f;
    Discs discs = tiltedDiscs(rng, {0.4f, 0.2f, -0.1f}, turned(0.5f, 0.3f), false);
    for (int i = 0; i < 15; ++i) // and an exact plane: a floor under the block
        for (int j = 0; j < 15; ++j) {
            discs.centers.push_back({-0.2f + 0.05f * float(i), -0.3f, -0.5f + 0.05f * float(j)});
            discs.normals.push_back({0.f, 1.f, 0.f});
        }
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    ASSERT_TRUE(index.direct());
    ASSERT_EQ(index.planarDiscCount(), discs.centers.size());
    std::uniform_int_distribution<std::size_t> pick(0, discs.centers.size() - 1);
    PhotonSegments segments;
    for (int i = 0; i < 12000; ++i) {
        const std::size_t j = pick(rng);
        const glm::vec3 n = discs.normals[j];
        const glm::vec3 tangent = glm::normalize(glm::cross(n, randomUnit(rng)));
        const glm::vec3 rim = discs.centers[j] + (kRadius * (0.97f + 0.06f * unit(rng))) * tangent;
        // |cos| from 0.005 to 0.05, spread evenly in its logarithm.
        const float cosine = 0.005f * std::pow(10.f, unit(rng));
        const glm::vec3 across = glm::normalize(glm::cross(n, tangent) * (unit(rng) - 0.5f) +
                                                tangent * (unit(rng) - 0.5f));
        const glm::vec3 d = glm::normalize(std::sqrt(1.f - cosine * cosine) * across - cosine * n);
        // 1 m to 100 m: the rule's own float rounding grows like the distance over |cos|, and
        // at 1 km it moves these skimming crossings by up to a radius (see DiscIndex).
        const float distance = std::pow(10.f, 2.f * unit(rng));
        const float length = distance + kRadius * (0.03f * unit(rng) - 0.01f);
        addSegment(segments, rim - distance * d, d, i % 3 == 0 ? kInf : length, 1);
    }
    expectBruteForce(index, discs, segments, kRadius, rng, 3000);
}

// With discs that fit no plane the index goes through Embree, and its tilted discs stay points
// (exact down to |cos| of about 1e-4: the segments here are random, none skims a face).
TEST(DetpDiscIndex, TiltedDiscsBesidePointsStayPoints) {
    std::mt19937 rng(33);
    constexpr float kRadius = 0.02f;
    const Discs discs = tiltedDiscs(rng, {0.4f, 0.2f, -0.1f}, turned(0.5f, 0.3f), true);
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    EXPECT_FALSE(index.direct());
    EXPECT_EQ(index.planeCount(), 0u);
    expectBruteForce(index, discs, randomSegments(rng, discs, kRadius, 9000), kRadius, rng, 500);
}

// Five kilometres from the origin the rounding of coordinates is large for a 2 cm radius: a
// tilted plane's lookup would leave most segments to test every disc, so the discs stay
// points, even on a plane as flat as floats allow (x + y the same for every centre, bit for
// bit, and one normal).
TEST(DetpDiscIndex, TiltedPlanesFarFromTheOriginStayPoints) {
    constexpr float kRadius = 0.02f, kStep = 1.f / 64.f; // steps exact in float
    Discs discs;
    for (int i = 0; i < 16; ++i)
        for (int j = 0; j < 16; ++j) {
            discs.centers.push_back(
                {5000.f + kStep * float(i), 1000.f - kStep * float(i), kStep * float(j)});
            discs.normals.push_back(glm::normalize(glm::vec3(1.f, 1.f, 0.f)));
        }
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    index.build(discs.centers, discs.normals, kRadius);
    EXPECT_EQ(index.planeCount(), 0u);
    EXPECT_FALSE(index.direct());
    // Near the origin the same plane is one.
    for (glm::vec3& c : discs.centers)
        c -= glm::vec3(5000.f, 1000.f, 0.f);
    index.build(discs.centers, discs.normals, kRadius);
    EXPECT_EQ(index.tiltedPlaneCount(), 1u);
    EXPECT_TRUE(index.direct());
}

TEST(DetpDiscIndex, MovingPlanesMatchBruteForce) {
    std::mt19937 rng(32);
    constexpr float kRadius = 0.02f;
    EmbreeDevice device;
    // A block: exact planes unturned and without rounding, tilted ones once turned, all queried
    // directly. The last move slides without a turn.
    Discs discs = tiltedDiscs(rng, glm::vec3(0.f), glm::mat3(1.f), false, 0.f);
    DiscIndex index(device, DiscIndex::Motion::Moving);
    index.build(discs.centers, discs.normals, kRadius);
    EXPECT_TRUE(index.direct());
    EXPECT_EQ(index.planeCount(), 6u);
    EXPECT_EQ(index.tiltedPlaneCount(), 0u);
    const glm::mat3 turns[] = {turned(0.2f, 0.f), turned(0.7f, -0.4f), turned(0.7f, -0.4f)};
    const glm::vec3 places[] = {{0.1f, 0.f, 0.f}, {0.3f, -0.2f, 0.5f}, {0.31f, -0.2f, 0.5f}};
    for (int step = 0; step < 3; ++step) {
        discs = tiltedDiscs(rng, places[step], turns[step], false);
        index.move(discs.centers, discs.normals);
        EXPECT_TRUE(index.direct()) << "step " << step;
        EXPECT_EQ(index.tiltedPlaneCount(), 6u) << "step " << step;
        expectBruteForce(index, discs, tiltedSegments(rng, discs, kRadius), kRadius, rng, 5000);
    }
    // Exact planes beside points, through Embree, sliding.
    discs = axisAlignedDiscs(rng);
    DiscIndex mixed(device, DiscIndex::Motion::Moving);
    mixed.build(discs.centers, discs.normals, kRadius);
    for (int step = 0; step < 2; ++step) {
        for (glm::vec3& c : discs.centers)
            c += glm::vec3(0.25f, -0.125f, 0.5f); // exact in float: the planes stay exact
        mixed.move(discs.centers, discs.normals);
        EXPECT_FALSE(mixed.direct());
        EXPECT_EQ(mixed.planeCount(), 4u);
        expectBruteForce(mixed, discs, randomSegments(rng, discs, kRadius, 6000), kRadius, rng,
                         1000);
    }
}

TEST(DetpDiscIndex, RejectsBadInput) {
    EmbreeDevice device;
    DiscIndex index(device, DiscIndex::Motion::Static);
    const std::vector<glm::vec3> centers{{0.f, 0.f, 0.f}};
    const std::vector<glm::vec3> normals{{0.f, 0.f, 1.f}};
    EXPECT_THROW(index.build(centers, normals, 0.f), Error);
    EXPECT_THROW(index.build(centers, normals, kInf), Error);
    const std::vector<glm::vec3> nan{{std::nanf(""), 0.f, 0.f}};
    EXPECT_THROW(index.build(nan, normals, 0.1f), Error);
    // An empty index finds nothing.
    index.build({}, {}, 0.1f);
    PhotonSegments segments;
    addSegment(segments, {0.f, 0.f, 1.f}, {0.f, 0.f, -1.f}, kInf, 1);
    const std::vector<std::uint32_t> indices{0};
    std::vector<DiscCrossing> out{{5, 5}};
    index.collectCrossings(segments, indices, out);
    EXPECT_TRUE(out.empty());
}

} // namespace
} // namespace qgi

namespace qgi {
namespace {

// A vertex on a shallow fold (two planes meeting at 0.5 degrees, like the published Cornell
// walls) has its disc tilted by half the fold, so half the disc lies just behind the surface.
// Vertical rays landing on the surface inside the disc's footprint must all count; with too
// small an end tolerance, the ones on the far half stopped short of the disc plane and the
// fold showed as a dark line.
TEST(DiscCrossingRule, LandingsOnAShallowFoldAllCount) {
    const float fold = 0.5f * 3.14159265f / 180.f; // radians
    const float r = 0.01f;
    const glm::vec3 normal = glm::normalize(glm::vec3(-std::sin(0.5f * fold), std::cos(0.5f * fold), 0.f));
    const glm::vec3 down(0.f, -1.f, 0.f);
    int inside = 0, counted = 0;
    const int n = 200;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            const float x = r * (2.f * (float(i) + 0.5f) / float(n) - 1.f);
            const float z = r * (2.f * (float(j) + 0.5f) / float(n) - 1.f);
            if (x * x + z * z > 0.95f * r * r) continue; // keep clear of the rim
            ++inside;
            const float surface = x > 0.f ? x * std::tan(fold) : 0.f;
            const glm::vec3 origin(x, 1.f, z);
            if (crossesDisc(origin, down, 1.f - surface, glm::vec3(0.f), normal, r)) ++counted;
        }
    EXPECT_EQ(counted, inside);
}

} // namespace
} // namespace qgi
