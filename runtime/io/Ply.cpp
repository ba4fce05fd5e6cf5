#include "runtime/io/Ply.h"
#include "runtime/io/AtomicFile.h"

#include "runtime/core/Error.h"
#include "runtime/core/Log.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <charconv>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <string_view>
#include <utility>

namespace qgi {
namespace {

static_assert(std::endian::native == std::endian::little,
              "binary PLY is written and read with the host's byte order");

constexpr std::array<std::string_view, 10> kVertexProperties{
    "property float x",  "property float y",     "property float z",  "property float nx",
    "property float ny", "property float nz",    "property float er", "property float eg",
    "property float eb", "property uchar mobile"};
constexpr std::string_view kFaceProperty = "property list uchar uint vertex_indices";
constexpr std::size_t kBinaryVertexBytes = 9 * sizeof(float) + 1;
constexpr std::size_t kBinaryFaceBytes = 1 + 3 * sizeof(std::uint32_t);
constexpr std::size_t kMinAsciiVertexChars = 20; // "0 0 0 0 0 0 0 0 0 0\n"
constexpr std::size_t kMinAsciiFaceChars = 8;    // "3 0 0 0\n"

void appendFloat(std::string& out, float value) {
    std::array<char, 32> text;
    const auto result = std::to_chars(text.data(), text.data() + text.size(), value);
    out.append(text.data(), result.ptr);
}

void appendBytes(std::string& out, const void* data, std::size_t size) {
    out.append(static_cast<const char*>(data), size);
}

/// Reads one header or body item at a time from the file's text; every failure names the file.
class PlyParser {
public:
    PlyParser(const std::filesystem::path& path, std::string text)
        : mPath(path), mText(std::move(text)) {}

    /// `what` may quote the file: its control bytes are escaped and its length bounded, so
    /// the message stays one short line.
    [[noreturn]] void error(std::string_view what) const {
        fail("malformed PLY '", mPath.string(), "': ", printableExcerpt(what, 300));
    }

    std::string_view line() {
        if (mPos >= mText.size()) error("header ends before end_header");
        std::size_t end = mText.find('\n', mPos);
        if (end == std::string::npos) end = mText.size();
        std::string_view result(mText.data() + mPos, end - mPos);
        mPos = std::min(end + 1, mText.size());
        if (!result.empty() && result.back() == '\r') result.remove_suffix(1);
        return result;
    }

    /// Next header line that is not a comment.
    std::string_view headerLine() {
        for (;;) {
            const std::string_view l = line();
            if (!l.starts_with("comment") && !l.starts_with("obj_info")) return l;
        }
    }

    std::uint64_t elementCount(std::string_view l, std::string_view element) const {
        const std::string prefix = str("element ", element, " ");
        if (!l.starts_with(prefix)) error(str("expected '", prefix, "<count>', found '", l, "'"));
        std::uint64_t count = 0;
        const char* end = l.data() + l.size();
        const auto [ptr, ec] = std::from_chars(l.data() + prefix.size(), end, count);
        if (ec != std::errc() || ptr != end) error(str("bad count in '", l, "'"));
        return count;
    }

    std::size_t remaining() const { return mText.size() - mPos; }

    template <typename T> T binary() {
        T value;
        std::memcpy(&value, mText.data() + mPos, sizeof(T));
        mPos += sizeof(T);
        return value;
    }

    template <typename T> T ascii(std::string_view what) {
        while (mPos < mText.size() && std::isspace(static_cast<unsigned char>(mText[mPos])))
            ++mPos;
        T value{};
        const auto [ptr, ec] =
            std::from_chars(mText.data() + mPos, mText.data() + mText.size(), value);
        if (ec != std::errc()) error(str("bad or missing ", what, " at byte ", mPos));
        mPos = std::size_t(ptr - mText.data());
        return value;
    }

private:
    const std::filesystem::path& mPath;
    std::string mText;
    std::size_t mPos = 0;
};

} // namespace

void writePly(const std::filesystem::path& path, std::span<const glm::vec3> positions,
              std::span<const glm::vec3> normals, std::span<const glm::vec3> irradiance,
              std::span<const std::uint8_t> mobile, std::span<const std::uint32_t> triangles,
              PlyFormat format, std::string_view note) {
    const std::size_t n = positions.size();
    if (note.find_first_of("\r\n") != std::string_view::npos)
        fail("cannot write PLY '", path.string(), "': the note spans more than one line");
    if (normals.size() != n || irradiance.size() != n || mobile.size() != n)
        fail("cannot write PLY '", path.string(), "': ", n, " positions but ", normals.size(),
             " normals, ", irradiance.size(), " irradiance values, ", mobile.size(),
             " mobile flags");
    if (triangles.size() % 3 != 0)
        fail("cannot write PLY '", path.string(), "': ", triangles.size(),
             " triangle indices is not a multiple of 3");
    for (const std::uint32_t index : triangles)
        if (index >= n)
            fail("cannot write PLY '", path.string(), "': vertex index ", index, " >= ", n);

    const bool binary = format == PlyFormat::BinaryLittleEndian;
    std::string out =
        str("ply\nformat ", binary ? "binary_little_endian" : "ascii",
            " 1.0\ncomment qgi vertex irradiance: x y z metres, nx ny nz unit "
            "normal, er eg eb W/m^2\n",
            note.empty() ? std::string() : str("comment ", note, "\n"), "element vertex ", n, "\n");
    for (const std::string_view property : kVertexProperties)
        out.append(property).append("\n");
    if (!triangles.empty())
        out.append(str("element face ", triangles.size() / 3, "\n", kFaceProperty, "\n"));
    out.append("end_header\n");

    out.reserve(out.size() + n * (binary ? kBinaryVertexBytes : 120) + triangles.size() * 12);
    for (std::size_t i = 0; i < n; ++i) {
        const std::array<float, 9> values{positions[i].x,  positions[i].y,  positions[i].z,
                                          normals[i].x,    normals[i].y,    normals[i].z,
                                          irradiance[i].x, irradiance[i].y, irradiance[i].z};
        if (binary) {
            appendBytes(out, values.data(), sizeof(values));
            const std::uint8_t flag = mobile[i] != 0;
            appendBytes(out, &flag, 1);
        } else {
            for (const float v : values) {
                appendFloat(out, v);
                out.push_back(' ');
            }
            out.append(mobile[i] != 0 ? "1\n" : "0\n");
        }
    }
    for (std::size_t t = 0; t < triangles.size(); t += 3) {
        if (binary) {
            const std::uint8_t count = 3;
            appendBytes(out, &count, 1);
            appendBytes(out, &triangles[t], 3 * sizeof(std::uint32_t));
        } else {
            out.append(str("3 ", triangles[t], " ", triangles[t + 1], " ", triangles[t + 2], "\n"));
        }
    }

    writeFileAtomically(path, out, "PLY");
}

bool isIrradiancePly(const std::filesystem::path& path) {
    std::error_code error;
    if (!std::filesystem::is_regular_file(path, error)) return false; // a FIFO would block
    std::ifstream file(path, std::ios::binary);
    std::string head(160, '\0');
    file.read(head.data(), std::streamsize(head.size()));
    head.resize(std::size_t(file.gcount()));
    return head.starts_with("ply\nformat ") &&
           head.find("\ncomment qgi vertex irradiance: ") != std::string::npos;
}

PlyMesh readPly(const std::filesystem::path& path) {
    std::ifstream file(path, std::ios::binary);
    if (!file) fail("cannot read PLY '", path.string(), "': cannot open the file");
    PlyParser parser(path, std::string(std::istreambuf_iterator<char>(file), {}));

    if (parser.line() != "ply") parser.error("missing 'ply' magic line");
    const std::string_view formatLine = parser.headerLine();
    bool binary = false;
    if (formatLine == "format binary_little_endian 1.0")
        binary = true;
    else if (formatLine != "format ascii 1.0")
        parser.error(str("unsupported '", formatLine, "'"));

    const std::uint64_t vertexCount = parser.elementCount(parser.headerLine(), "vertex");
    for (const std::string_view expected : kVertexProperties)
        if (const std::string_view l = parser.headerLine(); l != expected)
            parser.error(str("expected '", expected, "', found '", l, "'"));
    std::uint64_t faceCount = 0;
    if (std::string_view l = parser.headerLine(); l != "end_header") {
        faceCount = parser.elementCount(l, "face");
        if (const std::string_view p = parser.headerLine(); p != kFaceProperty)
            parser.error(str("expected '", kFaceProperty, "', found '", p, "'"));
        if (const std::string_view e = parser.headerLine(); e != "end_header")
            parser.error(str("expected 'end_header', found '", e, "'"));
    }

    // Reject counts the file cannot hold before allocating for them.
    const std::size_t available = parser.remaining();
    if (vertexCount > available || faceCount > available ||
        (binary ? vertexCount * kBinaryVertexBytes + faceCount * kBinaryFaceBytes != available
                : vertexCount * kMinAsciiVertexChars + faceCount * kMinAsciiFaceChars > available))
        parser.error(str(vertexCount, " vertices and ", faceCount, " faces do not match the ",
                         available, " bytes of data"));

    PlyMesh mesh;
    mesh.positions.resize(vertexCount);
    mesh.normals.resize(vertexCount);
    mesh.irradiance.resize(vertexCount);
    mesh.mobile.resize(vertexCount);
    mesh.triangles.resize(faceCount * 3);
    for (std::size_t i = 0; i < vertexCount; ++i) {
        std::array<float, 9> v;
        for (float& value : v)
            value = binary ? parser.binary<float>() : parser.ascii<float>("float");
        mesh.positions[i] = {v[0], v[1], v[2]};
        mesh.normals[i] = {v[3], v[4], v[5]};
        mesh.irradiance[i] = {v[6], v[7], v[8]};
        const unsigned mobile =
            binary ? parser.binary<std::uint8_t>() : parser.ascii<unsigned>("mobile flag");
        if (mobile > 1) parser.error(str("vertex ", i, " has mobile flag ", mobile));
        mesh.mobile[i] = std::uint8_t(mobile);
    }
    for (std::size_t f = 0; f < faceCount; ++f) {
        const unsigned count =
            binary ? parser.binary<std::uint8_t>() : parser.ascii<unsigned>("face size");
        if (count != 3) parser.error(str("face ", f, " has ", count, " vertices, expected 3"));
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t index =
                binary ? parser.binary<std::uint32_t>() : parser.ascii<std::uint32_t>("index");
            if (index >= vertexCount)
                parser.error(str("face ", f, " refers to vertex ", index, " of ", vertexCount));
            mesh.triangles[3 * f + k] = index;
        }
    }
    return mesh;
}

} // namespace qgi
