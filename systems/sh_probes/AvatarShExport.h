#pragma once

#include <filesystem>
#include <string>

namespace qgi {

class Registry;

/// The CSV header of exportAvatarSh: avatar,x,y,z then, for L00, L1m1, L10, L11, L2m2, L2m1,
/// L20, L21, L22 in turn, the columns <name>_r,<name>_g,<name>_b.
std::string avatarShCsvHeader();

/// Whether `path` is a regular file that starts with avatarShCsvHeader()'s line: an earlier
/// export, which a new one may replace.
bool isAvatarShCsv(const std::filesystem::path& path);

/** Writes one row per Avatar (with WorldTransform and ShLighting), in view order: its Name
 *  (or "entity<index>" without one; quoted when it holds a comma, quote or line break), its
 *  world position x, y, z in metres (the WorldTransform translation), then the 27
 *  coefficients of incident radiance, W/(m^2 sr), before any cosine convolution, in the real
 *  SH basis of Ramamoorthi and Hanrahan over world (x, y, z) (components/ShLighting.h):
 *    Y00 = 0.282095, Y1-1 = 0.488603 y, Y10 = 0.488603 z, Y11 = 0.488603 x,
 *    Y2-2 = 1.092548 xy, Y2-1 = 1.092548 yz, Y20 = 0.315392 (3z^2 - 1), Y21 = 1.092548 xz,
 *    Y22 = 0.546274 (x^2 - y^2).
 *  Irradiance at unit normal n then follows from Ramamoorthi and Hanrahan's equation 13.
 *  Numbers are written with 9 significant digits. Throws qgi::Error when the file cannot be
 *  written.                                                                                */
void exportAvatarSh(const Registry& registry, const std::filesystem::path& path);

} // namespace qgi
