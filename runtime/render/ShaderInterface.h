#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace qgi {

/// Binding points, uniform locations and enum values the scene shaders share with the C++
/// side. The shaders see them as macros (shaderInterfaceDefines), so this is the only copy.
namespace shader {

// Uniform locations (explicit, so no lookups by name; a mat4 takes 4, a mat3 3 locations).
constexpr int kModel = 0;          // mat4
constexpr int kNormalMatrix = 4;   // mat3
constexpr int kViewProjection = 8; // mat4
constexpr int kAlbedo = 12;
constexpr int kEmission = 13;
constexpr int kLighting = 14;
constexpr int kMirrored = 15;
constexpr int kSh = 16; // vec3[9]
constexpr int kCameraPosition = 25;
constexpr int kExposure = 26;
constexpr int kVlfFaces = 27;  // ivec2: first specular face, count
constexpr int kVlfParams = 28; // ivec4: level, lines per side, tile size, directions
constexpr int kVlfFrame = 29;  // vec4: VLF centre, radius
constexpr int kPointCacheGrid = 30;   // vec4: grid origin, cell size (shaders/common/pointcache.glsl)
constexpr int kPointCacheDims = 31;   // ivec4: cells per axis, falloff exponent
constexpr int kPointCacheParams = 32; // vec4: min normal cosine, plane tolerance, enabled, show
constexpr int kVlfCellScale = 33;     // float: the VLF atlas holds radiance / this

// Texture units and buffer binding points.
constexpr int kBaseColorUnit = 0;
constexpr int kHdrUnit = 0;
constexpr int kShadowUnit = 1;
constexpr int kLightBlockBinding = 0;
constexpr int kVlfAtlasUnit = 2;
constexpr int kVlfDirectionsBinding = 1; // shader storage blocks
constexpr int kVlfTrianglesBinding = 2;
constexpr int kVlfFacesBinding = 3;
constexpr int kVlfBlocksBinding = 4;
constexpr int kVlfSlotsBinding = 5;
constexpr int kVlfAtlasTiles = 256; // tiles per atlas row
// The point cache's shader storage blocks: 8 blocks in all with the VLF's, the fragment-stage
// minimum GL 4.3 guarantees, and binding points within the guaranteed 0..7.
constexpr int kPointCachePointsBinding = 6;
constexpr int kPointCacheCellStartBinding = 7;
constexpr int kPointCacheCellPointsBinding = 0;

// Array sizes: lights in the light block; shadow layers (a point light takes 6, a spot or
// directional light 1).
constexpr int kMaxLights = 64;
constexpr int kMaxShadowLayers = 32;

/// Size in texels of the VLF tile atlas holding `tiles` tiles of tileSize x tileSize cells:
/// kVlfAtlasTiles tiles a row, at least one row. The renderer lays the atlas out by it, and
/// the VLF checks it against the GL limit before its bake, so the two cannot disagree.
struct VlfAtlasSize {
    std::int64_t width = 0, height = 0;
};
inline VlfAtlasSize vlfAtlasSize(std::size_t tiles, int tileSize) {
    const std::int64_t m = tileSize > 1 ? tileSize : 1;
    const std::int64_t rows =
        tiles > 0 ? (std::int64_t(tiles) + kVlfAtlasTiles - 1) / kVlfAtlasTiles : 1;
    return {kVlfAtlasTiles * m, rows * m};
}

} // namespace shader

/// "#define NAME value" lines for every constant above and the enums of RenderScene.h, for
/// loadProgram.
std::string shaderInterfaceDefines();

} // namespace qgi
