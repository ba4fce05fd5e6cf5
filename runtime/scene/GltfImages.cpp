// glTF import, images: which images a material draws, decoding PNG and JPEG to 8-bit RGBA
// within size limits (from URIs in tinygltf's callback, from buffer views once their range is
// checked), and the one-white-pixel stand-in for an undecodable image nothing draws.

#include "runtime/scene/GltfReader.h"

#include "runtime/core/Log.h"

#include <nlohmann/json.hpp>
#include <stb/stb_image.h>

#include <memory>
#include <string>

namespace qgi::gltf_detail {

namespace {

/// stb_image's reason for its last failure; it gives none for some truncated data.
std::string failureReason() {
    const char* reason = stbi_failure_reason();
    return reason && *reason ? reason : "truncated or corrupt image data";
}

bool isPngOrJpeg(const unsigned char* bytes, int size) {
    static constexpr unsigned char kPng[] = {0x89, 'P', 'N', 'G'};
    static constexpr unsigned char kJpeg[] = {0xff, 0xd8, 0xff};
    return (size >= 4 && std::memcmp(bytes, kPng, 4) == 0) ||
           (size >= 3 && std::memcmp(bytes, kJpeg, 3) == 0);
}

/// Decodes a PNG or JPEG into `image` as 8-bit RGBA. Returns what is wrong, or "" on success.
std::string decodeRgba8(const unsigned char* bytes, std::size_t size, tinygltf::Image& image) {
    if (size > kGltfMaxFileBytes) return "encoded image is larger than the file size limit";
    const int length = int(size);
    if (!isPngOrJpeg(bytes, length)) return "not a PNG or JPEG image";
    int width = 0, height = 0, channels = 0;
    // Read the header first: a few bytes of PNG can claim gigabytes of pixels.
    if (!stbi_info_from_memory(bytes, length, &width, &height, &channels))
        return str("unreadable image header (", failureReason(), ")");
    if (width > kGltfMaxImageSide || height > kGltfMaxImageSide ||
        std::int64_t(width) * height > kGltfMaxImagePixels)
        return str(width, "x", height, " pixels exceed the limit of ", kGltfMaxImageSide,
                   " per side and ", kGltfMaxImagePixels, " in all");
    const std::unique_ptr<stbi_uc, void (*)(void*)> pixels(
        stbi_load_from_memory(bytes, length, &width, &height, &channels, 4), &stbi_image_free);
    if (!pixels) return str("cannot be decoded (", failureReason(), ")");
    image.width = width;
    image.height = height;
    image.component = 4;
    image.bits = 8;
    image.pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    image.image.assign(pixels.get(), pixels.get() + std::size_t(width) * std::size_t(height) * 4);
    return {};
}

/// Replaces an undecodable image nothing draws by one white pixel; false if it is drawn.
bool skipUnusedImage(ImageDecoding& context, int index, const std::string& what,
                     tinygltf::Image& image) {
    if (index < 0 || (std::size_t(index) < context.used.size() && context.used[std::size_t(index)]))
        return false;
    image.width = image.height = 1;
    image.component = 4;
    image.bits = 8;
    image.pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    image.image.assign(4, 255);
    context.skipped.push_back(str("images[", index, "]: ", what, "; no material draws it"));
    return true;
}

} // namespace

/// tinygltf image callback. Images in buffer views are skipped here and decoded once their
/// view has been range-checked: tinygltf hands over an unchecked pointer for them.
bool decodeImageCallback(tinygltf::Image* image, const int index, std::string*, std::string*, int,
                         int, const unsigned char* bytes, int size, void* user) {
    if (image->bufferView >= 0) return true;
    std::string what = decodeRgba8(bytes, std::size_t(size), *image);
    if (what.empty()) return true;
    auto& context = *static_cast<ImageDecoding*>(user);
    if (skipUnusedImage(context, index, what, *image)) return true;
    context.field = str("images[", index, "]");
    context.what = std::move(what);
    return false;
}

void GltfReader::reportSkippedImages() {
    for (const std::string& skipped : mImages.skipped)
        logWarning(mLabel, ": ", skipped);
    mImages.skipped.clear();
}

void GltfReader::findUsedImages(const nlohmann::json& document) {
    const auto images = document.find("images");
    mImages.used.assign(images != document.end() ? images->size() : 0, false);
    const auto textures = document.find("textures");
    const auto materials = document.find("materials");
    if (textures == document.end() || materials == document.end()) return;
    for (const auto& material : *materials) {
        const auto pbr = material.find("pbrMetallicRoughness");
        if (pbr == material.end()) continue;
        const auto texture = pbr->find("baseColorTexture");
        if (texture == pbr->end() || !texture->contains("index")) continue;
        const std::size_t t = (*texture)["index"].get<std::size_t>();
        if (t >= textures->size() || !(*textures)[t].contains("source")) continue;
        const std::size_t source = (*textures)[t]["source"].get<std::size_t>();
        if (source < mImages.used.size()) mImages.used[source] = true;
    }
}

TextureLibrary GltfReader::decodeImages() {
    TextureLibrary library;
    for (std::size_t i = 0; i < mModel.images.size(); ++i) {
        tinygltf::Image& image = mModel.images[i];
        const std::string field = str("images[", i, "]");
        if (image.bufferView >= 0) {
            checkIndex(field + ".bufferView", image.bufferView, mModel.bufferViews.size(),
                       "buffer views");
            const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(image.bufferView)];
            const auto& data = mModel.buffers[std::size_t(view.buffer)].data;
            const std::string what = decodeRgba8(&data[view.byteOffset], view.byteLength, image);
            if (!what.empty() && !skipUnusedImage(mImages, int(i), what, image)) fail(field, what);
        }
        if (image.image.empty()) fail(field, "no pixel data");
        reportSkippedImages();
        library.images.push_back(Image{image.name.empty() ? image.uri : image.name, image.width,
                                       image.height, std::move(image.image), true});
    }
    return library;
}

} // namespace qgi::gltf_detail
