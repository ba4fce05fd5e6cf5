#pragma once

#include "runtime/math/SphericalHarmonics.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/vec3.hpp>

#include <algorithm>
#include <cstdint>
#include <vector>

namespace qgi {

/// A regular lattice of probe positions: probe (i, j, k) sits at origin + spacing (i, j, k),
/// 0 <= i < counts.x and so on, at least 2 per axis; index = i + counts.x (j + counts.y k).
/// A cell is the box between 8 neighbouring probes; cell (i, j, k) has probe (i, j, k) as its
/// lowest corner, so there are counts - 1 cells per axis.
struct ProbeGrid {
    glm::vec3 origin{0.f}; ///< metres: probe (0, 0, 0)
    float spacing = 1.f;   ///< metres
    glm::ivec3 counts{2};  ///< probes per axis, each >= 2

    /// The lattice over `bounds`: ceil(extent / spacing) probes per axis (at least 2), centred
    /// on the bounds, so no probe lies on the bounds' faces unless the bounds are thinner than
    /// one spacing.
    static ProbeGrid over(const Aabb& bounds, float spacing);

    std::size_t probeCount() const { return std::size_t(counts.x) * counts.y * counts.z; }
    glm::ivec3 cellCounts() const { return counts - 1; }
    std::size_t cellCount() const {
        const glm::ivec3 c = cellCounts();
        return std::size_t(c.x) * c.y * c.z;
    }
    std::uint32_t probeIndex(const glm::ivec3& p) const {
        return std::uint32_t(p.x + counts.x * (p.y + counts.y * p.z));
    }
    glm::ivec3 probeCoords(std::uint32_t index) const {
        return {int(index % std::uint32_t(counts.x)),
                int(index / std::uint32_t(counts.x) % std::uint32_t(counts.y)),
                int(index / (std::uint32_t(counts.x) * std::uint32_t(counts.y)))};
    }
    glm::vec3 position(std::uint32_t index) const {
        return origin + spacing * glm::vec3(probeCoords(index));
    }
    /// Probe at corner `corner` (0 to 7; bit 0: +x, bit 1: +y, bit 2: +z) of cell `cell`.
    std::uint32_t cornerProbe(const glm::ivec3& cell, int corner) const {
        return probeIndex(cell + glm::ivec3(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1));
    }
    std::uint32_t cellIndex(const glm::ivec3& c) const {
        const glm::ivec3 n = cellCounts();
        return std::uint32_t(c.x + n.x * (c.y + n.y * c.z));
    }
    glm::ivec3 cellCoords(std::uint32_t index) const {
        const glm::ivec3 n = cellCounts();
        return {int(index % std::uint32_t(n.x)),
                int(index / std::uint32_t(n.x) % std::uint32_t(n.y)),
                int(index / (std::uint32_t(n.x) * std::uint32_t(n.y)))};
    }
    /// The cell holding `p` (clamped into the lattice) and p's position in it, each in [0, 1].
    void locate(const glm::vec3& p, glm::ivec3& cell, glm::vec3& t) const {
        const glm::vec3 g = (p - origin) / spacing;
        for (int a = 0; a < 3; ++a) {
            // NaN goes to 0: both comparisons are false for it. (Written out rather than
            // std::fmin/fmax, which the compiler calls into libm for.)
            const float top = float(counts[a] - 1);
            float clamped = g[a] > 0.f ? g[a] : 0.f;
            clamped = clamped < top ? clamped : top;
            const int i = std::min(int(clamped), counts[a] - 2);
            cell[a] = i;
            t[a] = std::min(1.f, clamped - float(i));
        }
    }
};

/// What one interpolation did (for tests and statistics).
struct ProbeBlend {
    std::uint32_t probes[8] = {}; ///< the cell's corner probes, corner c = bits (x, y, z) of c
    float weights[8] = {};        ///< normalised weights used; 0 for suppressed corners
    /// No corner kept a weight, so the enabled ones were blended plainly: every enabled corner
    /// with a trilinear weight was hidden (`hidden`), or p lies where only disabled corners
    /// weigh (on a face or past the lattice's edge beside disabled probes).
    bool fallback = false;
    bool hidden = false; ///< every enabled corner was hidden from p by geometry
};

/** World resource: the SH irradiance volume (seed 002 section 3.4). Each probe holds order-2
 *  RGB spherical harmonics of the radiance arriving at it, W/(m^2 sr) (ShLighting's basis and
 *  order); probes inside geometry are disabled. Per cell, an optional visibility mask records
 *  which of its 8 corner probes each point of a (S+1)^3 lattice inside the cell can see.
 *  Written by ShProbeSystem; interpolate() is const and thread safe.                      */
class ProbeVolume {
public:
    ProbeVolume() = default;
    ProbeVolume(const ProbeGrid& grid, std::uint32_t visibilitySubdivisions);

    const ProbeGrid& grid() const { return mGrid; }
    std::size_t probeCount() const { return mCoefficients.size(); }
    std::uint32_t visibilitySubdivisions() const { return mSubdivisions; }

    const sh::ShRgb& coefficients(std::uint32_t probe) const { return mCoefficients[probe]; }
    sh::ShRgb& coefficients(std::uint32_t probe) { return mCoefficients[probe]; }
    bool enabled(std::uint32_t probe) const { return mEnabled[probe] != 0; }
    void setEnabled(std::uint32_t probe, bool on) { mEnabled[probe] = on ? 1 : 0; }

    // ---- visibility masks ------------------------------------------------------------------
    /// Lattice points per cell: (S + 1)^3.
    std::uint32_t latticePointsPerCell() const { return mPointsPerCell; }
    /// World position of lattice point (a, b, c), 0..S each, of `cell`. Computed from global
    /// lattice coordinates, so points shared by neighbouring cells are bit-identical.
    glm::vec3 latticePoint(std::uint32_t cell, const glm::ivec3& abc) const;
    bool visibilityReady(std::uint32_t cell) const { return mVisibilityReady[cell] != 0; }
    /// Computed, and every lattice point of the cell sees all 8 corners.
    bool visibilityOpen(std::uint32_t cell) const { return mVisibilityReady[cell] == 2; }
    /// Bit c of mask[point] set: corner probe c is visible from that lattice point.
    std::uint8_t* visibilityMasks(std::uint32_t cell) {
        return &mVisibility[std::size_t(cell) * mPointsPerCell];
    }
    /// Marks the cell's masks computed (they are read from then on) or not; a computed cell
    /// whose masks are all 0xff is recorded as open, and interpolate() skips its blend.
    void setVisibilityReady(std::uint32_t cell, bool ready) {
        if (!ready) {
            mVisibilityReady[cell] = 0;
            return;
        }
        const std::uint8_t* m = &mVisibility[std::size_t(cell) * mPointsPerCell];
        mVisibilityReady[cell] =
            std::all_of(m, m + mPointsPerCell, [](std::uint8_t b) { return b == 0xff; }) ? 2 : 1;
    }
    void invalidateVisibility() { std::fill(mVisibilityReady.begin(), mVisibilityReady.end(), 0); }

    /** Radiance SH at world point p: trilinear over the 8 corner probes of p's cell (p is
     *  clamped into the lattice), each corner's weight multiplied by
     *    - 0 when the probe is disabled;
     *    - its visibility from p: the trilinear blend, over the 8 lattice points around p, of
     *      whether the probe is visible from each (1 where the cell's mask is not computed);
     *  and normalised. When no corner keeps a weight, the enabled corners are blended ignoring
     *  visibility (flagged `fallback`, and `hidden` where visibility was what zeroed them).
     *  Returns false, leaving `out` unchanged, when all 8 corners are disabled. Continuous in
     *  p wherever some enabled corner is visible.                                            */
    bool interpolate(const glm::vec3& p, sh::ShRgb& out, ProbeBlend* blend = nullptr) const;

private:
    ProbeGrid mGrid;
    std::uint32_t mSubdivisions = 1;
    std::uint32_t mPointsPerCell = 8;
    std::vector<sh::ShRgb> mCoefficients;
    std::vector<std::uint8_t> mEnabled;
    std::vector<std::uint8_t> mVisibility;      ///< cellCount x pointsPerCell masks
    std::vector<std::uint8_t> mVisibilityReady; ///< per cell: 0 not computed, 1 masks, 2 open
};

} // namespace qgi
