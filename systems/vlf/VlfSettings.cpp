#include "systems/vlf/VlfSettings.h"

#include "runtime/core/Error.h"

#include <cmath>

namespace qgi {

void validate(const VlfSettings& s) {
    if (s.directionLevel < 0 || s.directionLevel > 6)
        fail("VlfSettings.directionLevel = ", s.directionLevel, " is out of range (0..6)");
    if (s.linesPerSide < 2 || s.linesPerSide > 4096)
        fail("VlfSettings.linesPerSide = ", s.linesPerSide, " is out of range (2..4096)");
    if (s.tileSize < 1 || s.tileSize > s.linesPerSide || s.linesPerSide % s.tileSize != 0)
        fail("VlfSettings.tileSize = ", s.tileSize, " must divide linesPerSide = ", s.linesPerSide);
    if (s.iterations < 1 || s.iterations > 16)
        fail("VlfSettings.iterations = ", s.iterations, " is out of range (1..16)");
    if (s.jitterSamples < 0 || s.jitterSamples > 64)
        fail("VlfSettings.jitterSamples = ", s.jitterSamples, " is out of range (0..64)");
    const double lines = (2.0 * std::pow(4.0, s.directionLevel) + 1.0) * double(s.linesPerSide) *
                         double(s.linesPerSide) * double(std::max(1, s.jitterSamples));
    if (lines > 2e9)
        fail("VlfSettings: ", lines, " lines per iteration (directionLevel ", s.directionLevel,
             ", linesPerSide ", s.linesPerSide, ", jitterSamples ", s.jitterSamples,
             ") is beyond what a bake can trace; at most 2e9");
    if (!std::isfinite(s.texelCells) || s.texelCells < 0.25f || s.texelCells > 16.f)
        fail("VlfSettings.texelCells = ", s.texelCells, " is out of range (0.25..16)");
    if (!std::isfinite(s.filterSigma) || s.filterSigma < 0.f || s.filterSigma > 8.f)
        fail("VlfSettings.filterSigma = ", s.filterSigma, " is out of range (0..8)");
    if (!std::isfinite(s.glossyCutoff) || s.glossyCutoff < 0.f || s.glossyCutoff >= 1.f)
        fail("VlfSettings.glossyCutoff = ", s.glossyCutoff, " is out of range [0, 1)");
    if (s.maxAtlasSize < 0)
        fail("VlfSettings.maxAtlasSize = ", s.maxAtlasSize, " is negative (0: not checked)");
}

} // namespace qgi
