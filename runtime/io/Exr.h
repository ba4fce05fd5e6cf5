#pragma once

#include "runtime/io/ImageF.h"

#include <filesystem>
#include <span>

namespace qgi {

/// Storage type of the channels in a written EXR file. Float is lossless (use it for test
/// references); half is 16-bit (screenshots, about 3 significant digits).
enum class ExrPrecision { Half, Float };

/// Writes a linear scanline OpenEXR file with channels R, G, B (and A when `channels` is 4),
/// ZIP compressed. `pixels` holds width * height * channels floats, rows top to bottom.
/// Throws qgi::Error naming the path when the arguments disagree or the file cannot be written.
void writeExr(const std::filesystem::path& path, int width, int height,
              std::span<const float> pixels, int channels,
              ExrPrecision precision = ExrPrecision::Float);

inline void writeExr(const std::filesystem::path& path, const ImageF& image,
                     ExrPrecision precision = ExrPrecision::Float) {
    writeExr(path, image.width, image.height, image.rgba, 4, precision);
}

/// Reads the R, G, B and (if present, otherwise 1) A channels of an EXR file as float RGBA.
/// Throws qgi::Error naming the path for a missing, malformed or non-RGB file.
ImageF readExr(const std::filesystem::path& path);

} // namespace qgi
