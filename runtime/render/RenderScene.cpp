#include "runtime/render/RenderScene.h"

#include <glm/gtc/packing.hpp>

#include <algorithm>
#include <cmath>

namespace qgi {

float packVlfCells(std::span<const glm::vec4> cells, std::vector<glm::u16vec4>& out) {
    constexpr float kLargest = 16384.f; // a quarter of the largest half float
    const auto usable = [](float v) { return std::isfinite(v) && v > 0.f ? v : 0.f; };
    float largest = 0.f;
    for (const glm::vec4& c : cells)
        largest = std::max({largest, usable(c.x), usable(c.y), usable(c.z)});
    float scale = 1.f;
    while (largest / scale > kLargest)
        scale *= 2.f;
    const std::uint16_t one = glm::packHalf1x16(1.f);
    out.resize(cells.size());
    for (std::size_t i = 0; i < cells.size(); ++i) {
        const glm::vec4& c = cells[i];
        out[i] = {glm::packHalf1x16(usable(c.x) / scale), glm::packHalf1x16(usable(c.y) / scale),
                  glm::packHalf1x16(usable(c.z) / scale), c.w > 0.f ? one : std::uint16_t(0)};
    }
    return scale;
}

} // namespace qgi
