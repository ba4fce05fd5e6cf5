// Hostile glTF input: every file in tests/data/gltf/bad (one mutation of a valid triangle
// each, see make_corpus.py there) must give one qgi::Error line naming the file and the field,
// and leave the registry empty.

#include "runtime/scene/GltfImporter.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneLoader.h"
#include "runtime/scene/TextureLibrary.h"

#include "components/Mesh.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <span>
#include <sstream>
#include <string>

namespace qgi {
namespace {

using ::testing::HasSubstr;

namespace fs = std::filesystem;

const fs::path kData = fs::path(QGI_TEST_DATA_DIR) / "gltf";
const SceneOptions kNoRefinement{.maxEdgeLength = 1000.f};

struct BadCase {
    const char* file;
    const char* field; ///< the field path the message must name ("" for the file as a whole)
    const char* what;  ///< a word of the explanation
};

const BadCase kCases[] = {
    {"missing_buffer_file.gltf", "buffers[0].uri", "not found"},
    {"truncated.gltf", "JSON", "parse error"},
    {"invalid_json.gltf", "JSON", "parse error"},
    {"empty.gltf", "", "empty"},
    {"accessor_out_of_range.gltf", "meshes[0].primitives[0].attributes.POSITION", "out of range"},
    {"bufferview_out_of_range.gltf", "accessors[0].bufferView", "out of range"},
    {"bufferview_past_buffer.gltf", "bufferViews[1].byteLength", "past the end"},
    {"accessor_past_view.gltf", "accessors[0].count", "do not fit"},
    {"bad_component_type.gltf", "accessors[0].componentType", "DOUBLE"},
    {"index_out_of_range.gltf", "meshes[0].primitives[0].indices", "vertex count"},
    {"nan_position.gltf", "meshes[0].primitives[0].attributes.POSITION", "not finite"},
    {"inf_position.gltf", "meshes[0].primitives[0].attributes.POSITION", "not finite"},
    {"node_cycle.gltf", "nodes[1].children", "cycle"},
    {"two_parents.gltf", "nodes[1].children[0]", "already has parent"},
    {"bad_scene_node.gltf", "scenes[0].nodes[1]", "out of range"},
    {"bad_material.gltf", "meshes[0].primitives[0].material", "out of range"},
    {"uri_escape.gltf", "buffers[0].uri", "leaves the scene's folder"},
    {"uri_escape_encoded.gltf", "buffers[0].uri", "leaves the scene's folder"},
    {"uri_absolute.gltf", "buffers[0].uri", "absolute"},
    {"bad_base64.gltf", "buffers[0].uri", "invalid base64"},
    {"unknown_mobility.gltf", "nodes[0].extras.mobility", "'flying'"},
    {"point_cache_not_bool.gltf", "nodes[0].extras.pointCache", "true or false"},
    {"active_not_bool.gltf", "nodes[0].extras.active", "true or false"},
    {"active_on_static.gltf", "nodes[0].extras.active", "mobile"},
    {"light_intensity_string.gltf", "extensions.KHR_lights_punctual.lights[0].intensity",
     "not a finite number"},
    {"light_too_bright.gltf", "extensions.KHR_lights_punctual.lights[0].intensity", "from 0 to"},
    {"mesh_index_float.gltf", "nodes[0].mesh", "whole number"},
    {"accessor_negative_offset.gltf", "accessors[0].byteOffset", "whole number"},
    {"min_version_3.gltf", "asset.minVersion", "'3.0'"},
    {"alpha_out_of_range.gltf", "materials[0].pbrMetallicRoughness.baseColorFactor[3]",
     "outside [0, 1]"},
    {"far_from_origin.gltf", "", "from the origin"},
    {"scene_too_large.gltf", "", "units"},
    {"animation_times_not_increasing.gltf", "animations[0].samplers[0].input",
     "strictly increasing"},
    {"point_cache_on_mobile.gltf", "nodes[0].extras.pointCache", "static meshes only"},
    {"sheared_matrix.gltf", "nodes[0].matrix", "shear"},
    {"unsupported_required_extension.gltf", "extensionsRequired[0]", "not supported"},
    {"corrupt_image.gltf", "images[0]", "cannot be decoded (truncated or corrupt image data)"},
    {"image_chunk_control_bytes.gltf", "images[0]", "(\\x0aND\\x07 PNG chunk not known)"},
    {"bad_glb_magic.glb", "header.magic", "glTF"},
    {"bad_glb_length.glb", "header.length", "bytes declared"},
};

void PrintTo(const BadCase& c, std::ostream* out) {
    *out << c.file;
}

/// Imports `path` expecting failure; returns the message after checking the registry is empty.
std::string importFailure(const fs::path& path, const SceneOptions& options = kNoRefinement) {
    Registry registry;
    std::string message;
    try {
        importGltf(registry, path, options);
        ADD_FAILURE() << path << " was accepted";
    } catch (const Error& e) {
        message = e.what();
    }
    EXPECT_EQ(registry.aliveCount(), 0u) << path;
    EXPECT_FALSE(registry.ctx().contains<SceneInfo>()) << path;
    EXPECT_FALSE(registry.ctx().contains<TextureLibrary>()) << path;
    for (const char c : message) // one line, nothing a terminal would act on
        EXPECT_TRUE(static_cast<unsigned char>(c) >= 0x20 && c != 0x7f)
            << "control byte in " << message;
    return message;
}

class GltfBadInput : public ::testing::TestWithParam<BadCase> {};

TEST_P(GltfBadInput, FailsWithOneLineNamingFileAndField) {
    const BadCase& c = GetParam();
    const std::string message = importFailure(kData / "bad" / c.file);
    // "<file>: <field>: <what>", or "<file>: <what>" for the file as a whole.
    const std::string prefix = std::string(c.file) + ": " + c.field;
    EXPECT_EQ(message.rfind(prefix, 0), 0u) << message;
    EXPECT_NE(message.find(c.what), std::string::npos) << message;
}

INSTANTIATE_TEST_SUITE_P(Corpus, GltfBadInput, ::testing::ValuesIn(kCases),
                         [](const ::testing::TestParamInfo<BadCase>& test) {
                             std::string name = test.param.file;
                             for (char& ch : name)
                                 if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                             return name;
                         });

TEST(GltfBadInput, EveryCorpusFileHasACase) {
    std::set<std::string> files, cases;
    for (const auto& entry : fs::directory_iterator(kData / "bad"))
        files.insert(entry.path().filename().string());
    for (const BadCase& c : kCases)
        cases.insert(c.file);
    EXPECT_EQ(files, cases);
}

// One folder per test: ctest runs tests in parallel processes, and two tests writing the same
// scratch file (triangle.bin) would read each other's half-written copies.
fs::path scratchFile(const std::string& name) {
    const fs::path dir = fs::path(::testing::TempDir()) / "qgi_gltf_bad_input" /
                         ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::create_directories(dir);
    return dir / name;
}

/// The single-triangle scene of triangle.gltf, with `extras` on its node.
std::string triangleWithExtras(const std::string& extras) {
    std::ifstream in(kData / "good" / "triangle.gltf");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string anchor = R"("name": "Triangle",)";
    const std::size_t at = text.find(anchor);
    EXPECT_NE(at, std::string::npos);
    return text.insert(at + anchor.size(), R"("extras": )" + extras + ",");
}

TEST(GltfBadInput, AMisspeltExtrasKeyIsNamedWithTheOneMeant) {
    // "mobilty" loads the node as static, as the file says; a warning names the slip. Keys of
    // other tools (Blender's custom properties) pass without a word.
    fs::copy_file(kData / "good" / "triangle.bin", scratchFile("triangle.bin"),
                  fs::copy_options::overwrite_existing);
    for (const auto& [extras, warned] :
         {std::pair{R"({"mobilty": "mobile"})", true}, std::pair{R"({"PointCache": true})", true},
          std::pair{R"({"blender_prop": 3, "mobility": "mobile"})", false}}) {
        std::ofstream(scratchFile("extras.gltf")) << triangleWithExtras(extras);
        Registry registry;
        ::testing::internal::CaptureStderr();
        importGltf(registry, scratchFile("extras.gltf"), kNoRefinement);
        const std::string log = ::testing::internal::GetCapturedStderr();
        EXPECT_EQ(log.find("did you mean") != std::string::npos, warned) << extras << ": " << log;
    }
}

/// Writes `positions` (x, y, z triples) and triangle `indices` to scratch file NAME.bin, and
/// returns the glTF members that describe them: "buffers", "bufferViews" and "accessors"
/// (POSITION is accessor 0, the indices accessor 1).
std::string indexedMeshBuffers(const std::string& name, std::span<const float> positions,
                               std::span<const std::uint32_t> indices) {
    {
        std::ofstream bin(scratchFile(name + ".bin"), std::ios::binary);
        bin.write(reinterpret_cast<const char*>(positions.data()),
                  std::streamsize(positions.size_bytes()));
        bin.write(reinterpret_cast<const char*>(indices.data()),
                  std::streamsize(indices.size_bytes()));
    }
    Aabb box;
    for (std::size_t i = 0; i + 2 < positions.size(); i += 3)
        box.extend({positions[i], positions[i + 1], positions[i + 2]});
    std::ostringstream out;
    out << R"("buffers": [{"byteLength": )" << positions.size_bytes() + indices.size_bytes()
        << R"(, "uri": ")" << name << R"(.bin"}],
        "bufferViews": [{"buffer": 0, "byteLength": )"
        << positions.size_bytes() << R"(},
                        {"buffer": 0, "byteOffset": )"
        << positions.size_bytes() << R"(, "byteLength": )" << indices.size_bytes() << R"(}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": )"
        << positions.size() / 3 << R"(, "type": "VEC3",
                       "min": [)"
        << box.min.x << ", " << box.min.y << ", " << box.min.z << R"(], "max": [)" << box.max.x
        << ", " << box.max.y << ", " << box.max.z << R"(]},
                      {"bufferView": 1, "componentType": 5125, "count": )"
        << indices.size() << R"(, "type": "SCALAR"}])";
    return out.str();
}

TEST(GltfBadInput, ANeedleTriangleIsNamedWhenItIsDropped) {
    // A floor quad, and a triangle 0.08 m^2 in area with one corner 10,000 km off: a height of
    // 4 cm over that length is a needle, which processing drops like a degenerate triangle.
    // Unlike a degenerate one it takes area with it, so a warning names the primitive.
    const float positions[] = {-1, 0, -1,   1, 0,    -1,   1, 0,    1,    -1,  0,
                               1,  0, 0.5f, 0, 0.4f, 0.5f, 0, 1e7f, 0.5f, 0.4f};
    const std::uint32_t indices[] = {0, 2, 1, 0, 3, 2, 4, 5, 6};
    std::ofstream(scratchFile("needle.gltf"))
        << R"({"asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],)"
        << indexedMeshBuffers("needle", positions, indices) << "}";
    Registry registry;
    ::testing::internal::CaptureStderr();
    importGltf(registry, scratchFile("needle.gltf"), kNoRefinement);
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(log.find("meshes[0].primitives[0]: 1 triangle(s) too thin to light"),
              std::string::npos)
        << log;
    EXPECT_NE(log.find("0.08 m^2"), std::string::npos) << log;
    // The floor alone is what loads, and it sets the scene's size.
    EXPECT_EQ(registry.count<Mesh>(), 1u);
    EXPECT_NEAR(registry.ctx().get<SceneInfo>().bounds.extent().x, 2.f, 1e-6f);
}

TEST(GltfBadInput, AMeshFarFromTheRestIsNamedWhenItStretchesTheDefaultEdgeBound) {
    // Three 2 m quads, two side by side and one 400 km off: the scene is 400 km across and the
    // default edge bound 8 km, which leaves the room unrefined. A warning names the stray
    // node; a layout without one (the third quad 3 m from the others) says nothing.
    const float positions[] = {-1, 0, -1, 1, 0, -1, 1, 0, 1, -1, 0, 1};
    const std::uint32_t indices[] = {0, 2, 1, 0, 3, 2};
    const std::string buffers = indexedMeshBuffers("quad", positions, indices);
    for (const auto& [offset, warned] : {std::pair{"4e5", true}, std::pair{"3", false}}) {
        std::ofstream(scratchFile("stray.gltf")) << R"({"asset": {"version": "2.0"},
            "scene": 0, "scenes": [{"nodes": [0, 1, 2]}],
            "nodes": [{"mesh": 0, "name": "floor"},
                      {"mesh": 0, "name": "next floor", "translation": [0, 0, 2]},
                      {"mesh": 0, "name": "stray crate", "translation": [)"
                                                 << offset << R"(, 0, 0]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],)"
                                                 << buffers << "}";
        Registry registry;
        ::testing::internal::CaptureStderr();
        importGltf(registry, scratchFile("stray.gltf"), SceneOptions{});
        const std::string log = ::testing::internal::GetCapturedStderr();
        EXPECT_EQ(log.find("stray crate lies 400000 m from the rest of the scene") !=
                      std::string::npos,
                  warned)
            << log;
        EXPECT_EQ(log.find("lies") != std::string::npos, warned) << log;
    }
}

TEST(GltfBadInput, ASkinWithoutInverseBindMatricesLoadsInItsBindPose) {
    // glTF 2.0 leaves a skin's inverseBindMatrices optional (identity); tinygltf calls it
    // missing. Skinned meshes load in their bind pose with a warning either way.
    fs::copy_file(kData / "good" / "triangle.bin", scratchFile("triangle.bin"),
                  fs::copy_options::overwrite_existing);
    std::string text = triangleWithExtras("{}");
    const std::string anchor = R"("name": "Triangle",)";
    text.insert(text.find(anchor) + anchor.size(), R"("skin": 0,)");
    text.insert(text.find('{') + 1, R"("skins": [{"joints": [0]}],)");
    std::ofstream(scratchFile("skinned.gltf")) << text;
    Registry registry;
    ::testing::internal::CaptureStderr();
    importGltf(registry, scratchFile("skinned.gltf"), kNoRefinement);
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(log.find("nodes[0].skin: skinning is not supported"), std::string::npos) << log;
    EXPECT_EQ(registry.count<Mesh>(), 1u);
}

TEST(GltfBadInput, DeepNestingIsRefusedBeforeParsing) {
    // 10000 nested arrays overflow tinygltf's recursive parser; the importer must not hand
    // them over. The scene sits in the good folder's copy so the external .bin resolves.
    const fs::path deep = scratchFile("deep.gltf");
    fs::copy_file(kData / "good" / "triangle.bin", scratchFile("triangle.bin"),
                  fs::copy_options::overwrite_existing);
    std::ofstream(deep) << triangleWithExtras(std::string(10000, '[') + std::string(10000, ']'));
    const std::string message = importFailure(deep);
    EXPECT_EQ(message.rfind("deep.gltf: JSON: nesting depth 10003", 0), 0u) << message;

    // Exactly at the limit is fine: root object, "nodes" array and node object are 3 levels.
    const fs::path limit = scratchFile("limit.gltf");
    const int arrays = kGltfMaxJsonDepth - 3;
    std::ofstream(limit) << triangleWithExtras(std::string(std::size_t(arrays), '[') +
                                               std::string(std::size_t(arrays), ']'));
    Registry registry;
    importGltf(registry, limit, kNoRefinement);
    EXPECT_EQ(registry.count<Mesh>(), 1u);
}

TEST(GltfBadInput, RandomCorruptionsFailCleanly) {
    // Seeded corruptions of every good file (a few random bytes, sometimes truncation): each
    // import either succeeds or throws qgi::Error and leaves the registry empty. A crash or any
    // other exception fails; the sanitizer build (QGI_SANITIZE) also catches memory errors.
    std::mt19937 random(2024);
    fs::copy_file(kData / "good" / "triangle.bin", scratchFile("triangle.bin"),
                  fs::copy_options::overwrite_existing);
    for (const char* name : {"triangle.gltf", "hierarchy.gltf", "lights.gltf", "box.glb"}) {
        std::ifstream in(kData / "good" / name, std::ios::binary);
        const std::string original((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
        int failures = 0;
        for (int trial = 0; trial < 300; ++trial) {
            std::string bytes = original;
            for (std::uint32_t edits = 1 + random() % 4; edits > 0; --edits)
                bytes[random() % bytes.size()] = char(random() % 256);
            if (random() % 8 == 0) bytes.resize(random() % bytes.size());
            const fs::path path = scratchFile(name);
            std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
            Registry registry;
            try {
                importGltf(registry, path, kNoRefinement);
            } catch (const Error& e) {
                ++failures;
                EXPECT_EQ(registry.aliveCount(), 0u) << e.what();
                EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
            }
        }
        EXPECT_GT(failures, 0) << name; // the corruptions do reach the checks
    }
}

TEST(GltfBadInput, MissingFileAndUnknownExtensionNameThePath) {
    EXPECT_EQ(importFailure(scratchFile("absent.gltf")).rfind("absent.gltf: cannot read", 0), 0u);
    EXPECT_EQ(
        importFailure(kData / "good" / "triangle.bin").rfind("triangle.bin: unknown extension", 0),
        0u);
}

TEST(GltfBadInput, APipeOrAFolderIsNoSceneFile) {
    const fs::path pipe = scratchFile("pipe.gltf"), folder = scratchFile("folder.glb");
    fs::remove(pipe);
    fs::create_directories(folder);
    ASSERT_EQ(mkfifo(pipe.c_str(), 0600), 0);
    EXPECT_THAT(importFailure(pipe), ::testing::HasSubstr("pipe.gltf' is not a regular file"));
    EXPECT_THAT(importFailure(folder), ::testing::HasSubstr("folder.glb' is not a regular file"));
    // Through a link, too (a level that links its scene to /dev/zero).
    const fs::path link = scratchFile("zero.gltf");
    fs::remove(link);
    fs::create_symlink("/dev/zero", link);
    EXPECT_THAT(importFailure(link), ::testing::HasSubstr("zero.gltf' is not a regular file"));
}

TEST(GltfBadInput, APlusInAFileNameIsExplained) {
    // A URI reads '+' as a space: "tri+angle.bin" names "tri angle.bin". The file with the plus
    // is there, so the error says how to name it; written as %2B it loads.
    fs::copy_file(kData / "good" / "triangle.bin", scratchFile("tri+angle.bin"),
                  fs::copy_options::overwrite_existing);
    std::ifstream in(kData / "good" / "triangle.gltf");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto withUri = [&](const std::string& file, const std::string& uri) {
        std::string edited = text;
        const std::string from = R"("uri": "triangle.bin")";
        edited.replace(edited.find(from), from.size(), R"("uri": ")" + uri + R"(")");
        std::ofstream(scratchFile(file)) << edited;
        return scratchFile(file);
    };
    const std::string message = importFailure(withUri("plus.gltf", "tri+angle.bin"));
    EXPECT_EQ(message.rfind("plus.gltf: buffers[0].uri", 0), 0u) << message;
    EXPECT_THAT(message, HasSubstr("'tri angle.bin'"));
    EXPECT_THAT(message, HasSubstr("%2B"));
    Registry registry;
    EXPECT_NO_THROW(
        importGltf(registry, withUri("escaped.gltf", "tri%2Bangle.bin"), kNoRefinement));
    EXPECT_GT(registry.aliveCount(), 0u);
}

TEST(GltfBadInput, ASceneExposureThatIsNoPositiveNumberIsNamed) {
    std::ifstream in(kData / "good" / "triangle.gltf");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string from = R"("scenes": [)";
    ASSERT_NE(text.find(from), std::string::npos);
    for (const char* exposure : {R"("bright")", "-1", "0", "1e-300"}) {
        std::string edited = text;
        const std::size_t scene = edited.find("{", edited.find(from));
        edited.insert(scene + 1, std::string(R"("extras": {"exposure": )") + exposure + "}, ");
        std::ofstream(scratchFile("exposure.gltf")) << edited;
        fs::copy_file(kData / "good" / "triangle.bin", scratchFile("triangle.bin"),
                      fs::copy_options::overwrite_existing);
        EXPECT_THAT(importFailure(scratchFile("exposure.gltf")),
                    HasSubstr("scenes[0].extras.exposure"))
            << exposure;
    }
}

TEST(GltfBadInput, AMalformedPathTagIsNamedOnANodeWithoutAnimation) {
    // The tag is read where an animation drives the node, but checked on every node: a file
    // that loads must not hold a tag that breaks once an animation is added.
    std::ifstream in(kData / "good" / "triangle.gltf");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string from = R"("name": "Triangle",)";
    ASSERT_NE(text.find(from), std::string::npos);
    for (const auto& [tag, field] :
         {std::pair{R"("yes")", "nodes[0].extras.qgiPath"},
          std::pair{R"({"loop": "no"})", "nodes[0].extras.qgiPath.loop"},
          std::pair{R"({"timeOffset": "soon"})", "nodes[0].extras.qgiPath.timeOffset"}}) {
        std::string edited = text;
        edited.replace(edited.find(from), from.size(),
                       from + R"( "extras": {"qgiPath": )" + tag + "},");
        std::ofstream(scratchFile("path_tag.gltf")) << edited;
        fs::copy_file(kData / "good" / "triangle.bin", scratchFile("triangle.bin"),
                      fs::copy_options::overwrite_existing);
        EXPECT_THAT(importFailure(scratchFile("path_tag.gltf")), HasSubstr(field)) << tag;
    }
}

TEST(GltfBadInput, SpotConesThatMeetAsFloatsAreNamed) {
    // Apart in double, one float apart or equal as the lights systems read them: the photons
    // would leave such a spot dark while the renderer drew it.
    std::ifstream in(kData / "good" / "lights.gltf");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string from = R"("innerConeAngle": 0.2)";
    ASSERT_NE(text.find(from), std::string::npos);
    std::string edited = text;
    edited.replace(edited.find(from), from.size(), R"("innerConeAngle": 0.59999999999)");
    std::ofstream(scratchFile("spot.gltf")) << edited;
    const std::string message = importFailure(scratchFile("spot.gltf"));
    EXPECT_THAT(message, HasSubstr("extensions.KHR_lights_punctual.lights[1].spot.innerConeAngle"));
    EXPECT_THAT(message, HasSubstr("32-bit floats"));
}

TEST(GltfBadInput, AStrideOutOfRangeIsNamedWithItsRange) {
    // (tinygltf's own message says only "must be the multiple of 4", also of 256.)
    std::ifstream in(kData / "good" / "triangle.gltf");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    fs::copy_file(kData / "good" / "triangle.bin", scratchFile("triangle.bin"),
                  fs::copy_options::overwrite_existing);
    for (const char* stride : {"256", "6", "2"}) {
        std::string edited = text;
        const std::string from = R"("buffer": 0,)";
        edited.replace(edited.find(from), from.size(),
                       std::string(R"("buffer": 0, "byteStride": )") + stride + ",");
        std::ofstream(scratchFile("stride.gltf")) << edited;
        EXPECT_THAT(importFailure(scratchFile("stride.gltf")),
                    HasSubstr("bufferViews[0].byteStride: " + std::string(stride) +
                              " is not a multiple of 4 in [4, 252]"));
    }
}

TEST(GltfBadInput, ALinkOutOfTheScenesFolderIsRefused) {
    // A scene folder holding links: to a file outside it (a level that reads /etc/passwd), to
    // a device, and to a buffer of its own (harmless: it loads).
    const fs::path folder = scratchFile("linked_level");
    fs::remove_all(folder);
    fs::create_directories(folder / "sub");
    const fs::path outside = scratchFile("outside.bin");
    fs::copy_file(kData / "good" / "triangle.bin", outside, fs::copy_options::overwrite_existing);
    fs::copy_file(kData / "good" / "triangle.bin", folder / "sub" / "own.bin");
    fs::create_symlink(outside, folder / "out.bin");
    fs::create_symlink("/dev/zero", folder / "zero.bin");
    fs::create_symlink(folder / "sub" / "own.bin", folder / "own.bin");
    std::ifstream in(kData / "good" / "triangle.gltf");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto withUri = [&](const std::string& uri) {
        std::string edited = text;
        const std::string from = R"("uri": "triangle.bin")";
        edited.replace(edited.find(from), from.size(), R"("uri": ")" + uri + R"(")");
        const fs::path scene = folder / (uri + ".gltf");
        std::ofstream(scene) << edited;
        return scene;
    };
    EXPECT_THAT(importFailure(withUri("out.bin")),
                HasSubstr("is a link that leaves the scene's folder"));
    EXPECT_THAT(importFailure(withUri("zero.bin")), HasSubstr("is not a regular file"));
    Registry registry;
    EXPECT_NO_THROW(importGltf(registry, withUri("own.bin"), kNoRefinement));
    EXPECT_GT(registry.aliveCount(), 0u);

    // A mirror of the level made of links (cp -rs): its files lie beside the scene's real file.
    const fs::path mirror = scratchFile("mirror");
    fs::remove_all(mirror);
    fs::create_directories(mirror);
    fs::create_symlink(folder / "sub" / "own.bin", mirror / "own.bin");
    fs::create_symlink(withUri("own.bin"), mirror / "level.gltf");
    Registry mirrored;
    EXPECT_NO_THROW(importGltf(mirrored, mirror / "level.gltf", kNoRefinement));
}

TEST(GltfBadInput, FailureWhileProcessingMeshesLeavesTheRegistryEmpty) {
    // A 1 um edge bound would refine the triangle into ~10^12 pieces: processMesh refuses,
    // after everything else in the file has been read.
    const std::string message =
        importFailure(kData / "good" / "triangle.gltf", SceneOptions{.maxEdgeLength = 1e-6f});
    EXPECT_EQ(message.rfind("triangle.gltf: meshes[0].primitives[0]: ", 0), 0u) << message;
}

TEST(GltfBadInput, NegativeEdgeBoundIsRefused) {
    const std::string message =
        importFailure(kData / "good" / "triangle.gltf", SceneOptions{.maxEdgeLength = -1.f});
    EXPECT_NE(message.find("maxEdgeLength"), std::string::npos) << message;
}

} // namespace
} // namespace qgi
