// libFuzzer harnesses for the two bake caches a game finds on disk, the point cache
// (readPointCacheFile) and the VLF (VlfCache::load). Their checksums would stop almost every
// mutation at the door, so each input is first given a valid checksum, length and key: what is
// fuzzed is what the readers check after that. VLF inputs are loaded for the seed's scene and
// settings (a file of another scene is refused), and a loaded VLF is looked up on every face.
// Built twice, as fuzz_point_cache (QGI_FUZZ_POINT_CACHE) and fuzz_vlf_cache.
// With QGI_FUZZ_SEED=<file> set, the harness first writes a small valid file there.

#include "FuzzFile.h"

#include "runtime/core/Hash.h"

#include <cstring>
#include <vector>

#ifdef QGI_FUZZ_POINT_CACHE
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointCacheFile.h"

namespace {

void writeSeed(const char* path) {
    qgi::PointCache cache;
    cache.lightCount = 2;
    cache.sampleWords = 1;
    for (int p = 0; p < 3; ++p) {
        cache.position.emplace_back(float(p), 0.f, 0.f);
        cache.normal.emplace_back(0.f, 1.f, 0.f);
        cache.radius.push_back(0.1f);
        cache.dart.push_back(std::uint32_t(p));
        cache.ao.push_back(0.5f);
        cache.direct.emplace_back(1.f, 2.f, 3.f);
        cache.visibility.insert(cache.visibility.end(), {1.f, 0.25f});
        cache.reached.insert(cache.reached.end(), {0xffffu, 0x00f0u});
    }
    qgi::writePointCacheFile(path, 42, cache);
}

constexpr std::size_t kKeyAt = 16, kTotalAt = 24, kHeader = 32;

/// Key, length and checksum made valid; returns the key.
std::uint64_t repair(std::vector<std::uint8_t>& bytes) {
    if (bytes.size() < kHeader + 8) return 0;
    const std::uint64_t total = bytes.size();
    std::memcpy(&bytes[kTotalAt], &total, 8);
    qgi::Fnv1aHasher sum;
    sum.addBytes(bytes.data(), bytes.size() - 8);
    const std::uint64_t value = sum.value();
    std::memcpy(&bytes[bytes.size() - 8], &value, 8);
    std::uint64_t key = 0;
    std::memcpy(&key, &bytes[kKeyAt], 8);
    return key;
}

void load(const std::filesystem::path& path, std::uint64_t key) {
    qgi::PointCache cache;
    qgi::readPointCacheFile(path.string(), key, cache);
    const std::size_t n = cache.position.size();
    if (cache.normal.size() != n || cache.radius.size() != n || cache.dart.size() != n ||
        cache.ao.size() != n || cache.direct.size() != n ||
        cache.visibility.size() != n * cache.lightCount ||
        cache.reached.size() != n * cache.lightCount * cache.sampleWords) {
        std::fprintf(stderr, "readPointCacheFile returned arrays of different sizes\n");
        std::abort();
    }
}

constexpr const char* kName = "input.pcache";

} // namespace

#else
#include "systems/vlf/Vlf.h"
#include "systems/vlf/VlfBake.h"
#include "systems/vlf/VlfCache.h"
#include "tests/unit/test_vlf_scenes.h"

namespace {

/// The scene and settings every input is loaded for (the seed's).
const qgi::vlf::VlfScene& scene() {
    static const auto room = qgi::test::glossyRoom();
    return *room;
}
qgi::VlfSettings settings() {
    qgi::VlfSettings s;
    s.directionLevel = 1;
    s.linesPerSide = 8;
    s.tileSize = 4;
    s.iterations = 1;
    return s;
}

void writeSeed(const char* path) {
    qgi::vlf::VlfCache::save(qgi::vlf::bakeVlf(scene(), settings()), path);
}

constexpr std::size_t kKeyAt = 12, kSizeAt = 20, kHashAt = 28, kHeader = 36;

std::uint64_t repair(std::vector<std::uint8_t>& bytes) {
    if (bytes.size() < kHeader) return 0;
    const std::uint64_t size = bytes.size() - kHeader;
    std::memcpy(&bytes[kSizeAt], &size, 8);
    qgi::Fnv1aHasher sum;
    sum.addBytes(bytes.data() + kHeader, size);
    const std::uint64_t value = sum.value();
    std::memcpy(&bytes[kHashAt], &value, 8);
    const std::uint64_t key = qgi::vlf::vlfKey(scene(), settings());
    std::memcpy(&bytes[kKeyAt], &key, 8);
    return key;
}

void load(const std::filesystem::path& path, std::uint64_t) {
    const qgi::vlf::Vlf v = qgi::vlf::VlfCache::load(path, scene(), settings());
    for (std::uint32_t f = 0; f < v.faces().size(); ++f) {
        const qgi::vlf::Face& face = v.faces()[f];
        const glm::vec3 x =
            face.origin + 0.5f * (face.extentU * face.axisU + face.extentV * face.axisV);
        (void)v.radiance(f, x, face.normal);
        (void)v.radiance(f, face.origin, -face.normal);
    }
}

constexpr const char* kName = "input.vlf";

} // namespace
#endif

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const char* seed = std::getenv("QGI_FUZZ_SEED")) writeSeed(seed);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::vector<std::uint8_t> bytes(data, data + size);
    const std::uint64_t key = repair(bytes);
    const auto path = qgi::fuzz::writeInput(kName, bytes.data(), bytes.size());
    try {
        load(path, key);
    } catch (const qgi::Error& error) {
        qgi::fuzz::checkMessage(error);
    }
    return 0;
}
