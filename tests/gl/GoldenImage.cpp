#include "GoldenImage.h"

#include "runtime/io/Exr.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

namespace qgi::test {

GoldenCheck checkGolden(const std::filesystem::path& golden, const ImageF& fresh) {
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
    if (stored.rgba.size() != fresh.rgba.size()) {
        ADD_FAILURE() << golden << " has another size than the fresh reference";
        return GoldenCheck::Compared;
    }
    std::size_t differ = 0;
    for (std::size_t i = 0; i < fresh.rgba.size(); ++i)
        // Written so that a NaN on either side counts as a difference.
        differ += !(std::abs(stored.rgba[i] - fresh.rgba[i]) <= 1e-5f * std::abs(fresh.rgba[i]));
    EXPECT_LE(double(differ) / double(fresh.rgba.size()), 1e-3) << golden;
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
