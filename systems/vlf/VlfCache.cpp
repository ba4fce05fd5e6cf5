#include "systems/vlf/VlfCache.h"

#include "runtime/io/AtomicFile.h"
#include "runtime/io/CacheFile.h"

#include "runtime/core/Error.h"
#include "runtime/core/Finite.h"
#include "runtime/core/Hash.h"
#include "runtime/core/Log.h"
#include "systems/vlf/VlfBake.h"

#include <glm/geometric.hpp>
#include <glm/vector_relational.hpp>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>

namespace qgi::vlf {
namespace {

class Writer {
public:
    template <typename T> void put(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        const auto* p = reinterpret_cast<const char*>(&v);
        bytes.insert(bytes.end(), p, p + sizeof(T));
    }
    template <typename T> void putVector(const std::vector<T>& v) {
        put(std::uint64_t(v.size()));
        const auto* p = reinterpret_cast<const char*>(v.data());
        bytes.insert(bytes.end(), p, p + v.size() * sizeof(T));
    }
    std::vector<char> bytes;
};

class Reader {
public:
    Reader(const std::vector<char>& b, const std::string& file) : bytes(b), path(file) {}
    template <typename T> T get() {
        static_assert(std::is_trivially_copyable_v<T>);
        if (bytes.size() - pos < sizeof(T))
            fail(path, ": VLF cache is corrupt (payload truncated)");
        T v;
        std::memcpy(&v, bytes.data() + pos, sizeof(T));
        pos += sizeof(T);
        return v;
    }
    template <typename T> std::vector<T> getVector(std::size_t expected = SIZE_MAX) {
        const std::uint64_t n = get<std::uint64_t>();
        if (n > (bytes.size() - pos) / sizeof(T) || (expected != SIZE_MAX && n != expected))
            fail(path, ": VLF cache is corrupt (an array size does not match)");
        std::vector<T> v(n);
        if (n > 0) std::memcpy(v.data(), bytes.data() + pos, n * sizeof(T));
        pos += n * sizeof(T);
        return v;
    }
    const std::vector<char>& bytes;
    std::string path;
    std::size_t pos = 0;
};

struct FacePod {
    glm::vec3 normal;
    float offset;
    glm::vec3 origin, axisU, axisV;
    float extentU, extentV, area;
    glm::vec3 diffuse, emission, specular;
    float phongExponent;
};

bool isUnit(const glm::vec3& v) {
    return isFinite(v) && std::abs(glm::length(v) - 1.f) < 1e-3f;
}
bool isColour(const glm::vec3& v) {
    return isFinite(v) && glm::all(glm::greaterThanEqual(v, glm::vec3(0.f)));
}
bool isLength(float v) {
    return std::isfinite(v) && v >= 0.f;
}

/// What a loaded field must satisfy before a lookup may index with it: the checksum only
/// proves the file is as written, not that it was written by this code.
void checkLoaded(const Vlf& v, const std::string& name) {
    const auto corrupt = [&](const char* what) {
        fail(name, ": VLF cache is corrupt (", what, ")");
    };
    if (!isFinite(v.center()) || !(std::isfinite(v.radius()) && v.radius() > 0.f))
        corrupt("the bounding sphere is not finite and positive");
    for (const Face& f : v.faces())
        if (!isUnit(f.normal) || !isUnit(f.axisU) || !isUnit(f.axisV) || !isFinite(f.origin) ||
            !std::isfinite(f.offset) || !isLength(f.extentU) || !isLength(f.extentV) ||
            !isLength(f.area) || !isColour(f.diffuse) || !isColour(f.emission) ||
            !isColour(f.specular) || !isLength(f.phongExponent))
            corrupt("a face holds values out of range");
    for (const FaceMap& m : v.faceMaps())
        if (!(std::isfinite(m.texelU) && m.texelU > 0.f && std::isfinite(m.texelV) &&
              m.texelV > 0.f))
            corrupt("a texel size is not positive");
    for (const float c : v.texelCoverage())
        if (!(c >= 0.f && c <= 1.f)) corrupt("a texel coverage is outside [0, 1]");
    for (const glm::vec3& e : v.irradiance())
        if (!isColour(e)) corrupt("an irradiance is negative or not finite");
    // Every specular face listed once, in face order, and indexed back; no other face.
    for (std::uint32_t f = 0; f < v.faces().size(); ++f) {
        const std::int32_t sf = v.specularIndex(f);
        if (sf < -1 || (sf >= 0 && std::size_t(sf) >= v.specularFaceCount()))
            corrupt("a specular index is out of range");
        if ((sf >= 0) != v.faces()[f].isSpecular())
            corrupt("a specular index disagrees with its face's material");
    }
    for (std::size_t sf = 0; sf < v.specularFaceCount(); ++sf)
        if (v.specularIndex(v.specularFace(sf)) != std::int32_t(sf) ||
            (sf > 0 && v.specularFace(sf) <= v.specularFace(sf - 1)))
            corrupt("specular faces do not match their index");
    if (!(v.cellScale() >= 1.f) || !std::isfinite(v.cellScale()) ||
        std::exp2(std::round(std::log2(v.cellScale()))) != v.cellScale())
        corrupt("the cells' scale is not a power of two of at least 1");
    for (const glm::u16vec4& packed : v.cells()) {
        const glm::vec4 cell = unpackCell(packed, 1.f);
        if (!isColour(glm::vec3(cell)) || !(cell.w == 0.f || cell.w == 1.f))
            corrupt("a tile cell is negative or not finite");
    }
}

/// The scene and settings a loaded field was baked for must be these: the key says so
/// only as far as a hash can, and lookups index the field by the scene's face numbers.
void checkScene(const Vlf& v, const VlfScene& scene, const VlfSettings& settings,
                const std::string& name) {
    const auto stale = [&](const char* what) {
        fail(name, ": VLF cache is stale (", what, " differ from the scene's)");
    };
    const VlfSettings& s = v.settings();
    if (s.directionLevel != settings.directionLevel || s.linesPerSide != settings.linesPerSide ||
        s.tileSize != settings.tileSize || s.iterations != settings.iterations ||
        s.jitterSamples != settings.jitterSamples || s.texelCells != settings.texelCells ||
        s.filterSigma != settings.filterSigma || s.glossyCutoff != settings.glossyCutoff ||
        s.seed != settings.seed)
        stale("its settings");
    if (v.faces().size() != scene.faces().size()) stale("its faces");
    for (std::size_t f = 0; f < scene.faces().size(); ++f) {
        const Face& a = v.faces()[f];
        const Face& b = scene.faces()[f];
        if (a.normal != b.normal || a.offset != b.offset || a.origin != b.origin ||
            a.axisU != b.axisU || a.axisV != b.axisV || a.extentU != b.extentU ||
            a.extentV != b.extentV || a.area != b.area || a.diffuse != b.diffuse ||
            a.emission != b.emission || a.specular != b.specular ||
            a.phongExponent != b.phongExponent)
            stale("its faces");
    }
}

} // namespace

void VlfCache::save(const Vlf& v, const std::filesystem::path& path) {
    Writer w;
    const VlfSettings& s = v.mSettings;
    w.put(s.directionLevel);
    w.put(s.linesPerSide);
    w.put(s.tileSize);
    w.put(s.iterations);
    w.put(s.jitterSamples);
    w.put(s.texelCells);
    w.put(s.filterSigma);
    w.put(s.glossyCutoff);
    w.put(s.seed);
    w.put(v.mCenter);
    w.put(v.mRadius);
    std::vector<FacePod> faces;
    for (const Face& f : v.mFaces)
        faces.push_back({f.normal, f.offset, f.origin, f.axisU, f.axisV, f.extentU, f.extentV,
                         f.area, f.diffuse, f.emission, f.specular, f.phongExponent});
    w.putVector(faces);
    w.putVector(v.mFaceMaps);
    w.putVector(v.mCoverage);
    w.putVector(v.mIrradiance);
    w.putVector(v.mSpecularIndex);
    w.putVector(v.mSpecularFaces);
    w.putVector(v.mBlocks);
    w.putVector(v.mSlots);
    w.put(std::uint64_t(v.mTileCount));
    w.put(v.mCellScale);
    w.putVector(v.mCells);

    Fnv1aHasher h;
    h.addBytes(w.bytes.data(), w.bytes.size());
    checkCacheTarget(path, kMagic, "VLF cache file");
    std::string file(kMagic.data(), kMagic.size());
    const auto append = [&](const auto& value) {
        file.append(reinterpret_cast<const char*>(&value), sizeof(value));
    };
    append(std::uint32_t(kVersion));
    append(std::uint64_t(v.mKey));
    append(std::uint64_t(w.bytes.size()));
    append(std::uint64_t(h.value()));
    file.append(w.bytes.data(), w.bytes.size());
    writeFileAtomically(path, file, "the VLF cache");
}

Vlf VlfCache::load(const std::filesystem::path& path, const VlfScene& scene,
                   const VlfSettings& settings) {
    const std::uint64_t expectedKey = vlfKey(scene, settings);
    const std::string name = path.string();
    std::ifstream in(path, std::ios::binary);
    if (!in) fail(name, ": no VLF cache file");
    char magic[8];
    std::uint32_t version = 0;
    std::uint64_t key = 0, size = 0, hash = 0;
    in.read(magic, sizeof(magic));
    if (!in || std::string_view(magic, sizeof(magic)) != kMagic)
        fail(name, ": not a VLF cache file (bad magic)");
    in.read(reinterpret_cast<char*>(&version), sizeof(version));
    in.read(reinterpret_cast<char*>(&key), sizeof(key));
    in.read(reinterpret_cast<char*>(&size), sizeof(size));
    in.read(reinterpret_cast<char*>(&hash), sizeof(hash));
    if (!in) fail(name, ": VLF cache is corrupt (header truncated)");
    if (version != kVersion)
        fail(name, ": VLF cache has format version ", version, ", this build reads ", kVersion);
    if (key != expectedKey)
        fail(name, ": VLF cache is stale (it was baked for another scene or other settings)");
    const std::uintmax_t fileSize = std::filesystem::file_size(path);
    const std::uintmax_t header = kMagic.size() + sizeof(version) + 3 * sizeof(std::uint64_t);
    if (fileSize != header + size) fail(name, ": VLF cache is corrupt (file size does not match)");
    std::vector<char> bytes(size);
    in.read(bytes.data(), std::streamsize(size));
    if (!in) fail(name, ": VLF cache is corrupt (payload truncated)");
    Fnv1aHasher h;
    h.addBytes(bytes.data(), bytes.size());
    if (h.value() != hash) fail(name, ": VLF cache is corrupt (payload hash does not match)");

    Reader r(bytes, name);
    Vlf v;
    VlfSettings& s = v.mSettings;
    s.directionLevel = r.get<int>();
    s.linesPerSide = r.get<int>();
    s.tileSize = r.get<int>();
    s.iterations = r.get<int>();
    s.jitterSamples = r.get<int>();
    s.texelCells = r.get<float>();
    s.filterSigma = r.get<float>();
    s.glossyCutoff = r.get<float>();
    s.seed = r.get<std::uint64_t>();
    try {
        validate(s);
    } catch (const Error& e) {
        fail(name, ": VLF cache is corrupt (", e.what(), ")");
    }
    v.mKey = key;
    v.mCenter = r.get<glm::vec3>();
    v.mRadius = r.get<float>();
    v.mDirections = std::make_shared<DirectionSet>(s.directionLevel);
    for (std::size_t i = 0; i < v.mDirections->size(); ++i)
        v.mFrames.push_back(makeSubfieldFrame(v.mDirections->direction(i)));
    for (const FacePod& p : r.getVector<FacePod>()) {
        Face f;
        f.normal = p.normal;
        f.offset = p.offset;
        f.origin = p.origin;
        f.axisU = p.axisU;
        f.axisV = p.axisV;
        f.extentU = p.extentU;
        f.extentV = p.extentV;
        f.area = p.area;
        f.diffuse = p.diffuse;
        f.emission = p.emission;
        f.specular = p.specular;
        f.phongExponent = p.phongExponent;
        v.mFaces.push_back(f);
    }
    const std::size_t nf = v.mFaces.size();
    v.mFaceMaps = r.getVector<FaceMap>(nf);
    std::uint64_t texels = 0; // firstTexel is 32 bits: so is every texel index
    for (const FaceMap& m : v.mFaceMaps) {
        if (m.firstTexel != texels || m.width == 0 || m.height == 0 || m.width > (1u << 30) ||
            m.height > (1u << 30) || std::uint64_t(m.width) * m.height > UINT32_MAX - texels)
            fail(name, ": VLF cache is corrupt (irradiance maps do not line up)");
        texels += std::uint64_t(m.width) * m.height;
    }
    v.mCoverage = r.getVector<float>(texels);
    v.mIrradiance = r.getVector<glm::vec3>(texels);
    v.mSpecularIndex = r.getVector<std::int32_t>(nf);
    v.mSpecularFaces = r.getVector<std::uint32_t>();
    for (std::uint32_t f : v.mSpecularFaces)
        if (f >= nf) fail(name, ": VLF cache is corrupt (specular face out of range)");
    v.mBlocks = r.getVector<TileBlock>(v.mSpecularFaces.size() * v.mDirections->size());
    v.mSlots = r.getVector<std::int32_t>();
    const std::uint64_t tileCount = r.get<std::uint64_t>();
    const std::size_t cellsPerTile = std::size_t(s.tileSize) * s.tileSize;
    if (bytes.size() - r.pos < sizeof(float) ||
        tileCount > (bytes.size() - r.pos - sizeof(float)) / (cellsPerTile * sizeof(glm::u16vec4)))
        fail(name, ": VLF cache is corrupt (more tiles than the file holds)");
    v.mTileCount = std::size_t(tileCount);
    const std::int64_t n = s.linesPerSide / s.tileSize;
    for (const TileBlock& b : v.mBlocks) {
        if (b.side < -1 || b.side > 1)
            fail(name, ": VLF cache is corrupt (a tile block faces no side)");
        if (b.side != 0 && (b.s0 < 0 || b.t0 < 0 || b.sw < 1 || b.tw < 1 ||
                            std::int64_t(b.s0) + b.sw > n || std::int64_t(b.t0) + b.tw > n ||
                            std::uint64_t(b.firstSlot) + std::uint64_t(b.sw) * std::uint64_t(b.tw) >
                                v.mSlots.size()))
            fail(name, ": VLF cache is corrupt (a tile block is out of range)");
    }
    for (std::int32_t slot : v.mSlots)
        if (slot < -1 || (slot >= 0 && std::size_t(slot) >= v.mTileCount))
            fail(name, ": VLF cache is corrupt (a tile slot is out of range)");
    v.mCellScale = r.get<float>();
    v.mCells = r.getVector<glm::u16vec4>(v.mTileCount * cellsPerTile);
    if (r.pos != bytes.size()) fail(name, ": VLF cache is corrupt (trailing bytes)");
    checkLoaded(v, name);
    checkScene(v, scene, settings, name);
    return v;
}

Vlf VlfCache::loadOrBake(const VlfScene& scene, const VlfSettings& settings,
                         const std::filesystem::path& path, bool* baked, VlfBakeStats* stats) {
    validate(settings);
    std::error_code error;
    if (!path.empty() && !std::filesystem::exists(path, error)) {
        logInfo("VLF: no cache file ", path.string(), " yet: baking, then writing it");
    } else if (!path.empty()) {
        try {
            Vlf v = load(path, scene, settings);
            if (baked) *baked = false;
            logInfo("VLF: loaded ", path.string());
            return v;
        } catch (const Error& e) {
            logWarning(e.what(), "; baking anew");
        }
    }
    Vlf v = bakeVlf(scene, settings, stats);
    if (baked) *baked = true;
    if (!path.empty()) {
        // A cache that cannot be written costs the next start a bake, not this one its field.
        try {
            save(v, path);
            logInfo("VLF: saved ", path.string());
        } catch (const Error& e) {
            logWarning(e.what(), "; the VLF is used without a cache file");
        }
    }
    return v;
}

} // namespace qgi::vlf
