#pragma once

#include <cstdint>

namespace qgi {

/// Settings of the Virtual Light Field bake (seed 002). Distances in the VLF frame: the scene's
/// bounding sphere scaled to radius 1, so a subfield plane spans [-1, 1]^2 and a line cell is
/// 2 / linesPerSide wide.
struct VlfSettings {
    int directionLevel = 4; ///< octahedral level L: 2 * 4^L + 1 directions (4: 513)
    int linesPerSide = 64;  ///< N: lines per side of each parallel subfield
    int tileSize = 8;       ///< m: cells per tile side; N must be a multiple of m
    int iterations = 3;     ///< light bounces propagated (1 = emission only), 1..16
    /// Jittered transport directions per stored direction and iteration, each with jittered
    /// line positions; 0 transports along the stored directions through the cell centres.
    int jitterSamples = 1;
    float texelCells = 1.f;  ///< irradiance-map texel width in line cells (0.25 .. 16)
    float filterSigma = 1.f; ///< Gaussian filter on received irradiance, texels; 0: none
    /// Glossy lobe weights below this fraction of the lobe's peak are dropped (their weight
    /// goes to the rest, so the lobe keeps its albedo).
    float glossyCutoff = 1e-2f;
    std::uint64_t seed = 1; ///< seeds every jitter choice
    bool progress = false;  ///< log progress lines (info level) during the bake
    /// Most memory a bake may take (its peak, VlfMemory::bakeBytes), checked before its large
    /// arrays are allocated (the texel maps' share before them, the whole before the tiles): a
    /// bake that needs more fails with the figure. 0: half of the
    /// machine's physical memory (the rest is the scene's, the GL driver's, the system's; a
    /// container's memory limit is not read: set this below it). Settings within their ranges
    /// can ask for tens of GB (direction level 6 at 256 lines).
    std::uint64_t maxBakeBytes = 0;
    /// Largest texture side, texels, of the renderer that will draw the field (its
    /// GL_MAX_TEXTURE_SIZE): a layout whose tile atlas (shader::vlfAtlasSize) is larger fails
    /// before the bake, not after it at upload. 0: not checked (a field for no renderer);
    /// FrameSchedule sets it from the current GL context when it renders.
    int maxAtlasSize = 0;
};

/// Throws qgi::Error naming the field when a setting is out of range or not finite.
void validate(const VlfSettings& settings);

} // namespace qgi
