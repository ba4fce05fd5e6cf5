#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace qgi {

/// An 8-bit RGBA image, rows top to bottom. Encoding (sRGB or linear) is up to the producer.
struct Image8 {
    int width = 0;
    int height = 0;
    std::vector<std::uint8_t> rgba; ///< width * height * 4 bytes

    std::uint8_t* pixel(int x, int y) { return rgba.data() + 4 * (std::size_t(y) * width + x); }
    const std::uint8_t* pixel(int x, int y) const {
        return rgba.data() + 4 * (std::size_t(y) * width + x);
    }
};

} // namespace qgi
