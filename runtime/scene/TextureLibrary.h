#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace qgi {

/// An 8-bit RGBA image as loaded from glTF. Base colour textures are sRGB-encoded.
struct Image {
    std::string name;
    int width = 0;
    int height = 0;
    std::vector<std::uint8_t> rgba; ///< width * height * 4 bytes, rows top to bottom
    bool srgb = true;
};

/// World resource: every texture of the scene; Material::baseColorTexture indexes `images`.
struct TextureLibrary {
    std::vector<Image> images;
};

} // namespace qgi
