#include "systems/point_cache/PointGrid.h"

#include "runtime/core/Error.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace qgi {

void PointGrid::build(std::span<const glm::vec3> positions, std::span<const glm::vec3> normals,
                      std::span<const float> searchRadii, const Params& params) {
    QGI_ASSERT(positions.size() == normals.size() && positions.size() == searchRadii.size());
    QGI_ASSERT(params.cellSize > 0.f && std::isfinite(params.cellSize));
    for (std::size_t p = 0; p < positions.size(); ++p)
        QGI_ASSERT(std::isfinite(positions[p].x + positions[p].y + positions[p].z) &&
                       std::isfinite(normals[p].x + normals[p].y + normals[p].z) &&
                       searchRadii[p] > 0.f && std::isfinite(searchRadii[p]),
                   "point ", p, " is not finite");
    mParams = params;
    mPositions.assign(positions.begin(), positions.end());
    mNormals.assign(normals.begin(), normals.end());
    mRadii.assign(searchRadii.begin(), searchRadii.end());
    mCellStart.clear();
    mCellPoints.clear();
    mHeldBy.clear();
    mHeldPoints.clear();
    mDims = glm::ivec3(0);
    if (positions.empty()) return;

    // Bounds of every thick disc: extent along axis i is R sqrt(1 - n_i^2) + h |n_i|.
    const auto discHalf = [&](std::size_t p) {
        const glm::vec3 n = mNormals[p];
        const float r = mRadii[p], h = params.planeTolerance * r;
        return r * glm::sqrt(glm::max(glm::vec3(0.f), 1.f - n * n)) + h * glm::abs(n) +
               glm::vec3(1e-5f * r);
    };
    glm::vec3 low(std::numeric_limits<float>::max()), high(-std::numeric_limits<float>::max());
    for (std::size_t p = 0; p < positions.size(); ++p) {
        const glm::vec3 half = discHalf(p);
        low = glm::min(low, mPositions[p] - half);
        high = glm::max(high, mPositions[p] + half);
    }
    mCellSize = params.cellSize;
    const glm::vec3 extent = high - low;
    for (;;) {
        const glm::vec3 d = glm::floor(extent / mCellSize) + 1.f;
        if (double(d.x) * double(d.y) * double(d.z) <= double(kMaxCells)) {
            mDims = glm::ivec3(d);
            break;
        }
        mCellSize *= 1.25f;
    }
    mOrigin = low;
    const std::size_t cellCount = std::size_t(mDims.x) * mDims.y * mDims.z;

    // Two passes (count, fill) over the same conservative overlap rule.
    const auto forEachCell = [&](std::size_t p, auto&& emit) {
        const glm::vec3 half = discHalf(p);
        const glm::ivec3 a =
            glm::clamp(glm::ivec3(glm::floor((mPositions[p] - half - mOrigin) / mCellSize)),
                       glm::ivec3(0), mDims - 1);
        const glm::ivec3 b =
            glm::clamp(glm::ivec3(glm::floor((mPositions[p] + half - mOrigin) / mCellSize)),
                       glm::ivec3(0), mDims - 1);
        const glm::vec3 n = mNormals[p];
        const float reach = 0.5f * mCellSize * (std::abs(n.x) + std::abs(n.y) + std::abs(n.z));
        const float thickness = params.planeTolerance * mRadii[p] * (1.f + 1e-4f) + 1e-6f;
        for (int k = a.z; k <= b.z; ++k)
            for (int j = a.y; j <= b.y; ++j)
                for (int i = a.x; i <= b.x; ++i) {
                    const glm::vec3 centre = mOrigin + (glm::vec3(i, j, k) + 0.5f) * mCellSize;
                    // The cell box meets the thick plane slab.
                    if (std::abs(glm::dot(n, centre - mPositions[p])) > reach + thickness) continue;
                    emit(std::size_t((k * mDims.y + j) * mDims.x + i));
                }
    };
    mCellStart.assign(cellCount + 1, 0);
    for (std::size_t p = 0; p < positions.size(); ++p)
        forEachCell(p, [&](std::size_t c) { ++mCellStart[c + 1]; });
    for (std::size_t c = 0; c < cellCount; ++c)
        mCellStart[c + 1] += mCellStart[c];
    mCellPoints.resize(mCellStart[cellCount]);
    std::vector<std::uint32_t> cursor(mCellStart.begin(), mCellStart.end() - 1);
    for (std::size_t p = 0; p < positions.size(); ++p)
        forEachCell(p, [&](std::size_t c) { mCellPoints[cursor[c]++] = std::uint32_t(p); });

    std::vector<std::pair<std::uint32_t, std::uint32_t>> held(positions.size());
    for (std::size_t p = 0; p < positions.size(); ++p) {
        const std::int64_t c = cellOf(mPositions[p]);
        QGI_ASSERT(c >= 0, "point ", p, " lies outside the grid built around it");
        held[p] = {std::uint32_t(c), std::uint32_t(p)};
    }
    std::sort(held.begin(), held.end());
    mHeldBy.resize(held.size());
    mHeldPoints.resize(held.size());
    for (std::size_t i = 0; i < held.size(); ++i) {
        mHeldBy[i] = held[i].first;
        mHeldPoints[i] = held[i].second;
    }
}

std::span<const std::uint32_t> PointGrid::pointsHeldBy(std::uint32_t cell) const {
    const auto [first, last] = std::equal_range(mHeldBy.begin(), mHeldBy.end(), cell);
    return std::span<const std::uint32_t>(mHeldPoints)
        .subspan(std::size_t(first - mHeldBy.begin()), std::size_t(last - first));
}

float PointGrid::distanceTo(std::uint32_t p, const glm::vec3& x) const {
    return glm::length(x - mPositions[p]);
}

bool PointGrid::inRange(std::uint32_t p, const glm::vec3& x, const glm::vec3& n) const {
    const glm::vec3 offset = x - mPositions[p];
    const float r = mRadii[p];
    if (!(glm::dot(offset, offset) < r * r)) return false;
    if (!(glm::dot(mNormals[p], n) >= mParams.minNormalCosine)) return false;
    return std::abs(glm::dot(mNormals[p], offset)) <= mParams.planeTolerance * r;
}

std::int64_t PointGrid::cellOf(const glm::vec3& x) const {
    if (mCellStart.empty()) return -1;
    const glm::vec3 cell = glm::floor((x - mOrigin) / mCellSize);
    if (!(cell.x >= 0.f && cell.y >= 0.f && cell.z >= 0.f && cell.x < float(mDims.x) &&
          cell.y < float(mDims.y) && cell.z < float(mDims.z)))
        return -1;
    const glm::ivec3 c(cell);
    return (std::int64_t(c.z) * mDims.y + c.y) * mDims.x + c.x;
}

std::span<const std::uint32_t> PointGrid::candidates(const glm::vec3& x) const {
    const std::int64_t index = cellOf(x);
    if (index < 0) return {};
    return std::span<const std::uint32_t>(mCellPoints)
        .subspan(mCellStart[std::size_t(index)],
                 mCellStart[std::size_t(index) + 1] - mCellStart[std::size_t(index)]);
}

} // namespace qgi
