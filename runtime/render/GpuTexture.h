#pragma once

#include "runtime/render/GlHandle.h"

#include <cstdint>
#include <span>

namespace qgi {

/// An 8-bit RGBA colour texture with a full mip chain, trilinear filtering and repeat wrapping.
/// Rows are uploaded top row first, so glTF texture coordinates (origin top left) sample it
/// unflipped. `srgb`: the texels are sRGB-encoded and read back linear in the shader.
GlTexture createColorTexture(int width, int height, std::span<const std::uint8_t> rgba, bool srgb);

/// Sets the pixel unpack state to tightly packed rows read from client memory, whatever the
/// application left there, before a texture upload.
void useTightUnpacking();
/// The same for read-backs into client memory (pixel pack state).
void useTightPacking();

} // namespace qgi
