#include "GoldenImage.h"

#include "runtime/io/Exr.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

namespace qgi::test {

RefRange roundingRange(const std::vector<RefTriangle>& triangles,
                       const std::vector<RefLight>& lights, const RefCamera& camera) {
    double largest = 0.0;
    const auto extend = [&](const glm::dvec3& p) {
        largest = std::max({largest, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
    };
    for (const RefTriangle& tri : triangles)
        for (const glm::dvec3& p : {tri.p0, tri.p1, tri.p2})
            extend(p);
    for (const RefLight& light : lights)
        extend(light.position);
    extend(camera.position);
    RefPerturbation perturbation;
    perturbation.pointOffset = std::ldexp(largest, -18);
    perturbation.shadeEveryOffsetRay = true;
    return referenceRange(triangles, lights, camera, perturbation);
}

GoldenCheck checkGolden(const std::filesystem::path& golden, const ImageF& fresh,
                        const RefRange& range) {
    if (const char* write = std::getenv("QGI_WRITE_REFERENCE");
        write && std::string(write) == "1") {
        std::vector<float> rgb; // alpha is always 1: store colour only
        for (std::size_t i = 0; i < fresh.rgba.size(); ++i)
            if (i % 4 != 3) rgb.push_back(fresh.rgba[i]);
        writeExr(golden, fresh.width, fresh.height, rgb, 3);
        return GoldenCheck::Written;
    }
    const ImageF stored = readExr(golden);
    EXPECT_EQ(stored.width, fresh.width);
    EXPECT_EQ(stored.height, fresh.height);
    if (stored.rgba.size() != fresh.rgba.size() || range.lo.rgba.size() != fresh.rgba.size()) {
        ADD_FAILURE() << golden << " has another size than the fresh reference";
        return GoldenCheck::Compared;
    }
    constexpr float kInfinity = std::numeric_limits<float>::infinity();
    std::size_t outside = 0, first = 0;
    for (std::size_t i = 0; i < fresh.rgba.size(); ++i) {
        if (i % 4 == 3) continue;
        // Both lie in [lo, hi] up to the final rounding: one ulp of the larger. Written so
        // that a NaN on either side fails.
        const float larger = std::max(std::abs(stored.rgba[i]), std::abs(fresh.rgba[i]));
        const double allowed = double(range.hi.rgba[i]) - double(range.lo.rgba[i]) +
                               double(std::nextafter(larger, kInfinity) - larger);
        if (!(std::abs(double(stored.rgba[i]) - double(fresh.rgba[i])) <= allowed) &&
            outside++ == 0)
            first = i;
    }
    EXPECT_EQ(outside, 0u)
        << golden << ": " << outside
        << " values differ by more than their rounding range; the first at pixel " << first / 4
        << " channel " << first % 4 << ": stored " << stored.rgba[first] << ", fresh "
        << fresh.rgba[first] << ", range [" << range.lo.rgba[first] << ", " << range.hi.rgba[first]
        << "]";
    return GoldenCheck::Compared;
}

void writeFailureImages(const std::filesystem::path& dir, const std::string& name,
                        const ImageF& actual, const ImageF& expected) {
    ImageF diff = actual;
    for (std::size_t i = 0; i < diff.rgba.size(); ++i)
        diff.rgba[i] = (i % 4 == 3) ? 1.f : std::abs(actual.rgba[i] - expected.rgba[i]);
    writeExr(dir / (name + "_actual.exr"), actual);
    writeExr(dir / (name + "_reference.exr"), expected);
    writeExr(dir / (name + "_diff.exr"), diff);
    ADD_FAILURE() << "wrote " << name << "_{actual,reference,diff}.exr to " << dir;
}

} // namespace qgi::test
