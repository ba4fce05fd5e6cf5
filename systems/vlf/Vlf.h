#pragma once

#include "systems/vlf/DirectionSet.h"
#include "systems/vlf/VlfScene.h"
#include "systems/vlf/VlfSettings.h"

#include "runtime/core/Error.h"

#include <glm/gtc/type_precision.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace qgi::vlf {

/// A line of a subfield in tiled form: tile (s, t), cell (u, v) inside it (seed 002 section
/// 4.2.3: i = s m + u, j = t m + v).
struct TiledIndex {
    int s = 0, t = 0, u = 0, v = 0;
};
inline TiledIndex toTiled(int i, int j, int m) {
    return {i / m, j / m, i % m, j % m};
}
inline glm::ivec2 toGlobal(const TiledIndex& x, int m) {
    return {x.s * m + x.u, x.t * m + x.v};
}
/// Where global cell (i, j) lies in the cell arrays, given the slot `tile` of its tile: each
/// tile's m x m cells row by row.
inline std::size_t cellOffset(std::int32_t tile, int i, int j, int m) {
    const TiledIndex x = toTiled(i, j, m);
    return (std::size_t(tile) * std::size_t(m) + std::size_t(x.v)) * std::size_t(m) +
           std::size_t(x.u);
}

/// The irradiance map of one face: width x height texels of texelU x texelV metres tiling the
/// face's bounding rectangle exactly (Face::origin, axisU, axisV), starting at `firstTexel` of
/// the texel arrays.
struct FaceMap {
    std::uint32_t width = 0, height = 0;
    float texelU = 0.f, texelV = 0.f;
    std::uint32_t firstTexel = 0;
};

/// The tiles of one specular face in one subfield: a rectangle of tile slots
/// [s0, s0 + sw) x [t0, t0 + tw) whose entries (from `firstSlot`) hold a tile id or -1.
/// side: +1 when the face's front side sees +direction (its tiles hold light along +d),
/// -1 for -direction, 0 when the face is edge-on and has no tiles.
struct TileBlock {
    std::int32_t side = 0;
    std::int32_t s0 = 0, t0 = 0, sw = 0, tw = 0;
    std::uint32_t firstSlot = 0;
};

/// The bake's fixed number of work chunks (at most one per direction): each owns a copy of the
/// irradiance texels, and the copies are summed in order, so the result does not depend on
/// the thread count or scheduling.
inline constexpr std::size_t kBakeChunks = 16;

/** The baked cells as a Vlf keeps them, and as VlfGpuTables uploads them: 8 bytes each, RGB
 *  radiance / scale as half floats and A 1 where the cell holds a value, 0 where it holds none.
 *  The scale is the smallest power of two, at least 1, that brings the largest component to
 *  16384 or less, so no value overflows a half float (65504) and dividing by it rounds nothing;
 *  each value then rounds to the nearest half, within 2^-11 of itself (a normal half; a value
 *  under 2^-14 times the scale, to within 2^-25 times the scale). A component that is negative
 *  or not a finite number is stored as 0. `cells` are RGB radiance (W/(m^2 sr)) and a weight
 *  that is positive where the cell holds a value. Returns the scale. */
float packCells(std::span<const glm::vec4> cells, std::vector<glm::u16vec4>& out);
/// A packed cell as RGB radiance and weight (1 or 0).
glm::vec4 unpackCell(const glm::u16vec4& cell, float scale);

/// A baked Vlf's packed cells read as RGB radiance and weight, like a std::vector<glm::vec4> of
/// them: what the lookups take (sampleCells, lookupTiles).
struct PackedCellView {
    const glm::u16vec4* cells = nullptr;
    float scale = 1.f;
    glm::vec4 operator[](std::size_t i) const { return unpackCell(cells[i], scale); }
};

/// Memory of the structure (seed 002 section 1.7 of the digest): element counts and bytes.
struct VlfMemory {
    std::size_t directions = 0;
    std::size_t tiles = 0;         ///< allocated m x m tiles over all specular faces and PSFs
    std::size_t tileCells = 0;     ///< tiles * m^2: directional elements
    std::size_t diffuseTexels = 0; ///< irradiance-map texels over all faces
    std::size_t renderBytes = 0;   ///< what lookups keep: packed cells, RGB float texels, index
    std::size_t bakeBytes = 0;     ///< peak during the bake: the bake's extra copies on top
};

/// The memory of a layout with these counts: `tiles` tiles of tileSize^2 cells, `texels`
/// irradiance-map texels, `slots` tile slots in `blocks` blocks, `faces` face maps. What
/// Vlf::memory() reports and what Vlf::allocate checks before its large arrays, from one
/// formula.
VlfMemory vlfMemory(std::size_t directions, std::size_t tiles, int tileSize, std::size_t texels,
                    std::size_t slots, std::size_t blocks, std::size_t faces);

/** Thrown by Vlf::allocate (and so by bakeVlf) when the layout is beyond a limit of its
 *  settings: the bake's memory (VlfSettings::maxBakeBytes) or the renderer's tile atlas
 *  (VlfSettings::maxAtlasSize). Found before the bake and before any array of the tiles or
 *  texels is allocated. what() names the library's settings; `detail` is the figure alone
 *  ("needs about 41.2 GB, over the 12.6 GB allowed"), for a front end that words the advice
 *  with its own options.                                                                  */
class VlfTooLarge : public Error {
public:
    enum class Limit { Memory, Atlas };
    VlfTooLarge(Limit which, std::string figure, const std::string& message)
        : Error(message), limit(which), detail(std::move(figure)) {}
    Limit limit;
    std::string detail;
};

/** A baked Virtual Light Field (seed 002): the direction set, the subfield grids, per-face
 *  irradiance maps for the diffuse part and per-(specular face, direction) radiance tiles for
 *  the non-diffuse part. Built empty by allocate(), filled by bakeVlf(), saved and loaded by
 *  VlfCache. Lookups are const and thread safe.
 *
 *  The VLF frame maps world x to (x - center) / radius, the scene inside the unit sphere;
 *  subfield i has frame makeSubfieldFrame(direction(i)) and its N x N lines cross the plane
 *  through the origin at cell centres (u, v) = -1 + (k + 0.5) * 2 / N.
 *
 *  What the tiles hold (radiance, W/(m^2 sr), per cell of the face's front-side tiles):
 *   - glossy faces: the total outgoing specular radiance along the subfield direction;
 *   - mirror faces: the total incident radiance arriving from the subfield direction, so the
 *     renderer looks it up around the reflected view direction and multiplies by k_s.
 *  Diffuse: the total irradiance (W/m^2) per texel; outgoing radiance = emission +
 *  k_d / pi * E.                                                                         */
class Vlf {
public:
    Vlf() = default;
    /// The empty structure for `scene`: frame, faces, irradiance maps with their texel
    /// coverage, and the tiles of every specular face in every subfield where it is seen.
    static Vlf allocate(const VlfScene& scene, const VlfSettings& settings);

    // ---- layout ---------------------------------------------------------------------------
    const VlfSettings& settings() const { return mSettings; }
    const DirectionSet& directions() const { return *mDirections; }
    const glm::vec3& center() const { return mCenter; }
    float radius() const { return mRadius; }
    int linesPerSide() const { return mSettings.linesPerSide; }
    int tileSize() const { return mSettings.tileSize; }
    int tilesPerSide() const { return mSettings.linesPerSide / mSettings.tileSize; }
    float cellWidth() const { return 2.f / float(mSettings.linesPerSide); } ///< VLF units
    /// Cross-section of one line's beam in world units, m^2.
    float lineArea() const;
    const SubfieldFrame& frame(std::size_t psf) const { return mFrames[psf]; }
    /// World point -> subfield plane coordinates (u, v) in [-1, 1]^2 for points in the bounds.
    glm::vec2 project(std::size_t psf, const glm::vec3& world) const;
    /// World point on subfield `psf`'s line through plane point `uv`, at depth 0.
    glm::vec3 linePoint(std::size_t psf, const glm::vec2& uv) const;
    std::uint64_t key() const { return mKey; }

    const std::vector<Face>& faces() const { return mFaces; }
    const std::vector<FaceMap>& faceMaps() const { return mFaceMaps; }
    /// Fraction of each texel's area inside its face (exact: the face's triangles clipped
    /// against the texel), per texel. Deposits divide by it, so it must be exact: a texel
    /// half inside a face that counted as 9/16 would read 11 % low.
    const std::vector<float>& texelCoverage() const { return mCoverage; }
    /// Total irradiance per texel, W/m^2.
    const std::vector<glm::vec3>& irradiance() const { return mIrradiance; }
    std::vector<glm::vec3>& irradiance() { return mIrradiance; }
    /// Texel of face `face` that holds world point x (clamped into the map).
    std::uint32_t texelAt(std::uint32_t face, const glm::vec3& x) const;
    /// World position of a texel's centre.
    glm::vec3 texelCenter(std::uint32_t face, std::uint32_t x, std::uint32_t y) const;

    /// Index of face f among the specular faces, or -1.
    std::int32_t specularIndex(std::uint32_t face) const { return mSpecularIndex[face]; }
    std::size_t specularFaceCount() const { return mSpecularFaces.size(); }
    std::uint32_t specularFace(std::size_t sf) const { return mSpecularFaces[sf]; }
    const TileBlock& block(std::size_t sf, std::size_t psf) const {
        return mBlocks[sf * mDirections->size() + psf];
    }
    /// Tile id of global cell (i, j) of specular face sf in subfield psf, or -1.
    std::int32_t tileAt(std::size_t sf, std::size_t psf, int i, int j) const;
    std::size_t tileCount() const { return mTileCount; }
    /// Index of cell (i, j) in the per-cell arrays, or -1 when its tile is not allocated.
    std::int64_t cellIndex(std::size_t sf, std::size_t psf, int i, int j) const;
    /// Cells over all tiles: tileCount() * m^2.
    std::size_t cellCount() const { return mCells.size(); }
    /// Per-cell render table, packed (packCells): RGB radiance and whether the cell holds a
    /// value. Stored by the bake (storeCells) or read from the cache.
    const std::vector<glm::u16vec4>& cells() const { return mCells; }
    float cellScale() const { return mCellScale; }
    PackedCellView cellView() const { return {mCells.data(), mCellScale}; }
    /// The cells as floats (a copy, for tools and tests).
    std::vector<glm::vec4> unpackedCells() const;
    /// Packs `cells` (RGB radiance and weight, cellCount() of them) into the render table.
    void storeCells(std::span<const glm::vec4> cells);
    const std::vector<std::int32_t>& slots() const { return mSlots; }
    const std::vector<TileBlock>& blocks() const { return mBlocks; }

    VlfMemory memory() const;

    // ---- lookups ----------------------------------------------------------------------------
    /// Diffuse outgoing radiance of face `face` at x: emission + k_d / pi * E (bilinear over
    /// covered texels).
    glm::vec3 diffuseRadiance(std::uint32_t face, const glm::vec3& x) const;
    /// Bilinear irradiance of face `face` at x from `texels` (a per-texel array laid out like
    /// irradiance()), over covered texels.
    glm::vec3 sampleTexels(const std::vector<glm::vec3>& texels, std::uint32_t face,
                           const glm::vec3& x) const;
    /// Bilinear value of per-cell `cells` (RGB + weight) of specular face sf in subfield psf at
    /// world x: weights renormalised over the cells that hold a value. Returns the summed
    /// weight in w (0 where nothing is there).
    /// `cells`: a std::vector<glm::vec4> (the bake's working copies) or a PackedCellView.
    template <typename Cells>
    glm::vec3 sampleCells(const Cells& cells, std::size_t sf, std::size_t psf, const glm::vec3& x,
                          float& w) const;
    /// The 12-tap lookup of seed 002 (Eq 4.5): the three subfields around `dir`, a direction
    /// on the face's front side (outgoing for glossy tiles, the direction light arrives from
    /// for mirror tiles), barycentrically weighted, each a bilinear fetch at x; weights
    /// renormalised over the corners where the face has a tile on that side. nullopt where none
    /// has one.
    template <typename Cells>
    std::optional<glm::vec3> lookupTiles(const Cells& cells, std::uint32_t face, const glm::vec3& x,
                                         const glm::vec3& dir) const;
    /// Specular outgoing radiance of face `face` at x towards unit `toViewer` (zero for a
    /// diffuse face or where no tile covers it), from the packed cells the GPU holds too.
    glm::vec3 specularRadiance(std::uint32_t face, const glm::vec3& x,
                               const glm::vec3& toViewer) const;
    /// diffuseRadiance + specularRadiance.
    glm::vec3 radiance(std::uint32_t face, const glm::vec3& x, const glm::vec3& toViewer) const;

private:
    friend class VlfCache;

    VlfSettings mSettings;
    std::shared_ptr<const DirectionSet> mDirections;
    std::vector<SubfieldFrame> mFrames;
    glm::vec3 mCenter{0.f};
    float mRadius = 1.f;
    std::uint64_t mKey = 0;
    std::vector<Face> mFaces; // triangles lists are dropped
    std::vector<FaceMap> mFaceMaps;
    std::vector<float> mCoverage;
    std::vector<glm::vec3> mIrradiance;
    std::vector<std::int32_t> mSpecularIndex;
    std::vector<std::uint32_t> mSpecularFaces;
    std::vector<TileBlock> mBlocks;
    std::vector<std::int32_t> mSlots;
    std::size_t mTileCount = 0;
    std::vector<glm::u16vec4> mCells;
    float mCellScale = 1.f;
};

/// Cache key of a bake: the scene's content hash combined with every setting that changes
/// the result.
std::uint64_t vlfKey(const VlfScene& scene, const VlfSettings& settings);

} // namespace qgi::vlf
