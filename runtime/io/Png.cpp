#include "runtime/io/Png.h"

#include "runtime/core/Error.h"
#include "runtime/io/AtomicFile.h"

// stb's implementation comes from Debian's libstb (linked through pkg-config), the same copy
// tinygltf uses: defining STB_*_IMPLEMENTATION here would shadow it with a second, narrower one.
#include <stb/stb_image.h>
#include <stb/stb_image_write.h>

#include <memory>
#include <string>

namespace qgi {

void writePng(const std::filesystem::path& path, int width, int height,
              std::span<const std::uint8_t> rgba) {
    if (width <= 0 || height <= 0)
        fail("cannot write PNG '", path.string(), "': size ", width, "x", height);
    if (rgba.size() != std::size_t(width) * std::size_t(height) * 4)
        fail("cannot write PNG '", path.string(), "': ", rgba.size(), " bytes for ", width, "x",
             height, " RGBA");
    std::string bytes;
    const auto append = [](void* context, void* data, int size) {
        static_cast<std::string*>(context)->append(static_cast<const char*>(data),
                                                   std::size_t(size));
    };
    if (!stbi_write_png_to_func(append, &bytes, width, height, 4, rgba.data(), width * 4))
        fail("cannot write PNG '", path.string(), "': encoding failed");
    writeFileAtomically(path, bytes, "PNG");
}

Image8 readPng(const std::filesystem::path& path) {
    int width = 0, height = 0, channelsInFile = 0;
    const std::unique_ptr<stbi_uc, void (*)(void*)> pixels(
        stbi_load(path.string().c_str(), &width, &height, &channelsInFile, 4), stbi_image_free);
    if (!pixels) fail("cannot read PNG '", path.string(), "': ", stbi_failure_reason());
    Image8 image;
    image.width = width;
    image.height = height;
    image.rgba.assign(pixels.get(), pixels.get() + std::size_t(width) * std::size_t(height) * 4);
    return image;
}

} // namespace qgi
