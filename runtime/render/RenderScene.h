#pragma once

#include <epoxy/gl.h>
#include <glm/ext/vector_uint4_sized.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

struct GpuMesh;

/// Where a surface's irradiance (besides the renderer's direct light) comes from.
enum class SurfaceLighting : std::uint8_t {
    None,               ///< no indirect light known: 0
    VertexIrradiance,   ///< per-vertex irradiance buffer of the GpuMesh, Gouraud-interpolated
    SphericalHarmonics, ///< `sh` evaluated per pixel at the shading normal (avatars)
    /// Hybrid mode: the point cache blended per fragment (RenderScene::pointCache), the
    /// per-vertex irradiance where no cache point is in range; photon mode: as VertexIrradiance.
    PointCache,
};

/// The point cache's GPU copy (shaders/common/pointcache.glsl): three shader storage buffers
/// and the grid's parameters. Owned by the caller; `points` 0: no cache.
struct PointCacheView {
    GLuint points = 0;     ///< per point: vec4 position + R, vec4 normal + AO, vec4 E + r
    GLuint cellStart = 0;  ///< uint per cell + 1
    GLuint cellPoints = 0; ///< uint per entry
    glm::vec4 grid{0.f};   ///< origin (metres), cell size (metres)
    glm::ivec4 dims{0};    ///< cells along x, y, z; falloff exponent
    float minNormalCosine = 0.5f;
    float planeTolerance = 0.5f;
    bool showPoints = false; ///< draw the point set over the surfaces (debug view)
};

/// One mesh to draw this frame. Per-frame data: the pointers live until the frame is drawn.
struct DrawItem {
    const GpuMesh* mesh = nullptr;
    glm::mat4 model{1.f};        ///< object to world
    glm::vec3 albedo{0.8f};      ///< diffuse albedo, linear RGB
    glm::vec3 emission{0.f};     ///< emitted radiance, W/(m^2 sr)
    GLuint baseColorTexture = 0; ///< multiplies albedo; 0: none
    SurfaceLighting lighting = SurfaceLighting::None;
    /// May move every frame (mobiles, avatars): shadow maps keep the static casters' depth
    /// and redraw only these over it.
    bool movable = false;
    std::array<glm::vec3, 9> sh{}; ///< radiance SH (ShLighting order) for SphericalHarmonics
    /// Glossy / mirror static surface: its faces in VlfGpuTables (first, count; count 0: none).
    std::int32_t vlfFirstFace = 0, vlfFaceCount = 0;
};

/// A baked Virtual Light Field in the layout shaders/common/vlf.glsl reads (filled by the VLF's
/// owner, uploaded once by SceneRenderer; `version` changes when the contents do).
struct VlfGpuTables {
    std::uint64_t version = 0;
    int level = 0, linesPerSide = 0, tileSize = 0, directionCount = 0;
    glm::vec3 center{0.f};
    float radius = 1.f;
    std::vector<glm::vec4> directions;  ///< xyz: stored direction
    std::vector<glm::ivec4> triangles;  ///< per leaf: corner index * 2 + (1 if reversed)
    std::vector<glm::vec4> faces;       ///< per specular face: (normal, offset), (k_s, mirror)
    std::vector<glm::ivec4> blocks;     ///< per (face, direction): two ivec4, see vlf.glsl
    std::vector<std::int32_t> slots;    ///< tile id or -1
    /// Per tile cell (tile-major, m x m row-major), 8 bytes each: RGB radiance / cellScale as
    /// half floats, and A 1 where the cell holds a value, 0 where it holds none (the baked
    /// Vlf's cells as it keeps them, vlf::packCells).
    std::vector<glm::u16vec4> cells;
    float cellScale = 1.f; ///< a power of two; the shader multiplies the cells by it
};

enum class LightType : std::uint8_t { Point, Spot, Directional };

/// A light in world space, as the renderer shades it in hybrid mode.
struct RenderLight {
    LightType type = LightType::Point;
    glm::vec3 position{0.f};             ///< metres (point, spot)
    glm::vec3 direction{0.f, 0.f, -1.f}; ///< unit: spot axis, or where directional light travels
    glm::vec3 radiance{1.f};    ///< W/sr (point, spot: colour * intensity) or W/m^2 (directional)
    float innerConeAngle = 0.f; ///< spot, radians, half angle
    float outerConeAngle = 0.7853982f; ///< spot, radians, half angle, at most pi/2

    friend bool operator==(const RenderLight&, const RenderLight&) = default;
};

struct RenderCamera {
    glm::mat4 view{1.f};
    glm::mat4 projection{1.f};
    glm::vec3 position{0.f}; ///< metres, world
};

/// Everything SceneRenderer draws in one frame.
struct RenderScene {
    RenderCamera camera;
    std::span<const DrawItem> items;
    std::span<const RenderLight> lights;
    const VlfGpuTables* vlf = nullptr; ///< null: no VLF (items' vlfFaceCount must be 0)
    /// Since the previous frame a caster that is not movable moved, appeared or disappeared:
    /// every shadow map is redrawn (as when the lights change).
    bool staticCastersChanged = true;
    /// Since the previous frame a movable caster moved, appeared or disappeared: the shadow
    /// maps that see one, now or before, are refreshed.
    bool movableCastersChanged = true;
    const PointCacheView* pointCache = nullptr; ///< null: no point cache
};

} // namespace qgi
