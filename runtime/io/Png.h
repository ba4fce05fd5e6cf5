#pragma once

#include "runtime/io/Image8.h"

#include <cstdint>
#include <filesystem>
#include <span>

namespace qgi {

/// Writes an 8-bit RGBA PNG; `rgba` holds width * height * 4 bytes, rows top to bottom.
/// Throws qgi::Error naming the path when the sizes disagree or the file cannot be written.
void writePng(const std::filesystem::path& path, int width, int height,
              std::span<const std::uint8_t> rgba);

inline void writePng(const std::filesystem::path& path, const Image8& image) {
    writePng(path, image.width, image.height, image.rgba);
}

/// Reads a PNG as 8-bit RGBA (grey and RGB files are expanded, alpha 255).
/// Throws qgi::Error naming the path for a missing or malformed file.
Image8 readPng(const std::filesystem::path& path);

} // namespace qgi
