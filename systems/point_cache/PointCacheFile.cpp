#include "systems/point_cache/PointCacheFile.h"

#include "runtime/io/AtomicFile.h"
#include "runtime/io/CacheFile.h"

#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Finite.h"
#include "runtime/core/Hash.h"
#include "runtime/ecs/Registry.h"
#include "runtime/scene/SceneQueries.h"
#include "systems/photon_update/PhotonEmitter.h"
#include "systems/photon_update/PhotonSettings.h"
#include "systems/point_cache/PointCache.h"

#include <glm/geometric.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

namespace qgi {
namespace {

constexpr const char* kMagic = kPointCacheMagic.data();
constexpr std::size_t kMagicSize = kPointCacheMagic.size();
constexpr std::uint32_t kEndian = 0x01020304u;

void put(std::vector<char>& out, const void* data, std::size_t size) {
    const char* p = static_cast<const char*>(data);
    out.insert(out.end(), p, p + size);
}
template <typename T> void putValue(std::vector<char>& out, const T& v) {
    put(out, &v, sizeof v);
}
template <typename T> void putArray(std::vector<char>& out, const std::vector<T>& v) {
    if (!v.empty()) put(out, v.data(), v.size() * sizeof(T));
}

class Reader {
public:
    Reader(const std::vector<char>& data, std::size_t end, const std::string& path)
        : mData(data), mEnd(end), mPath(path) {}
    void get(void* out, std::size_t size) {
        if (size > mEnd - mAt) fail("point cache file '", mPath, "' is truncated");
        std::memcpy(out, mData.data() + mAt, size);
        mAt += size;
    }
    template <typename T> T value() {
        T v;
        get(&v, sizeof v);
        return v;
    }
    template <typename T> void array(std::vector<T>& v, std::size_t count) {
        if (count > (mEnd - mAt) / sizeof(T)) fail("point cache file '", mPath, "' is truncated");
        v.resize(count);
        if (count) get(v.data(), count * sizeof(T));
    }
    std::size_t remaining() const { return mEnd - mAt; }

private:
    const std::vector<char>& mData;
    std::size_t mEnd, mAt = 0;
    const std::string& mPath;
};

} // namespace

std::uint64_t pointCacheKey(const Registry& registry, const PointCacheSettings& s) {
    Fnv1aHasher h;
    h.add(kPointCacheFileVersion);
    h.add(kPointCacheBakeRevision);
    for (const auto v :
         {s.seed, std::uint64_t(s.particleCount), std::uint64_t(s.particleBounces),
          std::uint64_t(s.stopAfterRejections), s.maxDarts, std::uint64_t(s.maxPoints),
          std::uint64_t(s.aoRays), std::uint64_t(s.trivialTests), std::uint64_t(s.shadowSamples)})
        h.add(v);
    for (const float v : {s.rMin, s.rMax, s.aoDistance})
        h.add(v);
    const auto mesh = [&](Entity, const Mesh& m, const WorldTransform& world, bool mobile) {
        h.add(std::uint8_t(mobile));
        h.add(world.matrix);
        h.addArray(m.positions);
        h.addArray(m.indices);
    };
    registry.view<const StaticMesh, const Mesh, const WorldTransform>().each(
        [&](Entity e, const StaticMesh&, const Mesh& m, const WorldTransform& w) {
            mesh(e, m, w, false);
            if (const Material* mat = registry.tryGet<Material>(e)) {
                h.add(mat->emission);
                if (mat->emission != glm::vec3(0.f))
                    h.add(std::uint8_t(hasLightStandIn(registry, e)));
            }
        });
    registry.view<const MobileMesh, const Mesh, const WorldTransform>().each(
        [&](Entity e, const MobileMesh& mobile, const Mesh& m, const WorldTransform& w) {
            mesh(e, m, w, true);
            h.add(std::uint8_t(mobile.active)); // out of the world: no shadow in the cache
            if (const Material* mat = registry.tryGet<Material>(e)) h.add(mat->emission);
        });
    std::vector<PhotonEmitter> lights;
    findEmitterSources(registry, PhotonSettings{}, lights);
    for (const PhotonEmitter& l : lights) {
        h.add(l.kind);
        h.add(l.world);
        h.add(l.radiant);
        h.add(l.innerAngle);
        h.add(l.outerAngle);
    }
    return h.value();
}

void writePointCacheFile(const std::string& path, std::uint64_t key, const PointCache& c) {
    checkCacheTarget(path, kPointCacheMagic, "point cache file");
    std::vector<char> out;
    put(out, kMagic, kMagicSize);
    putValue(out, kPointCacheFileVersion);
    putValue(out, kEndian);
    putValue(out, key);
    const std::size_t totalAt = out.size();
    putValue(out, std::uint64_t(0)); // total bytes, patched below
    putValue(out, std::uint64_t(c.size()));
    putValue(out, c.lightCount);
    putValue(out, c.sampleWords);
    putArray(out, c.position);
    putArray(out, c.normal);
    putArray(out, c.radius);
    putArray(out, c.dart);
    putArray(out, c.ao);
    putArray(out, c.direct);
    putArray(out, c.visibility);
    putArray(out, c.reached);
    const std::uint64_t total = out.size() + sizeof(std::uint64_t);
    std::memcpy(out.data() + totalAt, &total, sizeof total);
    Fnv1aHasher sum;
    sum.addBytes(out.data(), out.size());
    putValue(out, sum.value());

    writeFileAtomically(path, std::string_view(out.data(), out.size()), "point cache file");
}

void readPointCacheFile(const std::string& path, std::uint64_t key, PointCache& cache) {
    std::ifstream file(path, std::ios::binary);
    if (!file) fail("point cache file '", path, "' cannot be opened");
    std::vector<char> data((std::istreambuf_iterator<char>(file)),
                           std::istreambuf_iterator<char>());
    if (data.size() < kMagicSize + 40 + sizeof(std::uint64_t))
        fail("point cache file '", path, "' is truncated (", data.size(), " bytes)");
    if (std::memcmp(data.data(), kMagic, kMagicSize) != 0)
        fail("point cache file '", path, "' is not a point cache file (bad magic)");
    const std::size_t body = data.size() - sizeof(std::uint64_t);
    Reader in(data, body, path);
    char magic[8];
    in.get(magic, sizeof magic);
    const auto version = in.value<std::uint32_t>();
    if (version != kPointCacheFileVersion)
        fail("point cache file '", path, "' has version ", version, ", expected ",
             kPointCacheFileVersion, " (stale)");
    if (in.value<std::uint32_t>() != kEndian)
        fail("point cache file '", path, "' was written on a machine of other byte order");
    if (in.value<std::uint64_t>() != key)
        fail("point cache file '", path, "' was made for another scene or other settings (stale)");
    const auto total = in.value<std::uint64_t>();
    if (total != data.size())
        fail("point cache file '", path, "' is truncated or extended (", data.size(),
             " bytes, its header says ", total, ")");
    std::uint64_t stored = 0;
    std::memcpy(&stored, data.data() + body, sizeof stored);
    Fnv1aHasher sum;
    sum.addBytes(data.data(), body);
    if (sum.value() != stored) fail("point cache file '", path, "' is corrupt (checksum mismatch)");

    const auto points = in.value<std::uint64_t>();
    const auto lights = in.value<std::uint32_t>();
    const auto words = in.value<std::uint32_t>();
    if (words > recordedShadowWords(kMaxRecordedShadowSamples))
        fail("point cache file '", path, "' records ", words,
             " words of shadow samples per light, more than are ever written");
    const std::uint64_t perPoint = 4 * (3 + 3 + 1 + 1 + 1 + 3) + 4ull * lights * (1 + words);
    if (points > in.remaining() / perPoint || points * perPoint != in.remaining())
        fail("point cache file '", path, "' has a size that does not match its ", points,
             " points and ", lights, " lights");
    PointCache read;
    in.array(read.position, points);
    in.array(read.normal, points);
    in.array(read.radius, points);
    in.array(read.dart, points);
    in.array(read.ao, points);
    in.array(read.direct, points);
    in.array(read.visibility, points * lights);
    in.array(read.reached, points * lights * words);
    for (std::size_t p = 0; p < points; ++p) {
        const float nl = glm::length(read.normal[p]);
        if (!isFinite(read.position[p]) || !isFinite(read.direct[p]) ||
            !(std::abs(nl - 1.f) < 1e-3f) ||
            !(read.radius[p] > 0.f && std::isfinite(read.radius[p])) ||
            !(read.ao[p] >= 0.f && read.ao[p] <= 1.f))
            fail("point cache file '", path, "': point ", p, " holds values out of range");
    }
    for (const float v : read.visibility)
        if (!(v >= 0.f && v <= 1.f))
            fail("point cache file '", path, "': a visibility is outside [0, 1]");
    cache.position = std::move(read.position);
    cache.normal = std::move(read.normal);
    cache.radius = std::move(read.radius);
    cache.dart = std::move(read.dart);
    cache.ao = std::move(read.ao);
    cache.direct = std::move(read.direct);
    cache.visibility = std::move(read.visibility);
    cache.lightCount = lights;
    cache.sampleWords = words;
    cache.reached = std::move(read.reached);
}

} // namespace qgi
