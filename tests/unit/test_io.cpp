// Round trips and failure modes of the image and mesh file writers (runtime/io).

#include "runtime/core/Error.h"
#include "runtime/io/AtomicFile.h"
#include "runtime/io/Exr.h"
#include "runtime/io/Ply.h"
#include "runtime/io/Png.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>

namespace qgi {
namespace {

namespace fs = std::filesystem;

class IoTest : public ::testing::Test {
protected:
    void SetUp() override {
        mDir = fs::path(::testing::TempDir()) /
               ("qgi_io_" +
                std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
        fs::remove_all(mDir);
        fs::create_directories(mDir);
    }
    void TearDown() override { fs::remove_all(mDir); }

    /// The bytes writePly gives `mesh` (binary).
    std::string plyText(const PlyMesh& mesh) const {
        const fs::path path = mDir / "text.ply";
        writePly(path, mesh);
        std::ifstream file(path, std::ios::binary);
        return {std::istreambuf_iterator<char>(file), {}};
    }

    fs::path mDir;
    std::mt19937 mRandom{1234};
};

// Floats over many binades, with both signs: a lossless format must return every bit.
std::vector<float> wideRangeFloats(std::mt19937& random, std::size_t count) {
    std::uniform_real_distribution<float> mantissa(-1.f, 1.f);
    std::uniform_int_distribution<int> exponent(-20, 20);
    std::vector<float> values(count);
    for (float& v : values)
        v = std::ldexp(mantissa(random), exponent(random));
    return values;
}

void writeText(const fs::path& path, const std::string& text) {
    std::ofstream(path, std::ios::binary) << text;
}

// Expects a qgi::Error whose message names `path`.
template <typename Fn> void expectErrorNaming(Fn&& fn, const fs::path& path) {
    try {
        fn();
        ADD_FAILURE() << "no qgi::Error for " << path;
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
}

TEST_F(IoTest, ExrFloatRgbaRoundTripIsExact) {
    ImageF image{7, 5, wideRangeFloats(mRandom, 7 * 5 * 4)};
    image.rgba[0] = std::numeric_limits<float>::infinity();
    image.rgba[1] = 0.f;
    image.rgba[2] = -0.f;
    image.rgba[3] = std::numeric_limits<float>::denorm_min();
    writeExr(mDir / "a.exr", image);
    const ImageF back = readExr(mDir / "a.exr");
    ASSERT_EQ(back.width, 7);
    ASSERT_EQ(back.height, 5);
    ASSERT_EQ(back.rgba.size(), image.rgba.size());
    for (std::size_t i = 0; i < image.rgba.size(); ++i)
        EXPECT_EQ(std::bit_cast<std::uint32_t>(back.rgba[i]),
                  std::bit_cast<std::uint32_t>(image.rgba[i]))
            << "value " << i;
}

TEST_F(IoTest, ExrRgbReadsBackWithOpaqueAlpha) {
    const std::vector<float> rgb = wideRangeFloats(mRandom, 4 * 3 * 3);
    writeExr(mDir / "rgb.exr", 4, 3, rgb, 3);
    const ImageF back = readExr(mDir / "rgb.exr");
    ASSERT_EQ(back.width * back.height, 12);
    for (std::size_t p = 0; p < 12; ++p) {
        for (std::size_t c = 0; c < 3; ++c)
            EXPECT_EQ(back.rgba[4 * p + c], rgb[3 * p + c]);
        EXPECT_EQ(back.rgba[4 * p + 3], 1.f);
    }
}

TEST_F(IoTest, ExrHalfRoundsToNearestHalf) {
    // Normal halves span 2^-14 .. 65504 and carry 11 significant bits, so rounding to nearest
    // changes a value by at most 2^-11 of itself.
    std::uniform_real_distribution<float> value(1e-3f, 6e4f);
    ImageF image{16, 16, std::vector<float>(16 * 16 * 4)};
    for (float& v : image.rgba)
        v = value(mRandom);
    writeExr(mDir / "h.exr", image, ExrPrecision::Half);
    const ImageF back = readExr(mDir / "h.exr");
    ASSERT_EQ(back.rgba.size(), image.rgba.size());
    for (std::size_t i = 0; i < image.rgba.size(); ++i)
        EXPECT_NEAR(back.rgba[i], image.rgba[i], image.rgba[i] * std::ldexp(1.f, -11));
}

TEST_F(IoTest, PngRoundTripIsExact) {
    Image8 image{9, 4, std::vector<std::uint8_t>(9 * 4 * 4)};
    std::uniform_int_distribution<int> byte(0, 255);
    for (auto& b : image.rgba)
        b = std::uint8_t(byte(mRandom));
    writePng(mDir / "a.png", image);
    const Image8 back = readPng(mDir / "a.png");
    EXPECT_EQ(back.width, 9);
    EXPECT_EQ(back.height, 4);
    EXPECT_EQ(back.rgba, image.rgba);
}

PlyMesh randomPly(std::mt19937& random, std::size_t vertices, std::size_t faces) {
    PlyMesh mesh;
    const std::vector<float> values = wideRangeFloats(random, vertices * 9);
    for (std::size_t i = 0; i < vertices; ++i) {
        const float* v = &values[9 * i];
        mesh.positions.push_back({v[0], v[1], v[2]});
        mesh.normals.push_back({v[3], v[4], v[5]});
        mesh.irradiance.push_back({v[6], v[7], v[8]});
        mesh.mobile.push_back(std::uint8_t(i % 3 == 0));
    }
    std::uniform_int_distribution<std::uint32_t> index(0, std::uint32_t(vertices - 1));
    for (std::size_t i = 0; i < faces * 3; ++i)
        mesh.triangles.push_back(index(random));
    return mesh;
}

void expectSame(const PlyMesh& a, const PlyMesh& b) {
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.normals, b.normals);
    EXPECT_EQ(a.irradiance, b.irradiance);
    EXPECT_EQ(a.mobile, b.mobile);
    EXPECT_EQ(a.triangles, b.triangles);
}

TEST_F(IoTest, PlyBinaryAndAsciiRoundTripsAreExact) {
    const PlyMesh mesh = randomPly(mRandom, 50, 20);
    for (const PlyFormat format : {PlyFormat::BinaryLittleEndian, PlyFormat::Ascii}) {
        const fs::path path = mDir / (format == PlyFormat::Ascii ? "a.ply" : "b.ply");
        writePly(path, mesh, format);
        expectSame(readPly(path), mesh);
    }
}

TEST_F(IoTest, PlyWithoutFacesHasTheDocumentedHeader) {
    const PlyMesh mesh = randomPly(mRandom, 3, 0);
    writePly(mDir / "points.ply", mesh, PlyFormat::Ascii);
    std::ifstream file(mDir / "points.ply");
    std::string text((std::istreambuf_iterator<char>(file)), {});
    EXPECT_TRUE(text.starts_with("ply\nformat ascii 1.0\n"));
    EXPECT_NE(text.find("element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                        "property float nx\nproperty float ny\nproperty float nz\n"
                        "property float er\nproperty float eg\nproperty float eb\n"
                        "property uchar mobile\nend_header\n"),
              std::string::npos);
    EXPECT_EQ(text.find("element face"), std::string::npos);
    expectSame(readPly(mDir / "points.ply"), mesh);
}

TEST_F(IoTest, PlyNoteIsAHeaderCommentThatReadsBackAndExportsAreKnownAgain) {
    const PlyMesh mesh = randomPly(mRandom, 5, 2);
    writePly(mDir / "noted.ply", mesh, PlyFormat::BinaryLittleEndian, "hybrid mode: indirect");
    std::ifstream file(mDir / "noted.ply", std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(file)), {});
    EXPECT_NE(text.find("W/m^2\ncomment hybrid mode: indirect\nelement vertex 5\n"),
              std::string::npos);
    expectSame(readPly(mDir / "noted.ply"), mesh);
    EXPECT_TRUE(isIrradiancePly(mDir / "noted.ply"));
    expectErrorNaming([&] { writePly(mDir / "bad.ply", mesh, PlyFormat::Ascii, "two\nlines"); },
                      mDir / "bad.ply");
    std::ofstream(mDir / "notes.txt") << "my notes";
    EXPECT_FALSE(isIrradiancePly(mDir / "notes.txt"));
    std::ofstream(mDir / "bunny.ply") << "ply\nformat ascii 1.0\nelement vertex 0\nend_header\n";
    EXPECT_FALSE(isIrradiancePly(mDir / "bunny.ply")) << "somebody's PLY";
    EXPECT_FALSE(isIrradiancePly(mDir / "missing.ply"));
    EXPECT_FALSE(isIrradiancePly(mDir)) << "a folder";
}

TEST_F(IoTest, WritesToAMissingFolderThrowNamingThePath) {
    const fs::path missing = mDir / "no_such_folder";
    const std::vector<float> rgba(4, 1.f);
    const std::vector<std::uint8_t> bytes(4, 255);
    const PlyMesh mesh = randomPly(mRandom, 3, 1);
    expectErrorNaming([&] { writeExr(missing / "a.exr", 1, 1, rgba, 4); }, missing / "a.exr");
    expectErrorNaming([&] { writePng(missing / "a.png", 1, 1, bytes); }, missing / "a.png");
    expectErrorNaming([&] { writePly(missing / "a.ply", mesh); }, missing / "a.ply");
}

std::string readAll(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST_F(IoTest, AtomicWriteReplacesTheFileOrLeavesItAsItWas) {
    const fs::path file = mDir / "out.ply";
    writeFileAtomically(file, "first", "test file");
    EXPECT_EQ(readAll(file), "first");
    writeFileAtomically(file, "second, longer", "test file");
    EXPECT_EQ(readAll(file), "second, longer");
    writeFileAtomically(file, "", "test file"); // empty is a file too
    EXPECT_TRUE(fs::exists(file));
    EXPECT_EQ(fs::file_size(file), 0u);

    // A write that fails after the temporary file was written (the name is a folder, so the
    // rename fails) throws naming the path, and leaves the folder as it was: nothing beside it.
    const fs::path folder = mDir / "taken";
    fs::create_directories(folder / "inside");
    expectErrorNaming([&] { writeFileAtomically(folder, "bytes", "test file"); }, folder);
    EXPECT_TRUE(fs::is_directory(folder / "inside"));
    std::size_t entries = 0;
    for ([[maybe_unused]] const auto& entry : fs::directory_iterator(mDir))
        ++entries;
    EXPECT_EQ(entries, 2u); // out.ply and taken/: no temporary file left
    // So does one that cannot open its temporary file (a missing folder).
    expectErrorNaming([&] { writeFileAtomically(mDir / "missing" / "a", "x", "test file"); },
                      mDir / "missing" / "a");
}

TEST_F(IoTest, ABareFileNameIsWrittenInTheWorkingFolder) {
    // A name without a folder names a file in the working folder, which is its write target's
    // folder: before, that folder came out empty and the demo refused "shot" as an output.
    const fs::path before = fs::current_path();
    fs::current_path(mDir);
    const fs::path target = writeTarget("bare.csv");
    writeFileAtomically("bare.csv", "here", "test file");
    fs::current_path(before);
    EXPECT_EQ(target, fs::weakly_canonical(mDir) / "bare.csv");
    EXPECT_EQ(target.parent_path(), fs::weakly_canonical(mDir));
    EXPECT_EQ(readAll(mDir / "bare.csv"), "here");
}

TEST_F(IoTest, AtomicWriteThroughASymbolicLinkChangesTheFileItNames) {
    // A dangling link names the file a write creates: an output clash check compares that.
    const fs::path target = mDir / "target.csv", link = mDir / "link.csv";
    fs::create_symlink("target.csv", link);
    EXPECT_EQ(writeTarget(link), writeTarget(target));
    EXPECT_EQ(writeTarget(link), fs::weakly_canonical(mDir) / "target.csv");
    writeFileAtomically(link, "through the link", "test file");
    EXPECT_TRUE(fs::is_symlink(link));
    EXPECT_EQ(readAll(target), "through the link");
    // A loop of links: the write fails with an error, not a hang, and leaves the links.
    fs::create_symlink("loop_b", mDir / "loop_a");
    fs::create_symlink("loop_a", mDir / "loop_b");
    expectErrorNaming([&] { writeFileAtomically(mDir / "loop_a", "x", "test file"); },
                      mDir / "loop_a");
    EXPECT_TRUE(fs::is_symlink(mDir / "loop_a"));
    EXPECT_TRUE(fs::is_symlink(mDir / "loop_b"));
}

TEST_F(IoTest, AtomicWriteKeepsTheFilesPermissions) {
    const fs::path file = mDir / "shared.csv";
    writeFileAtomically(file, "a", "test file");
    EXPECT_EQ(fs::status(file).permissions(), fs::perms::owner_read | fs::perms::owner_write |
                                                  fs::perms::group_read | fs::perms::others_read);
    fs::permissions(file, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_write |
                              fs::perms::group_read);
    writeFileAtomically(file, "b", "test file");
    EXPECT_EQ(fs::status(file).permissions(), fs::perms::owner_read | fs::perms::owner_write |
                                                  fs::perms::group_read | fs::perms::group_write);
    EXPECT_EQ(readAll(file), "b");
}

TEST_F(IoTest, ReadsOfMissingOrCorruptFilesThrowNamingThePath) {
    for (const char* name : {"none.exr", "none.png", "none.ply"}) {
        const fs::path path = mDir / name;
        expectErrorNaming([&] { readExr(path); }, path);
        expectErrorNaming([&] { readPng(path); }, path);
        expectErrorNaming([&] { readPly(path); }, path);
    }
    const fs::path junk = mDir / "junk.bin";
    writeText(junk, "this is not an image or a mesh");
    expectErrorNaming([&] { readExr(junk); }, junk);
    expectErrorNaming([&] { readPng(junk); }, junk);
    expectErrorNaming([&] { readPly(junk); }, junk);
}

TEST_F(IoTest, MalformedPlyFilesThrow) {
    const PlyMesh mesh = randomPly(mRandom, 4, 2);
    const fs::path good = mDir / "good.ply";
    const std::string text = plyText(mesh);

    const fs::path bad = mDir / "bad.ply";
    writeText(bad, text.substr(0, text.size() - 5)); // truncated data
    expectErrorNaming([&] { readPly(bad); }, bad);

    std::string wrongProperty = text;
    wrongProperty.replace(wrongProperty.find("float er"), 8, "double e");
    writeText(bad, wrongProperty);
    expectErrorNaming([&] { readPly(bad); }, bad);

    std::string hugeCount = text;
    hugeCount.replace(hugeCount.find("vertex 4"), 8, "vertex 99999999999");
    writeText(bad, hugeCount);
    expectErrorNaming([&] { readPly(bad); }, bad);

    PlyMesh outOfRange = mesh;
    outOfRange.triangles[0] = 7; // only 4 vertices
    expectErrorNaming([&] { writePly(bad, outOfRange); }, bad);
    writePly(good, mesh, PlyFormat::Ascii);
    std::ifstream asciiFile(good, std::ios::binary);
    std::string ascii((std::istreambuf_iterator<char>(asciiFile)), {});
    ascii[ascii.rfind('\n', ascii.size() - 2) + 1] = '4'; // last face: a quad, not a triangle
    writeText(bad, ascii);
    expectErrorNaming([&] { readPly(bad); }, bad);
}

// A message quotes the offending header line: its control bytes come out escaped and a long
// line cut short, so the message stays one short printable line (a fuzzer found the raw ones).
TEST_F(IoTest, MalformedPlyMessagesAreOnePrintableLine) {
    const std::string text = plyText(randomPly(mRandom, 4, 2));
    const fs::path bad = mDir / "bad.ply";
    const auto message = [&](const std::string& contents) {
        writeText(bad, contents);
        try {
            readPly(bad);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        ADD_FAILURE() << "no qgi::Error";
        return std::string();
    };
    std::string bell = text;
    bell.replace(bell.find("float er"), 8, "float e\a\x1b[2J");
    const std::string escaped = message(bell);
    EXPECT_NE(escaped.find("float e\\x07\\x1b[2J"), std::string::npos) << escaped;
    std::string longLine = text;
    longLine.replace(longLine.find("float er"), 8, "float " + std::string(5000, 'e'));
    const std::string cut = message(longLine);
    EXPECT_LT(cut.size(), 500u) << cut.size();
    EXPECT_EQ(cut.substr(cut.size() - 3), "...");
    for (const std::string& m : {escaped, cut})
        for (const char c : m)
            EXPECT_TRUE(static_cast<unsigned char>(c) >= 0x20 && c != 0x7f) << m;
}

TEST_F(IoTest, MismatchedSizesThrow) {
    const std::vector<float> three(3, 0.f);
    expectErrorNaming([&] { writeExr(mDir / "s.exr", 2, 2, three, 3); }, mDir / "s.exr");
    expectErrorNaming([&] { writeExr(mDir / "s.exr", 1, 1, three, 2); }, mDir / "s.exr");
    const std::vector<std::uint8_t> bytes(3, 0);
    expectErrorNaming([&] { writePng(mDir / "s.png", 1, 1, bytes); }, mDir / "s.png");
    PlyMesh mesh = randomPly(mRandom, 3, 1);
    mesh.normals.pop_back();
    expectErrorNaming([&] { writePly(mDir / "s.ply", mesh); }, mDir / "s.ply");
}

} // namespace
} // namespace qgi
