// The VLF cache file: round trip, stale and corrupt files rejected with a clear message.
#include "runtime/core/Error.h"
#include "systems/vlf/VlfBake.h"
#include "systems/vlf/VlfCache.h"
#include "test_vlf_scenes.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include <unistd.h>

using namespace qgi;
using namespace qgi::vlf;

namespace {

std::unique_ptr<VlfScene> glossyRoom(float lamp = 4.f) {
    test::VlfSceneBuilder b;
    const std::uint32_t wall = b.material(glm::vec3(0.5f));
    const std::uint32_t light = b.material(glm::vec3(0.f), glm::vec3(lamp));
    const std::uint32_t glossy = b.material(glm::vec3(0.3f), glm::vec3(0.f), glm::vec3(0.6f), 10.f);
    const std::uint32_t mirror = b.material(glm::vec3(0.f), glm::vec3(0.f), glm::vec3(0.8f), 0.f);
    b.box({-1.f, 0.f, -1.f}, {1.f, 2.f, 1.f}, true, [&](int axis, int side) {
        if (axis == 1 && side == 0) return glossy;
        if (axis == 0 && side == 1) return light;
        if (axis == 2 && side == 0) return mirror;
        return wall;
    });
    return b.build();
}

VlfSettings small() {
    VlfSettings s;
    s.directionLevel = 2;
    s.linesPerSide = 16;
    s.tileSize = 4;
    s.iterations = 2;
    return s;
}

std::filesystem::path tempFile(const char* name) {
    return std::filesystem::temp_directory_path() /
           (std::string("qgi_test_vlf_") + std::to_string(::getpid()) + "_" + name);
}

std::vector<char> readAll(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}
void writeAll(const std::filesystem::path& p, const std::vector<char>& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

void expectMessage(const std::filesystem::path& p, std::uint64_t key, const char* words) {
    try {
        VlfCache::load(p, key);
        ADD_FAILURE() << "no error for " << words;
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
    }
}

} // namespace

TEST(VlfCache, RoundTripKeepsEveryValue) {
    const auto scene = glossyRoom();
    const Vlf a = bakeVlf(*scene, small());
    const auto path = tempFile("roundtrip.vlf");
    VlfCache::save(a, path);
    const Vlf b = VlfCache::load(path, vlfKey(*scene, small()));
    EXPECT_EQ(a.key(), b.key());
    EXPECT_EQ(a.irradiance(), b.irradiance());
    EXPECT_EQ(a.texelCoverage(), b.texelCoverage());
    EXPECT_EQ(a.tiles(), b.tiles());
    EXPECT_EQ(a.slots(), b.slots());
    EXPECT_EQ(a.tileCount(), b.tileCount());
    EXPECT_EQ(a.center(), b.center());
    EXPECT_EQ(a.radius(), b.radius());
    EXPECT_EQ(a.memory().renderBytes, b.memory().renderBytes);
    // Lookups agree.
    std::mt19937 rng(4);
    std::uniform_real_distribution<float> u(-0.9f, 0.9f);
    for (std::uint32_t f = 0; f < a.faces().size(); ++f)
        for (int k = 0; k < 20; ++k) {
            const Face& face = a.faces()[f];
            const glm::vec3 x = face.origin + (0.5f + 0.5f * u(rng)) * face.extentU * face.axisU +
                                (0.5f + 0.5f * u(rng)) * face.extentV * face.axisV;
            const glm::vec3 view = glm::normalize(face.normal + 0.5f * glm::vec3(u(rng), u(rng), u(rng)));
            EXPECT_EQ(a.radiance(f, x, view), b.radiance(f, x, view));
        }
    std::filesystem::remove(path);
}

TEST(VlfCache, StaleAndCorruptFilesAreRejected) {
    const auto scene = glossyRoom();
    const VlfSettings s = small();
    const Vlf a = bakeVlf(*scene, s);
    const auto path = tempFile("bad.vlf");
    VlfCache::save(a, path);
    const std::uint64_t key = vlfKey(*scene, s);
    const std::vector<char> good = readAll(path);

    // Stale: another scene or other settings give another key.
    EXPECT_NE(vlfKey(*glossyRoom(5.f), s), key);
    VlfSettings other = s;
    other.iterations = 3;
    EXPECT_NE(vlfKey(*scene, other), key);
    expectMessage(path, vlfKey(*scene, other), "stale");

    // A flipped byte anywhere in the payload.
    std::mt19937 rng(9);
    for (int k = 0; k < 20; ++k) {
        std::vector<char> bad = good;
        const std::size_t at = 36 + rng() % (bad.size() - 36);
        bad[at] = char(bad[at] ^ 0x5a);
        writeAll(path, bad);
        expectMessage(path, key, "corrupt");
    }
    // Truncated, extended, wrong magic, other version, missing.
    std::vector<char> bad(good.begin(), good.begin() + std::ptrdiff_t(good.size() / 2));
    writeAll(path, bad);
    expectMessage(path, key, "corrupt");
    bad = good;
    bad.push_back(0);
    writeAll(path, bad);
    expectMessage(path, key, "corrupt");
    bad = good;
    bad[0] = 'X';
    writeAll(path, bad);
    expectMessage(path, key, "not a VLF cache");
    bad = good;
    bad[8] = char(bad[8] + 1);
    writeAll(path, bad);
    expectMessage(path, key, "version");
    writeAll(path, std::vector<char>(good.begin(), good.begin() + 10));
    expectMessage(path, key, "corrupt");
    std::filesystem::remove(path);
    expectMessage(path, key, "no VLF cache");
}

TEST(VlfCache, LoadOrBakeRebuildsABadFile) {
    const auto scene = glossyRoom();
    const VlfSettings s = small();
    const auto path = tempFile("rebuild.vlf");
    std::filesystem::remove(path);
    bool baked = false;
    const Vlf first = VlfCache::loadOrBake(*scene, s, path, &baked);
    EXPECT_TRUE(baked);
    const Vlf second = VlfCache::loadOrBake(*scene, s, path, &baked);
    EXPECT_FALSE(baked);
    EXPECT_EQ(first.tiles(), second.tiles());
    std::vector<char> bytes = readAll(path);
    bytes[bytes.size() - 5] = char(bytes[bytes.size() - 5] ^ 1);
    writeAll(path, bytes);
    const Vlf third = VlfCache::loadOrBake(*scene, s, path, &baked);
    EXPECT_TRUE(baked);
    EXPECT_EQ(first.tiles(), third.tiles());
    EXPECT_NO_THROW(VlfCache::load(path, vlfKey(*scene, s))); // the rebuilt file is good
    std::filesystem::remove(path);
}
