#include "systems/vlf/Vlf.h"

#include "runtime/core/Error.h"
#include "runtime/core/Hash.h"
#include "runtime/render/ShaderInterface.h"

#include <glm/geometric.hpp>
#include <glm/gtc/packing.hpp>
#include <glm/vec2.hpp>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace qgi::vlf {

float packCells(std::span<const glm::vec4> cells, std::vector<glm::u16vec4>& out) {
    constexpr float kLargest = 16384.f; // a quarter of the largest half float
    const auto usable = [](float v) { return std::isfinite(v) && v > 0.f ? v : 0.f; };
    float largest = 0.f;
    for (const glm::vec4& c : cells)
        largest = std::max({largest, usable(c.x), usable(c.y), usable(c.z)});
    float scale = 1.f;
    while (largest / scale > kLargest)
        scale *= 2.f;
    const std::uint16_t one = glm::packHalf1x16(1.f);
    out.resize(cells.size());
    for (std::size_t i = 0; i < cells.size(); ++i) {
        const glm::vec4& c = cells[i];
        out[i] = {glm::packHalf1x16(usable(c.x) / scale), glm::packHalf1x16(usable(c.y) / scale),
                  glm::packHalf1x16(usable(c.z) / scale), c.w > 0.f ? one : std::uint16_t(0)};
    }
    return scale;
}

glm::vec4 unpackCell(const glm::u16vec4& cell, float scale) {
    return {glm::unpackHalf1x16(cell.x) * scale, glm::unpackHalf1x16(cell.y) * scale,
            glm::unpackHalf1x16(cell.z) * scale, glm::unpackHalf1x16(cell.w)};
}
namespace {

/// Separating-axis test of a 2D triangle against the box [lo, hi].
bool overlaps(const std::array<glm::vec2, 3>& tri, const glm::vec2& lo, const glm::vec2& hi) {
    glm::vec2 tmin = glm::min(tri[0], glm::min(tri[1], tri[2]));
    glm::vec2 tmax = glm::max(tri[0], glm::max(tri[1], tri[2]));
    if (tmax.x < lo.x || tmin.x > hi.x || tmax.y < lo.y || tmin.y > hi.y) return false;
    const std::array<glm::vec2, 4> box{lo, {hi.x, lo.y}, hi, {lo.x, hi.y}};
    for (int e = 0; e < 3; ++e) {
        const glm::vec2 a = tri[e], b = tri[(e + 1) % 3];
        const glm::vec2 axis(a.y - b.y, b.x - a.x);
        float t0 = glm::dot(axis, a), t1 = glm::dot(axis, tri[(e + 2) % 3]);
        const float triMin = std::min(t0, t1), triMax = std::max(t0, t1);
        float bmin = glm::dot(axis, box[0]), bmax = bmin;
        for (int k = 1; k < 4; ++k) {
            const float p = glm::dot(axis, box[k]);
            bmin = std::min(bmin, p);
            bmax = std::max(bmax, p);
        }
        if (bmax < triMin || bmin > triMax) return false;
    }
    return true;
}

/// Area of the triangle `tri` inside the box [lo, hi] (Sutherland-Hodgman clipping of the
/// triangle against the box's four half-planes, then the shoelace formula).
double clippedArea(const std::array<glm::dvec2, 3>& tri, const glm::dvec2& lo,
                   const glm::dvec2& hi) {
    std::array<glm::dvec2, 8> a{}, b{}; // a convex polygon gains at most one vertex per clip
    std::size_t n = 3;
    for (std::size_t i = 0; i < 3; ++i)
        a[i] = tri[i];
    for (int side = 0; side < 4 && n > 0; ++side) {
        const int axis = side / 2;
        const bool upper = side % 2 == 1;
        const double bound = upper ? hi[axis] : lo[axis];
        const auto in = [&](const glm::dvec2& p) {
            return upper ? p[axis] <= bound : p[axis] >= bound;
        };
        std::size_t m = 0;
        for (std::size_t i = 0; i < n; ++i) {
            const glm::dvec2& p = a[i];
            const glm::dvec2& q = a[(i + 1) % n];
            const bool pin = in(p), qin = in(q);
            if (pin) b[m++] = p;
            if (pin != qin) {
                const double t = (bound - p[axis]) / (q[axis] - p[axis]);
                b[m++] = p + t * (q - p);
            }
        }
        a = b;
        n = m;
    }
    double twice = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const glm::dvec2& p = a[i];
        const glm::dvec2& q = a[(i + 1) % n];
        twice += p.x * q.y - q.x * p.y;
    }
    return 0.5 * std::abs(twice);
}

/// floor(v) as an int, saturated to +-2^30 (NaN reads as -2^30): far outside every map and
/// grid, where converting the float itself would be undefined.
int floorIndex(float v) {
    constexpr float kLimit = 1073741824.f;
    if (!(v >= -kLimit)) return -(1 << 30);
    return v <= kLimit ? int(std::floor(v)) : (1 << 30);
}

} // namespace

std::uint64_t vlfKey(const VlfScene& scene, const VlfSettings& s) {
    Fnv1aHasher h;
    h.add(scene.contentHash());
    h.add(s.directionLevel);
    h.add(s.linesPerSide);
    h.add(s.tileSize);
    h.add(s.iterations);
    h.add(s.jitterSamples);
    h.add(s.texelCells);
    h.add(s.filterSigma);
    h.add(s.glossyCutoff);
    h.add(s.seed);
    return h.value();
}

Vlf Vlf::allocate(const VlfScene& scene, const VlfSettings& settings) {
    validate(settings);
    Vlf v;
    v.mSettings = settings;
    v.mDirections = std::make_shared<DirectionSet>(settings.directionLevel);
    v.mKey = vlfKey(scene, settings);
    const Aabb& b = scene.bounds();
    v.mCenter = b.center();
    v.mRadius = std::max(0.5f * glm::length(b.extent()) * 1.001f, 1e-6f);
    const std::size_t l = v.mDirections->size();
    for (std::size_t i = 0; i < l; ++i)
        v.mFrames.push_back(makeSubfieldFrame(v.mDirections->direction(i)));

    v.mFaces = scene.faces();
    for (Face& f : v.mFaces)
        f.triangles.clear();

    // Settings within their ranges can still ask for more than the machine has, or for a tile
    // atlas larger than the renderer can hold: the layout (face maps, tile blocks, which tiles
    // are hit) is cheap and fixes every count, so both limits are checked from it before the
    // large arrays and long before the bake.
    const double limit = settings.maxBakeBytes > 0 ? double(settings.maxBakeBytes)
                                                   : 0.5 * double(::sysconf(_SC_PHYS_PAGES)) *
                                                         double(::sysconf(_SC_PAGESIZE));
    const std::string baking =
        str("VLF: baking ", l, " directions at ", settings.linesPerSide, "x", settings.linesPerSide,
            " lines (direction level ", settings.directionLevel, ") ");
    const auto checkMemory = [&](const VlfMemory& need) {
        if (limit <= 0.0 || double(need.bakeBytes) <= limit) return;
        const std::string detail =
            str("needs about ", double(need.bakeBytes) / 1e9, " GB, over the ", limit / 1e9,
                " GB allowed", settings.maxBakeBytes > 0 ? "" : " (half of this machine's memory)");
        throw VlfTooLarge(VlfTooLarge::Limit::Memory, detail,
                          str(baking, detail,
                              " (VlfSettings.maxBakeBytes; by default half of this machine's "
                              "memory): lower the direction level or the lines per side"));
    };

    // Irradiance maps: each face's bounding rectangle in texels.
    const float texel = settings.texelCells * v.cellWidth() * v.mRadius;
    std::uint64_t texels = 0;
    for (const Face& f : v.mFaces) {
        FaceMap m;
        m.width = std::uint32_t(std::clamp(std::ceil(f.extentU / texel), 1.f, 4096.f));
        m.height = std::uint32_t(std::clamp(std::ceil(f.extentV / texel), 1.f, 4096.f));
        m.texelU = std::max(f.extentU / float(m.width), 1e-9f);
        m.texelV = std::max(f.extentV / float(m.height), 1e-9f);
        m.firstTexel = std::uint32_t(texels);
        texels += std::uint64_t(m.width) * m.height;
        if (texels > std::numeric_limits<std::uint32_t>::max())
            fail("VLF: the faces' irradiance maps need more than 2^32 texels (", v.mFaces.size(),
                 " faces at ", texel, " m a texel): raise VlfSettings.texelCells");
        v.mFaceMaps.push_back(m);
    }

    // Tiles: a specular face gets tile (s, t) of subfield i when its projection comes within
    // one cell of the tile, so every bilinear neighbour of a point on the face exists. First
    // the blocks (the projection's bounding rectangle of tiles)...
    v.mSpecularIndex.assign(v.mFaces.size(), -1);
    for (std::size_t fi = 0; fi < v.mFaces.size(); ++fi)
        if (v.mFaces[fi].isSpecular()) {
            v.mSpecularIndex[fi] = std::int32_t(v.mSpecularFaces.size());
            v.mSpecularFaces.push_back(std::uint32_t(fi));
        }
    const int N = settings.linesPerSide, m = settings.tileSize, n = N / m;
    const float h = v.cellWidth();
    v.mBlocks.assign(v.mSpecularFaces.size() * l, TileBlock{});
    std::size_t slots = 0;
    const auto projected = [&](std::size_t i, std::uint32_t ti) {
        const VlfScene::Triangle& t = scene.triangles()[ti];
        return std::array<glm::vec2, 3>{(v.project(i, t.p0) + 1.f) / h,
                                        (v.project(i, t.p1) + 1.f) / h,
                                        (v.project(i, t.p2) + 1.f) / h};
    };
    for (std::size_t sf = 0; sf < v.mSpecularFaces.size(); ++sf) {
        const Face& f = scene.faces()[v.mSpecularFaces[sf]];
        for (std::size_t i = 0; i < l; ++i) {
            TileBlock& block = v.mBlocks[sf * l + i];
            const float c = glm::dot(f.normal, v.mDirections->direction(i));
            if (std::abs(c) < 1e-4f) continue;
            // Projected triangles in cell units.
            glm::vec2 lo(1e30f), hi(-1e30f);
            for (std::uint32_t ti : f.triangles)
                for (const glm::vec2& q : projected(i, ti)) {
                    lo = glm::min(lo, q);
                    hi = glm::max(hi, q);
                }
            const int s0 = std::clamp(int(std::floor(lo.x - 1.f)) / m, 0, n - 1);
            const int s1 = std::clamp(int(std::floor(hi.x + 1.f)) / m, 0, n - 1);
            const int t0 = std::clamp(int(std::floor(lo.y - 1.f)) / m, 0, n - 1);
            const int t1 = std::clamp(int(std::floor(hi.y + 1.f)) / m, 0, n - 1);
            block.side = c > 0.f ? 1 : -1;
            block.s0 = s0;
            block.t0 = t0;
            block.sw = s1 - s0 + 1;
            block.tw = t1 - t0 + 1;
            block.firstSlot = std::uint32_t(slots);
            slots += std::size_t(block.sw) * block.tw;
        }
    }
    // ...the slots with no tile yet (their share of the memory is known now)...
    checkMemory(vlfMemory(l, 0, m, texels, slots, v.mBlocks.size(), v.mFaces.size()));
    if (slots > std::numeric_limits<std::uint32_t>::max())
        fail(baking, "needs ", slots,
             " tile slots, more than 2^32: lower the direction level or the lines per side");
    v.mSlots.assign(slots, -1);
    // ...then the tiles each triangle touches, testing only those near its own bounds (not
    // every tile of the block against every triangle: a face split into thousands of
    // triangles would take minutes), numbered row by row within each block.
    constexpr std::int32_t kHit = -2;
    for (std::size_t sf = 0; sf < v.mSpecularFaces.size(); ++sf) {
        const Face& f = scene.faces()[v.mSpecularFaces[sf]];
        for (std::size_t i = 0; i < l; ++i) {
            TileBlock& block = v.mBlocks[sf * l + i];
            if (block.side == 0) continue;
            for (std::uint32_t ti : f.triangles) {
                const std::array<glm::vec2, 3> q = projected(i, ti);
                const glm::vec2 lo = glm::min(q[0], glm::min(q[1], q[2]));
                const glm::vec2 hi = glm::max(q[0], glm::max(q[1], q[2]));
                // One tile more on each side than the bounds reach: overlaps() decides.
                const float fm = float(m);
                const int sa = std::max(block.s0, floorIndex((lo.x - 1.f) / fm) - 1);
                const int sb = std::min(block.s0 + block.sw - 1, floorIndex((hi.x + 1.f) / fm) + 1);
                const int ta = std::max(block.t0, floorIndex((lo.y - 1.f) / fm) - 1);
                const int tb = std::min(block.t0 + block.tw - 1, floorIndex((hi.y + 1.f) / fm) + 1);
                for (int t = ta; t <= tb; ++t)
                    for (int s = sa; s <= sb; ++s) {
                        std::int32_t& slot =
                            v.mSlots[block.firstSlot + std::size_t(t - block.t0) * block.sw +
                                     std::size_t(s - block.s0)];
                        if (slot == kHit) continue;
                        const glm::vec2 boxLo(float(s * m) - 1.f, float(t * m) - 1.f);
                        const glm::vec2 boxHi(float((s + 1) * m) + 1.f, float((t + 1) * m) + 1.f);
                        if (overlaps(q, boxLo, boxHi)) slot = kHit;
                    }
            }
            const std::size_t count = std::size_t(block.sw) * block.tw;
            for (std::size_t k = 0; k < count; ++k)
                if (v.mSlots[block.firstSlot + k] == kHit)
                    v.mSlots[block.firstSlot + k] = std::int32_t(v.mTileCount++);
        }
    }

    // Every count is known: the whole bake's memory, and the atlas the renderer will upload.
    checkMemory(vlfMemory(l, v.mTileCount, m, texels, slots, v.mBlocks.size(), v.mFaces.size()));
    if (settings.maxAtlasSize > 0) {
        const shader::VlfAtlasSize atlas = shader::vlfAtlasSize(v.mTileCount, m);
        if (atlas.width > settings.maxAtlasSize || atlas.height > settings.maxAtlasSize) {
            const std::string detail =
                str("needs a tile atlas of ", atlas.width, "x", atlas.height, " texels for its ",
                    v.mTileCount, " tiles, over the GL limit ", settings.maxAtlasSize);
            throw VlfTooLarge(VlfTooLarge::Limit::Atlas, detail,
                              str(baking, detail,
                                  " (VlfSettings.maxAtlasSize): lower the direction level or the "
                                  "lines per side"));
        }
    }

    // Irradiance maps with the exact fraction of each texel inside the face: every triangle,
    // in texel units, clipped against the texels its bounds touch.
    v.mCoverage.assign(texels, 0.f);
    v.mIrradiance.assign(texels, glm::vec3(0.f));
    for (std::size_t fi = 0; fi < scene.faces().size(); ++fi) {
        const Face& f = scene.faces()[fi];
        const FaceMap& fm = v.mFaceMaps[fi];
        std::vector<double> area(std::size_t(fm.width) * fm.height, 0.0);
        for (std::uint32_t ti : f.triangles) {
            const VlfScene::Triangle& t = scene.triangles()[ti];
            std::array<glm::dvec2, 3> q;
            int k = 0;
            for (const glm::vec3& p : {t.p0, t.p1, t.p2})
                q[k++] = glm::dvec2(double(glm::dot(p - f.origin, f.axisU)) / fm.texelU,
                                    double(glm::dot(p - f.origin, f.axisV)) / fm.texelV);
            const glm::dvec2 lo = glm::min(q[0], glm::min(q[1], q[2]));
            const glm::dvec2 hi = glm::max(q[0], glm::max(q[1], q[2]));
            const int x0 = std::max(0, int(std::floor(lo.x))),
                      x1 = std::min(int(fm.width) - 1, int(std::floor(hi.x)));
            const int y0 = std::max(0, int(std::floor(lo.y))),
                      y1 = std::min(int(fm.height) - 1, int(std::floor(hi.y)));
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x)
                    area[std::size_t(y) * fm.width + x] +=
                        clippedArea(q, glm::dvec2(x, y), glm::dvec2(x + 1, y + 1));
        }
        // Triangles of a face do not overlap, so the sums stay within [0, 1] up to rounding;
        // a texel touched only along an edge or a corner (area below 1e-6) holds nothing.
        for (std::size_t tx = 0; tx < area.size(); ++tx)
            v.mCoverage[fm.firstTexel + tx] =
                area[tx] < 1e-6 ? 0.f : float(std::min(area[tx], 1.0));
    }
    v.mCells.assign(v.mTileCount * std::size_t(m) * m, glm::u16vec4(0));
    return v;
}

float Vlf::lineArea() const {
    const float w = cellWidth() * mRadius;
    return w * w;
}

glm::vec2 Vlf::project(std::size_t psf, const glm::vec3& world) const {
    const glm::vec3 p = (world - mCenter) / mRadius;
    return {glm::dot(p, mFrames[psf].u), glm::dot(p, mFrames[psf].v)};
}

glm::vec3 Vlf::linePoint(std::size_t psf, const glm::vec2& uv) const {
    return mCenter + mRadius * (uv.x * mFrames[psf].u + uv.y * mFrames[psf].v);
}

std::uint32_t Vlf::texelAt(std::uint32_t face, const glm::vec3& x) const {
    const Face& f = mFaces[face];
    const FaceMap& m = mFaceMaps[face];
    const int tx =
        std::clamp(floorIndex(glm::dot(x - f.origin, f.axisU) / m.texelU), 0, int(m.width) - 1);
    const int ty =
        std::clamp(floorIndex(glm::dot(x - f.origin, f.axisV) / m.texelV), 0, int(m.height) - 1);
    return m.firstTexel + std::uint32_t(ty) * m.width + std::uint32_t(tx);
}

glm::vec3 Vlf::texelCenter(std::uint32_t face, std::uint32_t x, std::uint32_t y) const {
    const Face& f = mFaces[face];
    const FaceMap& m = mFaceMaps[face];
    return f.origin + (float(x) + 0.5f) * m.texelU * f.axisU +
           (float(y) + 0.5f) * m.texelV * f.axisV;
}

std::int32_t Vlf::tileAt(std::size_t sf, std::size_t psf, int i, int j) const {
    const TileBlock& b = block(sf, psf);
    if (b.side == 0 || i < 0 || j < 0) return -1;
    const int m = mSettings.tileSize;
    const int s = i / m - b.s0, t = j / m - b.t0;
    if (s < 0 || t < 0 || s >= b.sw || t >= b.tw || i >= mSettings.linesPerSide ||
        j >= mSettings.linesPerSide)
        return -1;
    return mSlots[b.firstSlot + std::size_t(t) * b.sw + s];
}

std::int64_t Vlf::cellIndex(std::size_t sf, std::size_t psf, int i, int j) const {
    const std::int32_t tile = tileAt(sf, psf, i, j);
    if (tile < 0) return -1;
    return std::int64_t(cellOffset(tile, i, j, mSettings.tileSize));
}

VlfMemory vlfMemory(std::size_t directions, std::size_t tiles, int tileSize, std::size_t texels,
                    std::size_t slots, std::size_t blocks, std::size_t faces) {
    VlfMemory mem;
    mem.directions = directions;
    mem.tiles = tiles;
    mem.tileCells = tiles * std::size_t(tileSize) * std::size_t(tileSize);
    mem.diffuseTexels = texels;
    // Coverage: one float per texel.
    const std::size_t index = slots * sizeof(std::int32_t) + blocks * sizeof(TileBlock) +
                              faces * sizeof(FaceMap) + texels * sizeof(float);
    mem.renderBytes =
        mem.tileCells * sizeof(glm::u16vec4) + mem.diffuseTexels * sizeof(glm::vec3) + index;
    // The bake adds, per cell: the float cells it packs at the end (RGBA), unshot, next and
    // incident (RGB) plus the incident weight and the incident total for mirrors (RGBA); per
    // texel: unshot and received irradiance, and one accumulation copy per work chunk.
    const std::size_t chunks = std::min(kBakeChunks, mem.directions);
    mem.bakeBytes =
        mem.renderBytes +
        mem.tileCells * (2 * sizeof(glm::vec4) + 3 * sizeof(glm::vec3) + sizeof(float)) +
        mem.diffuseTexels * (2 + chunks) * sizeof(glm::vec3);
    return mem;
}

VlfMemory Vlf::memory() const {
    return vlfMemory(mDirections ? mDirections->size() : 0, mTileCount, mSettings.tileSize,
                     mIrradiance.size(), mSlots.size(), mBlocks.size(), mFaceMaps.size());
}

glm::vec3 Vlf::sampleTexels(const std::vector<glm::vec3>& texels, std::uint32_t face,
                            const glm::vec3& x) const {
    const Face& f = mFaces[face];
    const FaceMap& m = mFaceMaps[face];
    const float fx = glm::dot(x - f.origin, f.axisU) / m.texelU - 0.5f;
    const float fy = glm::dot(x - f.origin, f.axisV) / m.texelV - 0.5f;
    const int x0 = floorIndex(fx), y0 = floorIndex(fy);
    const float ax = fx - float(x0), ay = fy - float(y0);
    glm::vec3 sum(0.f);
    float wsum = 0.f;
    for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
            const int tx = x0 + dx, ty = y0 + dy;
            if (tx < 0 || ty < 0 || tx >= int(m.width) || ty >= int(m.height)) continue;
            const std::size_t t = m.firstTexel + std::size_t(ty) * m.width + tx;
            if (mCoverage[t] <= 0.f) continue;
            const float w = (dx ? ax : 1.f - ax) * (dy ? ay : 1.f - ay);
            sum += w * texels[t];
            wsum += w;
        }
    if (wsum > 0.f) return sum / wsum;
    return texels[texelAt(face, x)]; // outside every covered neighbour: the nearest texel
}

glm::vec3 Vlf::diffuseRadiance(std::uint32_t face, const glm::vec3& x) const {
    const Face& f = mFaces[face];
    constexpr float kInvPi = 0.31830988618f;
    return f.emission + f.diffuse * kInvPi * sampleTexels(mIrradiance, face, x);
}

std::vector<glm::vec4> Vlf::unpackedCells() const {
    std::vector<glm::vec4> out(mCells.size());
    for (std::size_t i = 0; i < mCells.size(); ++i)
        out[i] = unpackCell(mCells[i], mCellScale);
    return out;
}

void Vlf::storeCells(std::span<const glm::vec4> cells) {
    QGI_ASSERT(cells.size() == mCells.size(), "one value per cell");
    mCellScale = packCells(cells, mCells);
}

template <typename Cells>
glm::vec3 Vlf::sampleCells(const Cells& cells, std::size_t sf, std::size_t psf, const glm::vec3& x,
                           float& wOut) const {
    const float h = cellWidth();
    const glm::vec2 c = (project(psf, x) + 1.f) / h - 0.5f;
    const int i0 = floorIndex(c.x), j0 = floorIndex(c.y);
    // A point within 1e-4 cells of a cell centre (float rounding of the projection) takes
    // that cell alone, so a lookup at a cell centre returns the stored value exactly.
    const auto snap = [](float a) { return a < 1e-4f ? 0.f : a > 1.f - 1e-4f ? 1.f : a; };
    const float ax = snap(c.x - float(i0)), ay = snap(c.y - float(j0));
    glm::vec3 sum(0.f);
    float wsum = 0.f;
    for (int dj = 0; dj < 2; ++dj)
        for (int di = 0; di < 2; ++di) {
            const float w = (di ? ax : 1.f - ax) * (dj ? ay : 1.f - ay);
            if (w <= 0.f) continue;
            const std::int64_t k = cellIndex(sf, psf, i0 + di, j0 + dj);
            if (k < 0) continue;
            const glm::vec4 cell = cells[std::size_t(k)];
            if (cell.w <= 0.f) continue;
            sum += w * glm::vec3(cell);
            wsum += w;
        }
    wOut = wsum;
    return wsum > 0.f ? sum / wsum : glm::vec3(0.f);
}

template <typename Cells>
std::optional<glm::vec3> Vlf::lookupTiles(const Cells& cells, std::uint32_t face,
                                          const glm::vec3& x, const glm::vec3& dir) const {
    const std::int32_t sf = mSpecularIndex[face];
    if (sf < 0) return std::nullopt;
    const DirectionTriangle tri = mDirections->locate(dir);
    glm::vec3 sum(0.f);
    float wsum = 0.f;
    for (int k = 0; k < 3; ++k) {
        if (tri.weights[k] <= 0.f) continue;
        const OrientedDirection& c = tri.corners[k];
        // The face's tiles in this subfield hold light along block.side * direction; the
        // corner is usable only when it is that orientation.
        const TileBlock& b = block(std::size_t(sf), c.index);
        if (b.side == 0 || float(b.side) != c.sign) continue;
        float w = 0.f;
        const glm::vec3 value = sampleCells(cells, std::size_t(sf), c.index, x, w);
        if (w <= 0.f) continue;
        sum += tri.weights[k] * value;
        wsum += tri.weights[k];
    }
    if (wsum <= 0.f) return std::nullopt;
    return sum / wsum;
}

glm::vec3 Vlf::specularRadiance(std::uint32_t face, const glm::vec3& x,
                                const glm::vec3& toViewer) const {
    const Face& f = mFaces[face];
    if (!f.isSpecular()) return glm::vec3(0.f);
    std::optional<glm::vec3> value;
    if (f.isMirror()) {
        // Tiles hold incident light, indexed by the front-side direction it arrives from:
        // what the viewer sees arrives from the reflected view direction.
        const glm::vec3 from = 2.f * glm::dot(f.normal, toViewer) * f.normal - toViewer;
        value = lookupTiles(cellView(), face, x, from);
        if (value) *value *= f.specular;
    } else {
        value = lookupTiles(cellView(), face, x, toViewer);
    }
    return value.value_or(glm::vec3(0.f));
}

template glm::vec3 Vlf::sampleCells(const std::vector<glm::vec4>&, std::size_t, std::size_t,
                                    const glm::vec3&, float&) const;
template glm::vec3 Vlf::sampleCells(const PackedCellView&, std::size_t, std::size_t,
                                    const glm::vec3&, float&) const;
template std::optional<glm::vec3> Vlf::lookupTiles(const std::vector<glm::vec4>&, std::uint32_t,
                                                   const glm::vec3&, const glm::vec3&) const;
template std::optional<glm::vec3> Vlf::lookupTiles(const PackedCellView&, std::uint32_t,
                                                   const glm::vec3&, const glm::vec3&) const;

glm::vec3 Vlf::radiance(std::uint32_t face, const glm::vec3& x, const glm::vec3& toViewer) const {
    return diffuseRadiance(face, x) + specularRadiance(face, x, toViewer);
}

} // namespace qgi::vlf
