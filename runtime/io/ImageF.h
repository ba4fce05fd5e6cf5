#pragma once

#include <cstddef>
#include <vector>

namespace qgi {

/// A linear floating-point RGBA image, rows top to bottom (the first row is the top of the image).
struct ImageF {
    int width = 0;
    int height = 0;
    std::vector<float> rgba; ///< width * height * 4 values

    float* pixel(int x, int y) { return rgba.data() + 4 * (std::size_t(y) * width + x); }
    const float* pixel(int x, int y) const {
        return rgba.data() + 4 * (std::size_t(y) * width + x);
    }
};

} // namespace qgi
