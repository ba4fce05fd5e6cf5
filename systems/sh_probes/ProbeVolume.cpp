#include "systems/sh_probes/ProbeVolume.h"

#include "runtime/core/Error.h"

#include <glm/common.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace qgi {

static_assert(sizeof(sh::ShRgb) == 27 * sizeof(float), "ShRgb must be 27 packed floats");

ProbeGrid ProbeGrid::over(const Aabb& bounds, float spacing) {
    QGI_ASSERT(spacing > 0.f && !bounds.empty());
    ProbeGrid grid;
    grid.spacing = spacing;
    const glm::vec3 extent = bounds.extent();
    for (int a = 0; a < 3; ++a)
        grid.counts[a] = std::max(2, int(std::ceil(double(extent[a]) / double(spacing))));
    grid.origin = bounds.center() - 0.5f * spacing * glm::vec3(grid.counts - 1);
    return grid;
}

ProbeVolume::ProbeVolume(const ProbeGrid& grid, std::uint32_t visibilitySubdivisions)
    : mGrid(grid), mSubdivisions(visibilitySubdivisions) {
    QGI_ASSERT(visibilitySubdivisions >= 1 && visibilitySubdivisions <= 16);
    const std::uint32_t side = visibilitySubdivisions + 1;
    mPointsPerCell = side * side * side;
    mCoefficients.assign(grid.probeCount(), sh::ShRgb{});
    mEnabled.assign(grid.probeCount(), 1);
    mVisibility.assign(grid.cellCount() * mPointsPerCell, 0xff);
    mVisibilityReady.assign(grid.cellCount(), 0);
}

glm::vec3 ProbeVolume::latticePoint(std::uint32_t cell, const glm::ivec3& abc) const {
    const glm::ivec3 global = mGrid.cellCoords(cell) * int(mSubdivisions) + abc;
    return mGrid.origin + (mGrid.spacing / float(mSubdivisions)) * glm::vec3(global);
}

bool ProbeVolume::interpolate(const glm::vec3& p, sh::ShRgb& out, ProbeBlend* blend) const {
    glm::ivec3 cellCoords;
    glm::vec3 t;
    mGrid.locate(p, cellCoords, t);
    const std::uint32_t cell = mGrid.cellIndex(cellCoords);

    // Visibility of each corner from p: trilinear over the lattice points around p.
    float visibility[8] = {1.f, 1.f, 1.f, 1.f, 1.f, 1.f, 1.f, 1.f};
    // State 2: every lattice point sees every corner (open space): nothing to blend.
    if (mVisibilityReady[cell] == 1) {
        const std::uint32_t s = mSubdivisions, side = s + 1;
        const glm::vec3 f = t * float(s);
        glm::ivec3 j;
        glm::vec3 u;
        for (int a = 0; a < 3; ++a) {
            j[a] = std::min(int(f[a]), int(s) - 1);
            u[a] = f[a] - float(j[a]);
        }
        const std::uint8_t* masks = &mVisibility[std::size_t(cell) * mPointsPerCell];
        std::fill(visibility, visibility + 8, 0.f);
        const std::uint32_t base =
            std::uint32_t(j.x) + side * (std::uint32_t(j.y) + side * std::uint32_t(j.z));
        const std::uint32_t step[2] = {0, 1};
        for (int k = 0; k < 8; ++k) {
            const int dx = k & 1, dy = (k >> 1) & 1, dz = (k >> 2) & 1;
            const float w =
                (dx ? u.x : 1.f - u.x) * (dy ? u.y : 1.f - u.y) * (dz ? u.z : 1.f - u.z);
            const std::uint32_t mask = masks[base + step[dx] + side * (step[dy] + side * step[dz])];
            // Branch-free: the eight corners' bits scaled by w (vectorises to one AVX lane each).
            for (int c = 0; c < 8; ++c)
                visibility[c] += w * float((mask >> c) & 1u);
        }
    }

    std::uint32_t probes[8];
    float trilinear[8], weights[8];
    float sum = 0.f, sumEnabled = 0.f;
    for (int c = 0; c < 8; ++c) {
        const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
        probes[c] = mGrid.cornerProbe(cellCoords, c);
        const float w = (dx ? t.x : 1.f - t.x) * (dy ? t.y : 1.f - t.y) * (dz ? t.z : 1.f - t.z);
        trilinear[c] = mEnabled[probes[c]] ? w : 0.f;
        weights[c] = trilinear[c] * visibility[c];
        sum += weights[c];
        sumEnabled += trilinear[c];
    }
    bool fallback = false, hidden = false;
    if (!(sum > 0.f)) {
        hidden = sumEnabled > 0.f; // enabled corners weighed, and visibility took them all
        if (!(sumEnabled > 0.f)) {
            // All corners disabled, or p sits exactly on the far face of disabled corners:
            // try the enabled corners with equal weight before giving up.
            for (int c = 0; c < 8; ++c)
                trilinear[c] = mEnabled[probes[c]] ? 1.f : 0.f;
            sumEnabled = 0.f;
            for (int c = 0; c < 8; ++c)
                sumEnabled += trilinear[c];
            if (!(sumEnabled > 0.f)) return false;
        }
        fallback = true;
        std::copy(trilinear, trilinear + 8, weights);
        sum = sumEnabled;
    }
    const float inverse = 1.f / sum;
    // Blend as 27 contiguous floats per probe.
    float result[27] = {};
    for (int c = 0; c < 8; ++c) {
        if (weights[c] == 0.f) continue;
        const float w = weights[c] * inverse;
        const float* probe = &mCoefficients[probes[c]][0].x;
        for (int i = 0; i < 27; ++i)
            result[i] += w * probe[i];
    }
    std::memcpy(&out[0].x, result, sizeof result);
    if (blend) {
        for (int c = 0; c < 8; ++c) {
            blend->probes[c] = probes[c];
            blend->weights[c] = weights[c] * inverse;
        }
        blend->fallback = fallback;
        blend->hidden = hidden;
    }
    return true;
}

} // namespace qgi
