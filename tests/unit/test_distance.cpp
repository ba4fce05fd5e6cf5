// runtime/math/Distance.h against brute force.
#include "runtime/math/Distance.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace qgi {
namespace {

// The cone's defining minimum over t, by a scan of 20001 steps in double.
double scannedBeyondCone(const glm::dvec3& c, const glm::dvec3& apex, const glm::dvec3& centre,
                         double radius) {
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i <= 20000; ++i) {
        const double t = i / 20000.0;
        best = std::min(best, glm::length(c - (apex + t * (centre - apex))) - t * radius);
    }
    return best;
}

TEST(Distance, BeyondTheConeIsTheMinimumOverItsSegmentsAndNeverAboveTheCapsule) {
    // Random configurations at scene scale, thin and wide cones, c near the apex, beside
    // the axis, past the ball and behind the apex. The scan's step moves the minimum by at
    // most |d| (1 + radius / |d|) / 20000 (g is that Lipschitz in t) and its minimum is at or
    // above the true one, so the closed form must lie in [scan - step bound, scan] (plus the
    // float rounding of c, apex and centre, which both see alike).
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> coordinate(-10.f, 10.f), unit(0.f, 1.f);
    int inside = 0;
    for (int i = 0; i < 20000; ++i) {
        const glm::vec3 apex(coordinate(rng), coordinate(rng), coordinate(rng));
        const glm::vec3 centre(coordinate(rng), coordinate(rng), coordinate(rng));
        const float radius = i % 3 == 0 ? 0.1f * unit(rng) : 10.f * unit(rng);
        glm::vec3 c(coordinate(rng), coordinate(rng), coordinate(rng));
        if (i % 4 == 1) c = apex + 0.05f * (c - apex); // near the apex
        const double got = distanceBeyondCone(c, apex, centre, radius);
        const double scanned = scannedBeyondCone(c, apex, centre, radius);
        const double length = glm::length(glm::dvec3(centre) - glm::dvec3(apex));
        const double step = (length + radius) / 20000.0;
        ASSERT_LE(got, scanned + 1e-9) << i;
        ASSERT_GE(got, scanned - step - 1e-9) << i;
        // Never looser than the capsule test it replaces (distance to the axis segment, less
        // the radius), and equal to it at the far end, t = 1.
        EXPECT_GE(got, double(distanceToSegment(c, apex, centre)) - radius - 1e-5) << i;
        EXPECT_LE(got, glm::length(glm::dvec3(c) - glm::dvec3(centre)) - radius + 1e-9) << i;
        inside += got < 0.0 ? 1 : 0;
    }
    EXPECT_GT(inside, 1000); // the cases cover points inside the cone too
}

TEST(Distance, AConeOfNoLengthIsItsBallAndTheApexIsAlwaysOnIt) {
    const glm::vec3 p(1.f, 2.f, 3.f);
    EXPECT_DOUBLE_EQ(distanceBeyondCone({4.f, 6.f, 3.f}, p, p, 1.f), 4.0);
    for (const float radius : {0.f, 0.5f, 50.f})
        EXPECT_LE(distanceBeyondCone(p, p, {7.f, -1.f, 2.f}, radius), 1e-12);
    // Beside the axis the balls of radius t r around the axis make a cone of half-angle
    // asin(r / length), and the value is the signed distance to its side:
    // across cos - along sin. Length 10, radius 1, a point 5 along and 0.5 across:
    // 0.5 sqrt(0.99) - 0.5 (inside, though it is on the cone of half-angle atan(0.1)).
    EXPECT_NEAR(distanceBeyondCone({5.f, 0.5f, 0.f}, {0.f, 0.f, 0.f}, {10.f, 0.f, 0.f}, 1.f),
                0.5 * std::sqrt(0.99) - 0.5, 1e-12);
    EXPECT_NEAR(distanceBeyondCone({3.f, -2.f, 0.f}, {0.f, 0.f, 0.f}, {10.f, 0.f, 0.f}, 1.f),
                2.0 * std::sqrt(0.99) - 0.3, 1e-12);
}

} // namespace
} // namespace qgi
