// The VLF cache file: round trip, stale and corrupt files rejected with a clear message; and
// VlfSystem, which bakes or loads it and publishes the VlfField resource.
#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Hash.h"
#include "runtime/ecs/Registry.h"
#include "systems/frame/FrameSchedule.h"
#include "systems/vlf/VlfBake.h"
#include "systems/vlf/VlfCache.h"
#include "systems/vlf/VlfField.h"
#include "systems/vlf/VlfSystem.h"
#include "test_meshes.h"
#include "test_vlf_scenes.h"

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>

#include <unistd.h>

using namespace qgi;
using namespace qgi::vlf;

namespace {

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

void expectMessage(const std::filesystem::path& p, const VlfScene& scene, const VlfSettings& s,
                   const char* words) {
    try {
        VlfCache::load(p, scene, s);
        ADD_FAILURE() << "no error for " << words;
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
    }
}

} // namespace

TEST(VlfCache, RoundTripKeepsEveryValue) {
    const auto scene = test::glossyRoom();
    const Vlf a = bakeVlf(*scene, small());
    const auto path = tempFile("roundtrip.vlf");
    VlfCache::save(a, path);
    const Vlf b = VlfCache::load(path, *scene, small());
    EXPECT_EQ(a.key(), b.key());
    EXPECT_EQ(a.irradiance(), b.irradiance());
    EXPECT_EQ(a.texelCoverage(), b.texelCoverage());
    EXPECT_EQ(a.unpackedCells(), b.unpackedCells());
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
            const glm::vec3 view =
                glm::normalize(face.normal + 0.5f * glm::vec3(u(rng), u(rng), u(rng)));
            EXPECT_EQ(a.radiance(f, x, view), b.radiance(f, x, view));
        }
    std::filesystem::remove(path);
}

TEST(VlfCache, StaleAndCorruptFilesAreRejected) {
    const auto scene = test::glossyRoom();
    const VlfSettings s = small();
    const Vlf a = bakeVlf(*scene, s);
    const auto path = tempFile("bad.vlf");
    VlfCache::save(a, path);
    const std::uint64_t key = vlfKey(*scene, s);
    const std::vector<char> good = readAll(path);

    // Stale: another scene or other settings give another key.
    EXPECT_NE(vlfKey(*test::glossyRoom(5.f), s), key);
    VlfSettings other = s;
    other.iterations = 3;
    EXPECT_NE(vlfKey(*scene, other), key);
    expectMessage(path, *scene, other, "stale");

    // A flipped byte anywhere in the payload.
    std::mt19937 rng(9);
    for (int k = 0; k < 20; ++k) {
        std::vector<char> bad = good;
        const std::size_t at = 36 + rng() % (bad.size() - 36);
        bad[at] = char(bad[at] ^ 0x5a);
        writeAll(path, bad);
        expectMessage(path, *scene, s, "corrupt");
    }
    // Truncated, extended, wrong magic, other version, missing.
    std::vector<char> bad(good.begin(), good.begin() + std::ptrdiff_t(good.size() / 2));
    writeAll(path, bad);
    expectMessage(path, *scene, s, "corrupt");
    bad = good;
    bad.push_back(0);
    writeAll(path, bad);
    expectMessage(path, *scene, s, "corrupt");
    bad = good;
    bad[0] = 'X';
    writeAll(path, bad);
    expectMessage(path, *scene, s, "not a VLF cache");
    bad = good;
    bad[8] = char(bad[8] + 1);
    writeAll(path, bad);
    expectMessage(path, *scene, s, "version");
    writeAll(path, std::vector<char>(good.begin(), good.begin() + 10));
    expectMessage(path, *scene, s, "corrupt");
    std::filesystem::remove(path);
    expectMessage(path, *scene, s, "no VLF cache");
}

namespace {

/// Where each of save()'s arrays starts in a file (after its count), and the tile count.
struct Sections {
    std::size_t faces = 0, faceMaps = 0, coverage = 0, irradiance = 0, specularIndex = 0,
                specularFaces = 0, blocks = 0, slots = 0, tileCount = 0, cellScale = 0, tiles = 0;
};

Sections sections(const std::vector<char>& file) {
    constexpr std::size_t kHeader = 36, kSettingsAndBounds = 56;
    constexpr std::size_t kFace = 104, kFaceMap = 20, kBlock = 24;
    std::size_t at = kHeader + kSettingsAndBounds;
    const auto array = [&](std::size_t element) {
        std::uint64_t n = 0;
        if (at + sizeof n > file.size()) return at;
        std::memcpy(&n, &file[at], sizeof n);
        at += sizeof n;
        if (n > file.size()) n = 0; // a wrong layout; the check below reports it
        const std::size_t first = at;
        at += n * element;
        return first;
    };
    Sections s;
    s.faces = array(kFace);
    s.faceMaps = array(kFaceMap);
    s.coverage = array(sizeof(float));
    s.irradiance = array(sizeof(glm::vec3));
    s.specularIndex = array(sizeof(std::int32_t));
    s.specularFaces = array(sizeof(std::uint32_t));
    s.blocks = array(kBlock);
    s.slots = array(sizeof(std::int32_t));
    s.tileCount = at;
    at += sizeof(std::uint64_t);
    s.cellScale = at;
    at += sizeof(float);
    s.tiles = array(sizeof(glm::u16vec4));
    EXPECT_EQ(at, file.size()) << "save()'s layout changed: update sections()";
    return s;
}

/// Writes `value` at `at` and gives the payload its hash again, as a hostile file would.
template <typename T>
std::vector<char> withValue(std::vector<char> file, std::size_t at, const T& value) {
    std::memcpy(&file[at], &value, sizeof value);
    Fnv1aHasher h;
    h.addBytes(file.data() + 36, file.size() - 36);
    const std::uint64_t hash = h.value();
    std::memcpy(&file[28], &hash, sizeof hash);
    return file;
}

} // namespace

// The payload hash proves a file is as it was written, not that qgi wrote it: values a lookup
// would index with or shade by are checked too (a fuzzer found lookups reading out of bounds).
TEST(VlfCache, HostileValuesWithAValidHashAreRejected) {
    const auto scene = test::glossyRoom();
    const VlfSettings s = small();
    const auto path = tempFile("hostile.vlf");
    VlfCache::save(bakeVlf(*scene, s), path);
    const std::vector<char> good = readAll(path);
    const Sections at = sections(good);
    const float nan = std::numeric_limits<float>::quiet_NaN();

    writeAll(path, withValue(good, 36 + 52, 0.f)); // the bounding sphere's radius
    expectMessage(path, *scene, s, "the bounding sphere is not finite and positive");
    writeAll(path, withValue(good, at.faces, nan)); // face 0's normal.x
    expectMessage(path, *scene, s, "a face holds values out of range");
    writeAll(path, withValue(good, at.faceMaps + 8, -1.f)); // face 0's texelU
    expectMessage(path, *scene, s, "a texel size is not positive");
    // (Widths and heights past 2^30, which would overflow the lookups' int arithmetic, are
    // refused too; a file that passed the other checks with them would be gigabytes long.)
    writeAll(path, withValue(good, at.coverage, 2.f));
    expectMessage(path, *scene, s, "a texel coverage is outside [0, 1]");
    writeAll(path, withValue(good, at.irradiance, -1.f));
    expectMessage(path, *scene, s, "an irradiance is negative or not finite");

    // A diffuse face (index -1) pointed past the specular faces, and a specular face pointed
    // at another one's slot.
    writeAll(path, good);
    const Vlf field = VlfCache::load(path, *scene, s);
    std::int32_t diffuse = -1, specular = -1;
    for (std::uint32_t f = 0; f < field.faces().size(); ++f)
        (field.specularIndex(f) < 0 ? diffuse : specular) = std::int32_t(f);
    ASSERT_GE(diffuse, 0);
    ASSERT_GE(specular, 0);
    ASSERT_GE(field.specularFaceCount(), 2u);
    writeAll(path,
             withValue(good, at.specularIndex + 4 * std::size_t(diffuse), std::int32_t(1000)));
    expectMessage(path, *scene, s, "a specular index is out of range");
    const std::int32_t wrong = (field.specularIndex(std::uint32_t(specular)) + 1) %
                               std::int32_t(field.specularFaceCount());
    writeAll(path, withValue(good, at.specularIndex + 4 * std::size_t(specular), wrong));
    expectMessage(path, *scene, s, "specular faces do not match their index");
    writeAll(path, withValue(good, at.specularIndex + 4 * std::size_t(diffuse), std::int32_t(0)));
    expectMessage(path, *scene, s, "a specular index disagrees with its face's material");
    // The first two specular faces swapped in the list and in the index: a consistent mapping,
    // but each face's tiles would be read for the other.
    const std::uint32_t f0 = field.specularFace(0), f1 = field.specularFace(1);
    writeAll(path, withValue(withValue(withValue(withValue(good, at.specularFaces, f1),
                                                 at.specularFaces + 4, f0),
                                       at.specularIndex + 4 * std::size_t(f0), std::int32_t(1)),
                             at.specularIndex + 4 * std::size_t(f1), std::int32_t(0)));
    expectMessage(path, *scene, s, "specular faces do not match their index");

    writeAll(path, withValue(good, at.blocks, std::int32_t(5))); // block 0's side
    expectMessage(path, *scene, s, "a tile block faces no side");
    writeAll(path, withValue(good, at.tileCount, std::uint64_t(1) << 62));
    expectMessage(path, *scene, s, "more tiles than the file holds");
    // Cell 0's weight as a half float -1, then its red as +inf and as NaN; the scale 3 and 0.5.
    writeAll(path, withValue(good, at.tiles + 6, std::uint16_t(0xbc00)));
    expectMessage(path, *scene, s, "a tile cell is negative or not finite");
    writeAll(path, withValue(good, at.tiles, std::uint16_t(0x7c00)));
    expectMessage(path, *scene, s, "a tile cell is negative or not finite");
    writeAll(path, withValue(good, at.tiles, std::uint16_t(0x7e00)));
    expectMessage(path, *scene, s, "a tile cell is negative or not finite");
    writeAll(path, withValue(good, at.cellScale, 3.f));
    expectMessage(path, *scene, s, "the cells' scale is not a power of two");
    writeAll(path, withValue(good, at.cellScale, 0.5f));
    expectMessage(path, *scene, s, "the cells' scale is not a power of two");

    // A face that is well formed but not the scene's (face 0's emission red channel).
    writeAll(path, withValue(good, at.faces + 76, 1.f));
    expectMessage(path, *scene, s, "its faces differ from the scene's");

    writeAll(path, good); // and the file as written still loads
    EXPECT_NO_THROW(VlfCache::load(path, *scene, s));
    std::filesystem::remove(path);
}

// The key sits in the header, outside the payload hash: another scene's file with this scene's
// key written over its own must still be refused, since lookups and the renderer index the
// field by this scene's face numbers (another scene has other faces, or fewer).
TEST(VlfCache, AnotherScenesFileUnderThisScenesKeyIsRefused) {
    const auto scene = test::glossyRoom();
    const VlfSettings s = small();
    test::VlfSceneBuilder b;
    b.box({-1.f, 0.f, -1.f}, {1.f, 2.f, 1.f}, true, [&](int, int) {
        return b.material(glm::vec3(0.5f), glm::vec3(0.f), glm::vec3(0.3f), 20.f);
    });
    const auto other = b.build();
    ASSERT_NE(other->faces().size(), 0u);
    const auto path = tempFile("other.vlf");
    VlfCache::save(bakeVlf(*other, s), path);
    std::vector<char> bytes = readAll(path);
    const std::uint64_t key = vlfKey(*scene, s);
    std::memcpy(&bytes[12], &key, sizeof key);
    writeAll(path, bytes);
    expectMessage(path, *scene, s, "its faces differ from the scene's");
    std::filesystem::remove(path);
}

TEST(VlfCache, LoadOrBakeRebuildsABadFile) {
    const auto scene = test::glossyRoom();
    const VlfSettings s = small();
    const auto path = tempFile("rebuild.vlf");
    std::filesystem::remove(path);
    bool baked = false;
    const Vlf first = VlfCache::loadOrBake(*scene, s, path, &baked);
    EXPECT_TRUE(baked);
    const Vlf second = VlfCache::loadOrBake(*scene, s, path, &baked);
    EXPECT_FALSE(baked);
    EXPECT_EQ(first.unpackedCells(), second.unpackedCells());
    std::vector<char> bytes = readAll(path);
    bytes[bytes.size() - 5] = char(bytes[bytes.size() - 5] ^ 1);
    writeAll(path, bytes);
    const Vlf third = VlfCache::loadOrBake(*scene, s, path, &baked);
    EXPECT_TRUE(baked);
    EXPECT_EQ(first.unpackedCells(), third.unpackedCells());
    EXPECT_NO_THROW(VlfCache::load(path, *scene, s)); // the rebuilt file is good
    std::filesystem::remove(path);
}

TEST(VlfCache, AnUnwritableCacheFileStillGivesTheBakedField) {
    // The cache's folder is a regular file: no one, root included, can write there.
    const auto scene = test::glossyRoom();
    const VlfSettings s = small();
    const auto blocker = tempFile("not_a_folder");
    writeAll(blocker, {'x'});
    bool baked = false;
    const Vlf field = VlfCache::loadOrBake(*scene, s, blocker / "field.vlf", &baked);
    EXPECT_TRUE(baked);
    EXPECT_EQ(field.unpackedCells(), bakeVlf(*scene, s).unpackedCells());
    std::filesystem::remove(blocker);
}

TEST(VlfCache, SomebodysFileAtThePathIsNeverOverwritten) {
    const auto scene = test::glossyRoom();
    const VlfSettings s = small();
    const auto notes = tempFile("notes.vlf");
    writeAll(notes, {'m', 'y', ' ', 'n', 'o', 't', 'e', 's'});
    bool baked = false;
    const Vlf field = VlfCache::loadOrBake(*scene, s, notes, &baked);
    EXPECT_TRUE(baked);
    EXPECT_EQ(readAll(notes), (std::vector<char>{'m', 'y', ' ', 'n', 'o', 't', 'e', 's'}));
    EXPECT_THROW(VlfCache::save(field, notes), Error);
    // An empty file, or an older cache, may be replaced.
    writeAll(notes, {});
    EXPECT_NO_THROW(VlfCache::save(field, notes));
    EXPECT_NO_THROW(VlfCache::save(field, notes));
    std::filesystem::remove(notes);
}

// ---- VlfSystem: the registry's static meshes in, the VlfField resource out ------------------

namespace {

Entity addQuad(Registry& world, glm::vec3 corner, glm::vec3 u, glm::vec3 v, const Material& m,
               bool mobile = false) {
    const Entity e = world.create();
    world.emplace<Mesh>(e, test::quadMesh(corner, u, v));
    world.emplace<WorldTransform>(e);
    world.emplace<Material>(e, m);
    if (mobile)
        world.emplace<MobileMesh>(e);
    else
        world.emplace<StaticMesh>(e);
    return e;
}

} // namespace

TEST(VlfSystem, PublishesTheFieldAndMapsSpecularFacesToEntities) {
    Registry world;
    Material lamp;
    lamp.baseColor = glm::vec3(0.f);
    lamp.emission = glm::vec3(2.f);
    Material glossy;
    glossy.baseColor = glm::vec3(0.3f);
    glossy.specular = glm::vec3(0.5f);
    glossy.phongExponent = 20.f;
    Material metal; // glTF metallic-roughness only: read as a mirror
    metal.metallic = 1.f;
    metal.roughness = 0.f;
    const Entity floor = addQuad(world, {-1, 0, 1}, {2, 0, 0}, {0, 0, -2}, glossy);
    addQuad(world, {-1, 1, -1}, {2, 0, 0}, {0, 0, 2}, lamp); // ceiling light, facing down
    const Entity wall = addQuad(world, {-1, 0, -1}, {2, 0, 0}, {0, 1, 0}, metal);
    addQuad(world, {-0.2f, 0.5f, 0.2f}, {0.4f, 0, 0}, {0, 0, -0.4f}, glossy,
            true); // mobile: not baked

    VlfSystemSettings settings;
    settings.bake = small();
    settings.cacheFile = tempFile("system.vlf");
    std::filesystem::remove(settings.cacheFile);
    VlfSystem(settings).build(world);
    ASSERT_TRUE(world.ctx().contains<VlfField>());
    const VlfField& field = world.ctx().get<VlfField>();
    EXPECT_EQ(field.vlf.faces().size(), 3u); // the mobile quad is not part of the field
    ASSERT_EQ(field.specularFaces.size(), 2u);
    ASSERT_TRUE(field.specularFaces.contains(floor));
    ASSERT_TRUE(field.specularFaces.contains(wall));
    const vlf::Face& wallFace = field.vlf.faces()[field.specularFaces.at(wall).front()];
    EXPECT_TRUE(wallFace.isMirror());
    EXPECT_EQ(wallFace.specular, glm::vec3(1.f));
    EXPECT_EQ(wallFace.diffuse, glm::vec3(0.f));
    // The floor reflects the lamp: its glossy tiles hold light.
    const std::uint32_t f = field.specularFaces.at(floor).front();
    EXPECT_GT(
        field.vlf.specularRadiance(f, {0.f, 0.f, 0.f}, glm::normalize(glm::vec3(0.2f, 1.f, 0.1f)))
            .x,
        0.f);
    EXPECT_TRUE(std::filesystem::exists(settings.cacheFile));

    // Through the frame schedule (no renderer): loaded from the cache this time.
    Registry again;
    addQuad(again, {-1, 0, 1}, {2, 0, 0}, {0, 0, -2}, glossy);
    addQuad(again, {-1, 1, -1}, {2, 0, 0}, {0, 0, 2}, lamp);
    addQuad(again, {-1, 0, -1}, {2, 0, 0}, {0, 1, 0}, metal);
    addQuad(again, {-0.2f, 0.5f, 0.2f}, {0.4f, 0, 0}, {0, 0, -0.4f}, glossy, true);
    FrameSettings frame;
    frame.photons.reset();
    frame.render.reset();
    frame.vlf = settings;
    FrameSchedule schedule(again, frame);
    ASSERT_TRUE(again.ctx().contains<VlfField>());
    EXPECT_EQ(again.ctx().get<VlfField>().vlf.unpackedCells(), field.vlf.unpackedCells());
    std::filesystem::remove(settings.cacheFile);
}

TEST(VlfScene, ReadsPointSpotAndDirectionalLightsButNotStandIns) {
    Registry world;
    addQuad(world, {-1, 0, 1}, {2, 0, 0}, {0, 0, -2}, Material{});
    const auto light = [&](const glm::mat4& at) {
        const Entity e = world.create();
        world.emplace<WorldTransform>(e, at);
        return e;
    };
    world.emplace<PointLight>(light(glm::translate(glm::mat4(1.f), {0.f, 1.f, 0.f})),
                              PointLight{{1.f, 0.5f, 0.25f}, 2.f});
    world.emplace<SpotLight>(light(glm::translate(glm::mat4(1.f), {0.f, 1.f, 0.f})),
                             SpotLight{glm::vec3(1.f), 3.f, 0.2f, 0.4f});
    // The sun shines along its local -z turned -90 degrees about x: straight down.
    world.emplace<DirectionalLight>(
        light(glm::rotate(glm::mat4(1.f), -glm::half_pi<float>(), glm::vec3(1.f, 0.f, 0.f))),
        DirectionalLight{{1.f, 0.9f, 0.8f}, 5.f});
    const Entity bulb = light(glm::translate(glm::mat4(1.f), {0.f, 1.f, 0.f}));
    world.emplace<PointLight>(bulb, PointLight{});
    world.emplace<LightStandIn>(bulb);
    // Past kMaxPoseReach (runtime/math/Pose.h) a light is dark everywhere, so not read.
    world.emplace<PointLight>(light(glm::translate(glm::mat4(1.f), {0.f, 1e20f, 0.f})),
                              PointLight{glm::vec3(1.f), 1.f});
    world.emplace<SpotLight>(light(glm::translate(glm::mat4(1.f), {2e7f, 1.f, 0.f})),
                             SpotLight{glm::vec3(1.f), 3.f, 0.2f, 0.4f});

    const auto scene = VlfScene::fromRegistry(world);
    ASSERT_EQ(scene->lights().size(), 3u);
    int local = 0;
    for (const PunctualLight& l : scene->lights()) {
        if (l.kind == PunctualLight::Kind::Local) {
            ++local;
            continue;
        }
        EXPECT_NEAR(l.axis.y, -1.f, 1e-6f);
        EXPECT_NEAR(glm::length(l.axis), 1.f, 1e-6f);
        EXPECT_EQ(l.intensity, glm::vec3(5.f, 4.5f, 4.f));
    }
    EXPECT_EQ(local, 2);
}

TEST(VlfScene, AMaterialThatReflectsMoreThanItReceivesIsAClearError) {
    for (const auto& [diffuse, specular] :
         {std::pair{0.5f, 0.6f}, std::pair{-0.1f, 0.5f}, std::pair{0.5f, -0.1f}}) {
        Registry world;
        Material m;
        m.baseColor = glm::vec3(0.2f, diffuse, 0.2f);
        m.specular = glm::vec3(0.2f, specular, 0.2f);
        m.phongExponent = 10.f;
        const Entity e = addQuad(world, {-1, 0, 1}, {2, 0, 0}, {0, 0, -2}, m);
        world.emplace<Name>(e, Name{"polished floor"});
        try {
            VlfScene::fromRegistry(world);
            ADD_FAILURE() << "accepted diffuse " << diffuse << ", specular " << specular;
        } catch (const Error& error) {
            const std::string what = error.what();
            EXPECT_NE(what.find("polished floor"), std::string::npos) << what;
            EXPECT_NE(what.find("channel 1"), std::string::npos) << what;
        }
    }
    Registry world; // at the limit: accepted
    Material m;
    m.baseColor = glm::vec3(0.4f);
    m.specular = glm::vec3(0.6f);
    addQuad(world, {-1, 0, 1}, {2, 0, 0}, {0, 0, -2}, m);
    EXPECT_NO_THROW(VlfScene::fromRegistry(world));
}

TEST(VlfSystem, EmptySceneIsAClearError) {
    Registry world;
    VlfSystemSettings settings;
    settings.bake = small();
    EXPECT_THROW(VlfSystem(settings).build(world), Error);
    settings.bake.tileSize = 5;
    EXPECT_THROW(VlfSystem{settings}, Error);
}
