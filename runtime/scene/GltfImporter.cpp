#include "runtime/scene/GltfImporter.h"

#include "components/Avatar.h"
#include "components/Camera.h"
#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PathFollower.h"
#include "components/PointCacheShaded.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Finite.h"
#include "runtime/core/Log.h"
#include "runtime/scene/MeshProcessing.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneLoader.h"
#include "runtime/scene/TextureLibrary.h"

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtx/component_wise.hpp>
#include <glm/gtx/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <nlohmann/json.hpp>
#include <stb/stb_image.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>
#include <variant>

namespace qgi {

namespace fs = std::filesystem;

static_assert(std::endian::native == std::endian::little, "glTF buffers are little endian");

namespace {

} // namespace

int jsonNestingDepth(std::string_view text) {
    int depth = 0;
    int deepest = 0;
    bool inString = false;
    for (std::size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (inString) {
            if (c == '\\')
                ++i; // the escaped character cannot end the string
            else if (c == '"')
                inString = false;
        } else if (c == '"') {
            inString = true;
        } else if (c == '[' || c == '{') {
            deepest = std::max(deepest, ++depth);
        } else if (c == ']' || c == '}') {
            --depth;
        }
    }
    return deepest;
}

std::optional<Transform> decomposeTrs(const glm::mat4& m) {
    if (!isFinite(m)) return std::nullopt;
    if (m[0][3] != 0.f || m[1][3] != 0.f || m[2][3] != 0.f || m[3][3] != 1.f) return std::nullopt;

    const glm::mat3 basis(m);
    glm::vec3 scale(glm::length(basis[0]), glm::length(basis[1]), glm::length(basis[2]));
    if (!(scale.x > 0.f && scale.y > 0.f && scale.z > 0.f)) return std::nullopt;
    if (glm::determinant(basis) < 0.f) scale.x = -scale.x; // a mirror: fold it into one axis
    const glm::mat3 rotation(basis[0] / scale.x, basis[1] / scale.y, basis[2] / scale.z);
    // Decimal matrices in JSON carry ~7 digits; anything further from orthogonal is shear.
    constexpr float kTolerance = 1e-4f;
    if (std::abs(glm::dot(rotation[0], rotation[1])) > kTolerance ||
        std::abs(glm::dot(rotation[0], rotation[2])) > kTolerance ||
        std::abs(glm::dot(rotation[1], rotation[2])) > kTolerance)
        return std::nullopt;

    Transform t;
    t.translation = glm::vec3(m[3]);
    t.rotation = glm::normalize(glm::quat_cast(rotation));
    t.scale = scale;
    return t;
}

namespace {

constexpr std::string_view kLightsExtension = "KHR_lights_punctual";
constexpr std::string_view kEmissiveStrengthExtension = "KHR_materials_emissive_strength";

enum class Mobility { Static, Mobile, Avatar };

using Light = std::variant<std::monostate, PointLight, SpotLight, DirectionalLight>;

/// One triangle primitive as read from the file, before processing.
struct RawPrimitive {
    std::string field; ///< "meshes[m].primitives[p]", for messages
    Mesh mesh;
    int material = -1;
};

/// One future entity. Records are ordered parents first; `parent` indexes the records.
struct EntityRecord {
    std::string name;
    Transform transform; ///< parent left null
    int parent = -1;
    glm::mat4 world{1.f};
    std::optional<Camera> camera;
    Light light;
    bool lightStandIn = false; ///< node extras {"standIn": true}: see LightStandIn
    bool pointCacheShaded = false; ///< node extras {"pointCache": true}: see PointCacheShaded
    std::optional<PathFollower> path; ///< from the file's animations (readAnimations)
    Mobility mobility = Mobility::Static;
    const RawPrimitive* source = nullptr; ///< the primitive this entity draws, if any
    bool primitiveOnly = false; ///< exists only to hold one primitive of a multi-primitive mesh
    std::optional<Mesh> mesh;   ///< processed `source`
    Material material;
    float avatarRadius = 0.f; ///< metres
};

/// Everything an import produces, checked and complete, before any entity exists.
struct ImportedScene {
    std::vector<EntityRecord> records;
    SceneInfo info;
    TextureLibrary textures;
};

/// A checked accessor: `count` elements, `stride` bytes apart, from `data`.
struct AccessorData {
    const unsigned char* data = nullptr;
    std::size_t stride = 0;
    std::size_t count = 0;
    int componentType = 0;
};

template <typename T> T load(const unsigned char* p) {
    T value;
    std::memcpy(&value, p, sizeof value); // glTF does not promise alignment to hostile files
    return value;
}

/// Bytes per component of a glTF 2.0 accessor component type; 0 for anything else.
std::size_t componentBytes(int componentType) {
    switch (componentType) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return 4;
    default:
        return 0; // INT and DOUBLE exist in tinygltf, not in glTF 2.0 accessors
    }
}

const char* componentName(int componentType) {
    switch (componentType) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
        return "BYTE";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return "UNSIGNED_BYTE";
    case TINYGLTF_COMPONENT_TYPE_SHORT:
        return "SHORT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return "UNSIGNED_SHORT";
    case TINYGLTF_COMPONENT_TYPE_INT:
        return "INT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
        return "UNSIGNED_INT";
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return "FLOAT";
    case TINYGLTF_COMPONENT_TYPE_DOUBLE:
        return "DOUBLE";
    default:
        return "unknown";
    }
}

const char* typeName(int type) {
    switch (type) {
    case TINYGLTF_TYPE_SCALAR:
        return "SCALAR";
    case TINYGLTF_TYPE_VEC2:
        return "VEC2";
    case TINYGLTF_TYPE_VEC3:
        return "VEC3";
    case TINYGLTF_TYPE_VEC4:
        return "VEC4";
    case TINYGLTF_TYPE_MAT2:
        return "MAT2";
    case TINYGLTF_TYPE_MAT3:
        return "MAT3";
    case TINYGLTF_TYPE_MAT4:
        return "MAT4";
    default:
        return "unknown";
    }
}

const char* modeName(int mode) {
    static constexpr const char* kNames[] = {"POINTS",      "LINES",     "LINE_LOOP",
                                             "LINE_STRIP",  "TRIANGLES", "TRIANGLE_STRIP",
                                             "TRIANGLE_FAN"};
    return mode >= 0 && mode < 7 ? kNames[mode] : "unknown";
}

/// Bytes of one accessor element, with the column padding the spec requires for small matrices.
std::size_t elementBytes(int componentType, int type) {
    const std::size_t c = componentBytes(componentType);
    switch (type) {
    case TINYGLTF_TYPE_MAT2:
        return c == 1 ? 8 : 4 * c;
    case TINYGLTF_TYPE_MAT3:
        return c == 1 ? 12 : c == 2 ? 24 : 9 * c;
    default:
        return c * std::size_t(tinygltf::GetNumComponentsInType(std::uint32_t(type)));
    }
}

/// Replaces line breaks so a message from a library stays one line, and bounds its length
/// (tinygltf quotes whole data URIs).
std::string oneLine(std::string text) {
    constexpr std::size_t kMaxLength = 300;
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back())))
        text.pop_back();
    std::replace_if(
        text.begin(), text.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
    if (text.size() > kMaxLength) text = text.substr(0, kMaxLength) + "...";
    return text;
}

bool isPngOrJpeg(const unsigned char* bytes, int size) {
    static constexpr unsigned char kPng[] = {0x89, 'P', 'N', 'G'};
    static constexpr unsigned char kJpeg[] = {0xff, 0xd8, 0xff};
    return (size >= 4 && std::memcmp(bytes, kPng, 4) == 0) ||
           (size >= 3 && std::memcmp(bytes, kJpeg, 3) == 0);
}

/// Decodes a PNG or JPEG into `image` as 8-bit RGBA. Returns what is wrong, or "" on success.
std::string decodeRgba8(const unsigned char* bytes, std::size_t size, tinygltf::Image& image) {
    if (size > kGltfMaxFileBytes) return "encoded image is larger than the file size limit";
    const int length = int(size);
    if (!isPngOrJpeg(bytes, length)) return "not a PNG or JPEG image";
    int width = 0, height = 0, channels = 0;
    // Read the header first: a few bytes of PNG can claim gigabytes of pixels.
    if (!stbi_info_from_memory(bytes, length, &width, &height, &channels))
        return str("unreadable image header (", stbi_failure_reason(), ")");
    if (width > kGltfMaxImageSide || height > kGltfMaxImageSide ||
        std::int64_t(width) * height > kGltfMaxImagePixels)
        return str(width, "x", height, " pixels exceed the limit of ", kGltfMaxImageSide,
                   " per side and ", kGltfMaxImagePixels, " in all");
    const std::unique_ptr<stbi_uc, void (*)(void*)> pixels(
        stbi_load_from_memory(bytes, length, &width, &height, &channels, 4), &stbi_image_free);
    if (!pixels) return str("cannot be decoded (", stbi_failure_reason(), ")");
    image.width = width;
    image.height = height;
    image.component = 4;
    image.bits = 8;
    image.pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    image.image.assign(pixels.get(), pixels.get() + std::size_t(width) * std::size_t(height) * 4);
    return {};
}

/// What the image callback knows and reports: which images are drawn, a failure (tinygltf
/// would only keep a string), the images replaced for want of a decoder.
struct ImageDecoding {
    std::string field;
    std::string what;
    /// Per image: a material draws it (through a texture's source). An image nothing draws,
    /// such as one in a format an optional extension adds next to a PNG fallback, may fail to
    /// decode: it is replaced by one white pixel, with a warning.
    std::vector<bool> used;
    std::vector<std::string> skipped;
};

/// Replaces an undecodable image nothing draws by one white pixel; false if it is drawn.
bool skipUnusedImage(ImageDecoding& context, int index, const std::string& what,
                     tinygltf::Image& image) {
    if (index < 0 || (std::size_t(index) < context.used.size() && context.used[std::size_t(index)]))
        return false;
    image.width = image.height = 1;
    image.component = 4;
    image.bits = 8;
    image.pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    image.image.assign(4, 255);
    context.skipped.push_back(str("images[", index, "]: ", what, "; no material draws it"));
    return true;
}

/// tinygltf image callback. Images in buffer views are skipped here and decoded once their
/// view has been range-checked: tinygltf hands over an unchecked pointer for them.
bool decodeImageCallback(tinygltf::Image* image, const int index, std::string*, std::string*, int,
                         int, const unsigned char* bytes, int size, void* user) {
    if (image->bufferView >= 0) return true;
    std::string what = decodeRgba8(bytes, std::size_t(size), *image);
    if (what.empty()) return true;
    auto& context = *static_cast<ImageDecoding*>(user);
    if (skipUnusedImage(context, index, what, *image)) return true;
    context.field = str("images[", index, "]");
    context.what = std::move(what);
    return false;
}

struct Base64Check {
    std::size_t bytes = 0;                      ///< decoded size
    std::size_t badAt = std::string_view::npos; ///< offset of the first invalid character
};

Base64Check checkBase64(std::string_view text) {
    std::size_t padding = 0;
    while (padding < 2 && padding < text.size() && text[text.size() - 1 - padding] == '=')
        ++padding;
    const std::size_t digits = text.size() - padding;
    for (std::size_t i = 0; i < digits; ++i) {
        const char c = text[i];
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '+' && c != '/') return {0, i};
    }
    if (digits % 4 == 1 || (padding > 0 && text.size() % 4 != 0)) return {0, text.size()};
    return {digits * 6 / 8, std::string_view::npos};
}

/// Reads one glTF file into an ImportedScene, checking everything on the way.
class GltfReader {
public:
    GltfReader(const fs::path& path, const SceneOptions& options)
        : mPath(path), mFolder(fs::absolute(path).parent_path()), mLabel(path.filename().string()),
          mOptions(options) {}

    ImportedScene read();

private:
    template <typename... Args>
    [[noreturn]] void fail(std::string_view field, Args&&... what) const {
        if (field.empty()) qgi::fail(mLabel, ": ", std::forward<Args>(what)...);
        qgi::fail(mLabel, ": ", field, ": ", std::forward<Args>(what)...);
    }
    void checkIndex(std::string_view field, int index, std::size_t count,
                    std::string_view what) const {
        if (index < 0 || std::size_t(index) >= count)
            fail(field, "index ", index, " out of range (", count, " ", what, ")");
    }

    // Before tinygltf: the raw file, the GLB container, the JSON syntax and every URI.
    std::vector<unsigned char> readFile() const;
    std::string_view glbJsonChunk(const std::vector<unsigned char>& bytes) const;
    /// Parses the JSON (syntax errors end here, with line and column), then checks the URIs
    /// of every buffer and image.
    void checkUris(std::string_view json);
    /// The JSON types of the fields qgi reads (tinygltf quietly puts a default in place of a
    /// value of the wrong type: a string intensity, a float index, a negative offset).
    void checkTypes(const nlohmann::json& document) const;
    /// Which images a material draws (ImageDecoding::used); after checkTypes.
    void findUsedImages(const nlohmann::json& document);
    /// Warns about the images replaced by skipUnusedImage since the last call.
    void reportSkippedImages();
    void checkUri(const nlohmann::json& object, const std::string& section, std::size_t index,
                  bool isBuffer) const;
    /// The file a relative URI names inside the scene's folder; throws for anything else.
    fs::path resolveUri(const std::string& field, const std::string& uri) const;
    void loadModel(const std::vector<unsigned char>& bytes, std::string_view json, bool glb);

    // After tinygltf: what it does not check, then the conversion to components.
    void checkAsset() const;
    void checkBufferViews() const;
    void checkAccessors() const;
    TextureLibrary decodeImages();
    /// A range-checked accessor used as `usage` (a field path), of the given type and one of
    /// the given component types.
    AccessorData useAccessor(const std::string& usage, int index, int type,
                             std::initializer_list<int> componentTypes) const;
    /// Accessor `index`'s own buffer view, as stored.
    AccessorData rawView(int index, std::size_t element) const;
    /// Writes a sparse accessor's substitutions over its dense elements.
    void applySparse(int index, std::size_t element, std::vector<unsigned char>& dense) const;
    std::vector<glm::vec3> readVec3(const std::string& usage, int index) const;
    std::vector<glm::vec2> readTexcoords(const std::string& usage, int index) const;
    std::vector<std::uint32_t> readIndices(const std::string& usage, int index,
                                           std::size_t vertexCount) const;
    std::vector<RawPrimitive> readMesh(int meshIndex) const;
    Material readMaterial(int index) const;
    std::optional<Camera> readCamera(int index) const;
    Light readLight(int index) const;

    /// Parent of every node (-1 for roots), after checking children indices, single parents,
    /// cycles and depth.
    std::vector<int> checkNodeGraph() const;
    std::vector<int> sceneRoots(const std::vector<int>& parents) const;
    Transform localTransform(int index) const;
    std::optional<Mobility> nodeMobility(int index) const;
    bool nodeStandIn(int index) const;
    bool nodePointCache(int index) const;
    int nodeLight(int index) const;
    /// One record per node below `roots` (and per primitive of multi-primitive meshes).
    std::vector<EntityRecord> traverse(const std::vector<int>& roots);
    /// Turns the animations' translation and rotation channels into PathFollowers on the
    /// records of their nodes (see the header).
    void readAnimations(std::vector<EntityRecord>& records) const;
    /// Node extras {"qgiPath": {"loop": bool, "timeOffset": s}} (what glTF cannot say).
    void readPathExtras(int index, PathFollower& path) const;
    std::vector<float> readScalars(const std::string& usage, int index) const;
    std::vector<glm::vec4> readRotations(const std::string& usage, int index) const;
    /// Chooses the edge bound, runs processMesh, fills materials, bounds and avatar radii.
    void processMeshes(ImportedScene& scene) const;
    /// Refuses a scene so far from the origin that float positions cannot resolve it, and
    /// warns where they resolve it only coarsely.
    void checkPrecision(const Aabb& bounds) const;
    /// Refuses a mesh node whose world matrix scales beyond reason; false (with a warning) when
    /// it scales an axis to nearly nothing, which hides the mesh.
    bool checkMeshScale(const std::string& field, const glm::mat4& world) const;

    fs::path mPath;
    fs::path mFolder;
    std::string mLabel;
    SceneOptions mOptions;
    tinygltf::Model mModel;
    ImageDecoding mImages;
    std::vector<std::optional<std::vector<RawPrimitive>>> mRawMeshes; // by mesh index, on use
    std::vector<int> mNodeRecord; ///< per node, its record (traverse); -1: not in the scene
    /// Sparse accessors and accessors without a buffer view, laid out densely while read.
    mutable std::deque<std::vector<unsigned char>> mDenseAccessors;
};

std::vector<unsigned char> GltfReader::readFile() const {
    std::error_code error;
    const std::uintmax_t size = fs::file_size(mPath, error);
    if (error) fail("", "cannot read '", mPath.string(), "': ", error.message());
    if (size == 0) fail("", "file is empty");
    if (size > kGltfMaxFileBytes)
        fail("", "file has ", size, " bytes, more than the limit of ", kGltfMaxFileBytes);
    std::vector<unsigned char> bytes(size);
    std::ifstream in(mPath, std::ios::binary);
    in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(size));
    if (!in) fail("", "cannot read '", mPath.string(), "'");
    return bytes;
}

std::string_view GltfReader::glbJsonChunk(const std::vector<unsigned char>& bytes) const {
    constexpr std::size_t kHeaderBytes = 12 + 8; // file header + first chunk header
    constexpr std::uint32_t kJsonChunk = 0x4E4F534A;
    if (bytes.size() < kHeaderBytes)
        fail("header", "file has ", bytes.size(), " bytes, a GLB needs at least ", kHeaderBytes);
    if (std::memcmp(bytes.data(), "glTF", 4) != 0) fail("header.magic", "not 'glTF'");
    const std::uint32_t version = load<std::uint32_t>(&bytes[4]);
    const std::uint32_t length = load<std::uint32_t>(&bytes[8]);
    const std::uint32_t jsonLength = load<std::uint32_t>(&bytes[12]);
    if (version != 2) fail("header.version", version, ", expected 2");
    if (length != bytes.size())
        fail("header.length", length, " bytes declared, the file has ", bytes.size());
    if (load<std::uint32_t>(&bytes[16]) != kJsonChunk)
        fail("chunks[0].chunkType", "the first chunk is not JSON");
    if (jsonLength == 0 || jsonLength > bytes.size() - kHeaderBytes)
        fail("chunks[0].chunkLength", jsonLength, " bytes do not fit in the file");
    return {reinterpret_cast<const char*>(&bytes[kHeaderBytes]), jsonLength};
}

void GltfReader::checkUris(std::string_view json) {
    nlohmann::json document;
    try {
        document = nlohmann::json::parse(json.begin(), json.end());
    } catch (const nlohmann::json::exception& e) {
        std::string what = e.what();
        // Drop nlohmann's "[json.exception.parse_error.101] " prefix: it means nothing to users.
        if (const auto end = what.find("] "); what.starts_with("[json.") && end != what.npos)
            what.erase(0, end + 2);
        fail("JSON", oneLine(std::move(what)));
    }
    if (!document.is_object()) fail("JSON", "the top level is not an object");
    checkTypes(document);
    findUsedImages(document);
    for (const auto& [section, isBuffer] :
         {std::pair{"buffers", true}, std::pair{"images", false}}) {
        const auto it = document.find(section);
        if (it == document.end() || !it->is_array()) continue;
        for (std::size_t i = 0; i < it->size(); ++i)
            checkUri((*it)[i], section, i, isBuffer);
    }
}

void GltfReader::reportSkippedImages() {
    for (const std::string& skipped : mImages.skipped)
        logWarning(mLabel, ": ", skipped);
    mImages.skipped.clear();
}

void GltfReader::findUsedImages(const nlohmann::json& document) {
    const auto images = document.find("images");
    mImages.used.assign(images != document.end() ? images->size() : 0, false);
    const auto textures = document.find("textures");
    const auto materials = document.find("materials");
    if (textures == document.end() || materials == document.end()) return;
    for (const auto& material : *materials) {
        const auto pbr = material.find("pbrMetallicRoughness");
        if (pbr == material.end()) continue;
        const auto texture = pbr->find("baseColorTexture");
        if (texture == pbr->end() || !texture->contains("index")) continue;
        const std::size_t t = (*texture)["index"].get<std::size_t>();
        if (t >= textures->size() || !(*textures)[t].contains("source")) continue;
        const std::size_t source = (*textures)[t]["source"].get<std::size_t>();
        if (source < mImages.used.size()) mImages.used[source] = true;
    }
}

void GltfReader::checkTypes(const nlohmann::json& document) const {
    using Json = nlohmann::json;
    enum class Kind { Index, Number, String, Bool, Object };
    // An index, count, offset or size: a whole number >= 0 that fits tinygltf's int.
    const auto check = [&](const Json& value, const std::string& field, Kind kind) {
        switch (kind) {
        case Kind::Index:
            if (!value.is_number_unsigned() ||
                value.get<std::uint64_t>() > std::uint64_t(std::numeric_limits<int>::max()))
                fail(field, value.dump(), " is not a whole number from 0 to 2^31 - 1");
            return;
        case Kind::Number:
            if (!value.is_number() || !std::isfinite(value.get<double>()))
                fail(field, value.dump(), " is not a finite number");
            return;
        case Kind::String:
            if (!value.is_string()) fail(field, value.dump(), " is not a string");
            return;
        case Kind::Bool:
            if (!value.is_boolean()) fail(field, value.dump(), " is not true or false");
            return;
        case Kind::Object:
            if (!value.is_object()) fail(field, "is not an object");
            return;
        }
    };
    const auto join = [](const std::string& path, const char* name) {
        return path.empty() ? std::string(name) : path + "." + name;
    };
    // Optional members of `object` (itself at `path`), each of one kind.
    const auto members = [&](const Json& object, const std::string& path,
                             std::initializer_list<std::pair<const char*, Kind>> list) {
        for (const auto& [name, kind] : list)
            if (const auto it = object.find(name); it != object.end())
                check(*it, join(path, name), kind);
    };
    const auto array = [&](const Json& object, const std::string& path, const char* name, Kind kind,
                           std::size_t size = 0) {
        const auto it = object.find(name);
        if (it == object.end()) return;
        const std::string field = join(path, name);
        if (!it->is_array()) fail(field, "is not an array");
        if (size != 0 && it->size() != size) fail(field, it->size(), " values; needs ", size);
        for (std::size_t i = 0; i < it->size(); ++i)
            check((*it)[i], str(field, "[", i, "]"), kind);
    };
    // Each element of a top-level array (or of `object`'s member) that must be an object.
    const auto each = [&](const Json& object, const std::string& path, const char* name,
                          const auto& fn) {
        const auto it = object.find(name);
        if (it == object.end()) return;
        const std::string field = join(path, name);
        if (!it->is_array()) fail(field, "is not an array");
        for (std::size_t i = 0; i < it->size(); ++i) {
            const std::string element = str(field, "[", i, "]");
            check((*it)[i], element, Kind::Object);
            fn((*it)[i], element);
        }
    };
    const auto child = [&](const Json& object, const std::string& path, const char* name,
                           const auto& fn) {
        if (const auto it = object.find(name); it != object.end()) {
            check(*it, join(path, name), Kind::Object);
            fn(*it, join(path, name));
        }
    };

    if (const auto it = document.find("asset"); it != document.end()) {
        check(*it, "asset", Kind::Object);
        members(*it, "asset", {{"version", Kind::String}, {"minVersion", Kind::String}});
        if (const auto min = it->find("minVersion");
            min != it->end() && min->get_ref<const std::string&>() != "2.0")
            fail("asset.minVersion", "'", min->get<std::string>(), "': this reader is glTF 2.0");
    }
    members(document, "", {{"scene", Kind::Index}});
    each(document, "", "scenes",
         [&](const Json& o, const std::string& at) { array(o, at, "nodes", Kind::Index); });
    each(document, "", "nodes", [&](const Json& o, const std::string& at) {
        members(o, at,
                {{"camera", Kind::Index},
                 {"mesh", Kind::Index},
                 {"skin", Kind::Index},
                 {"name", Kind::String}});
        array(o, at, "children", Kind::Index);
        array(o, at, "translation", Kind::Number, 3);
        array(o, at, "rotation", Kind::Number, 4);
        array(o, at, "scale", Kind::Number, 3);
        array(o, at, "matrix", Kind::Number, 16);
        child(o, at, "extensions", [&](const Json& e, const std::string& ext) {
            child(e, ext, kLightsExtension.data(), [&](const Json& l, const std::string& light) {
                members(l, light, {{"light", Kind::Index}});
            });
        });
    });
    each(document, "", "meshes", [&](const Json& o, const std::string& at) {
        each(o, at, "primitives", [&](const Json& p, const std::string& primitive) {
            members(p, primitive,
                    {{"indices", Kind::Index}, {"material", Kind::Index}, {"mode", Kind::Index}});
            child(p, primitive, "attributes", [&](const Json& a, const std::string& attributes) {
                for (const auto& [name, value] : a.items())
                    check(value, attributes + "." + name, Kind::Index);
            });
        });
    });
    each(document, "", "accessors", [&](const Json& o, const std::string& at) {
        members(o, at,
                {{"bufferView", Kind::Index},
                 {"byteOffset", Kind::Index},
                 {"componentType", Kind::Index},
                 {"count", Kind::Index},
                 {"type", Kind::String},
                 {"normalized", Kind::Bool}});
        array(o, at, "min", Kind::Number);
        array(o, at, "max", Kind::Number);
    });
    each(document, "", "bufferViews", [&](const Json& o, const std::string& at) {
        members(o, at,
                {{"buffer", Kind::Index},
                 {"byteOffset", Kind::Index},
                 {"byteLength", Kind::Index},
                 {"byteStride", Kind::Index},
                 {"target", Kind::Index}});
    });
    each(document, "", "buffers", [&](const Json& o, const std::string& at) {
        members(o, at, {{"byteLength", Kind::Index}, {"uri", Kind::String}});
    });
    each(document, "", "images", [&](const Json& o, const std::string& at) {
        members(o, at,
                {{"uri", Kind::String}, {"bufferView", Kind::Index}, {"mimeType", Kind::String}});
    });
    each(document, "", "textures", [&](const Json& o, const std::string& at) {
        members(o, at, {{"source", Kind::Index}, {"sampler", Kind::Index}});
    });
    each(document, "", "materials", [&](const Json& o, const std::string& at) {
        members(o, at,
                {{"alphaCutoff", Kind::Number},
                 {"doubleSided", Kind::Bool},
                 {"alphaMode", Kind::String}});
        array(o, at, "emissiveFactor", Kind::Number, 3);
        child(o, at, "pbrMetallicRoughness", [&](const Json& p, const std::string& pbr) {
            array(p, pbr, "baseColorFactor", Kind::Number, 4);
            members(p, pbr, {{"metallicFactor", Kind::Number}, {"roughnessFactor", Kind::Number}});
            child(p, pbr, "baseColorTexture", [&](const Json& t, const std::string& texture) {
                members(t, texture, {{"index", Kind::Index}, {"texCoord", Kind::Index}});
            });
        });
        child(o, at, "extensions", [&](const Json& e, const std::string& ext) {
            child(e, ext, kEmissiveStrengthExtension.data(),
                  [&](const Json& x, const std::string& strength) {
                      members(x, strength, {{"emissiveStrength", Kind::Number}});
                  });
        });
    });
    each(document, "", "cameras", [&](const Json& o, const std::string& at) {
        members(o, at, {{"type", Kind::String}});
        child(o, at, "perspective", [&](const Json& p, const std::string& perspective) {
            members(p, perspective,
                    {{"yfov", Kind::Number},
                     {"znear", Kind::Number},
                     {"zfar", Kind::Number},
                     {"aspectRatio", Kind::Number}});
        });
    });
    child(document, "", "extensions", [&](const Json& e, const std::string& ext) {
        child(e, ext, kLightsExtension.data(), [&](const Json& x, const std::string& lights) {
            each(x, lights, "lights", [&](const Json& l, const std::string& light) {
                members(
                    l, light,
                    {{"type", Kind::String}, {"intensity", Kind::Number}, {"range", Kind::Number}});
                array(l, light, "color", Kind::Number, 3);
                child(l, light, "spot", [&](const Json& sp, const std::string& spot) {
                    members(sp, spot,
                            {{"innerConeAngle", Kind::Number}, {"outerConeAngle", Kind::Number}});
                });
            });
        });
    });
}

void GltfReader::checkUri(const nlohmann::json& object, const std::string& section,
                          std::size_t index, bool isBuffer) const {
    if (!object.is_object() || !object.contains("uri") || !object["uri"].is_string()) return;
    const std::string& uri = object["uri"].get_ref<const std::string&>();
    const std::string field = str(section, "[", index, "].uri");
    const std::string lengthField = str(section, "[", index, "].byteLength");
    const nlohmann::json* byteLength =
        isBuffer && object.contains("byteLength") && object["byteLength"].is_number_unsigned()
            ? &object["byteLength"]
            : nullptr;

    if (uri.starts_with("data:")) {
        // Only the media types tinygltf decodes; any other "data:" would be opened as a file.
        static constexpr std::string_view kBufferTypes[] = {"data:application/octet-stream;base64,",
                                                            "data:application/gltf-buffer;base64,"};
        static constexpr std::string_view kImageTypes[] = {"data:image/png;base64,",
                                                           "data:image/jpeg;base64,"};
        const auto& types = isBuffer ? kBufferTypes : kImageTypes;
        const auto header = std::find_if(std::begin(types), std::end(types),
                                         [&](std::string_view t) { return uri.starts_with(t); });
        if (header == std::end(types))
            fail(field, "data URI is not ",
                 isBuffer ? "application/octet-stream or application/gltf-buffer"
                          : "image/png or image/jpeg",
                 " in base64");
        const Base64Check base64 = checkBase64(std::string_view(uri).substr(header->size()));
        if (base64.badAt != std::string_view::npos)
            fail(field, "invalid base64 at character ", header->size() + base64.badAt);
        if (byteLength && base64.bytes != byteLength->get<std::uint64_t>())
            fail(lengthField, byteLength->get<std::uint64_t>(), " but the data URI holds ",
                 base64.bytes, " bytes");
        return;
    }
    const fs::path file = resolveUri(field, uri);
    std::error_code error;
    if (!fs::is_regular_file(file, error)) fail(field, "'", uri, "' not found next to the scene");
    const std::uintmax_t size = fs::file_size(file, error);
    if (error) fail(field, "cannot read '", uri, "': ", error.message());
    if (size > kGltfMaxFileBytes)
        fail(field, "'", uri, "' has ", size, " bytes, more than the limit of ", kGltfMaxFileBytes);
    if (byteLength && size != byteLength->get<std::uint64_t>())
        fail(lengthField, byteLength->get<std::uint64_t>(), " but '", uri, "' has ", size,
             " bytes");
}

fs::path GltfReader::resolveUri(const std::string& field, const std::string& uri) const {
    // Decode exactly as tinygltf will ('+' is a space, %XX a byte), so the file checked here
    // is the file it opens.
    std::string path;
    for (std::size_t i = 0; i < uri.size(); ++i) {
        if (uri[i] == '+') {
            path += ' ';
        } else if (uri[i] == '%') {
            if (i + 2 >= uri.size() || !std::isxdigit(static_cast<unsigned char>(uri[i + 1])) ||
                !std::isxdigit(static_cast<unsigned char>(uri[i + 2])))
                fail(field, "malformed percent escape in '", uri, "'");
            path += char(std::stoi(uri.substr(i + 1, 2), nullptr, 16));
            i += 2;
        } else {
            path += uri[i];
        }
    }
    if (path.empty()) fail(field, "empty");
    if (path.find('\0') != path.npos) fail(field, "'", uri, "' contains a NUL byte");
    if (path.front() == '/' || path.front() == '\\')
        fail(field, "'", uri, "' is absolute; only paths relative to the scene are allowed");
    if (const auto colon = path.find(':'); colon != path.npos && colon < path.find_first_of("/\\"))
        fail(field, "'", uri, "' has a scheme or drive; only relative paths and data: URIs");
    for (std::size_t begin = 0; begin <= path.size();) {
        const std::size_t end = std::min(path.find_first_of("/\\", begin), path.size());
        if (std::string_view(path).substr(begin, end - begin) == "..")
            fail(field, "'", uri, "' leaves the scene's folder");
        begin = end + 1;
    }
    return mFolder / path;
}

void GltfReader::loadModel(const std::vector<unsigned char>& bytes, std::string_view json,
                           bool glb) {
    tinygltf::TinyGLTF loader;
    loader.SetImageLoader(&decodeImageCallback, &mImages);
    std::string error, warning;
    bool ok = false;
    try {
        const std::string folder = mFolder.string();
        ok = glb ? loader.LoadBinaryFromMemory(&mModel, &error, &warning, bytes.data(),
                                               unsigned(bytes.size()), folder)
                 : loader.LoadASCIIFromString(&mModel, &error, &warning, json.data(),
                                              unsigned(json.size()), folder);
    } catch (const std::exception& e) { // tinygltf indexes with .at() on some bad input
        error = e.what();
    }
    if (!mImages.field.empty()) fail(mImages.field, mImages.what);
    reportSkippedImages();
    // tinygltf reports some malformed values (a string where a number belongs, a colour of the
    // wrong length) in `error` and still returns success, with a default in their place.
    if (!ok || !error.empty()) fail("glTF", oneLine(error.empty() ? "load failed" : error));
    if (!warning.empty()) logWarning(mLabel, ": ", oneLine(warning));
}

void GltfReader::checkAsset() const {
    if (!mModel.asset.version.starts_with("2."))
        fail("asset.version", "'", mModel.asset.version, "' is not glTF 2.x");
    for (std::size_t i = 0; i < mModel.extensionsRequired.size(); ++i) {
        const std::string& name = mModel.extensionsRequired[i];
        if (name != kLightsExtension && name != kEmissiveStrengthExtension)
            fail(str("extensionsRequired[", i, "]"), "'", name, "' is not supported");
    }
}

void GltfReader::checkBufferViews() const {
    for (std::size_t i = 0; i < mModel.bufferViews.size(); ++i) {
        const tinygltf::BufferView& view = mModel.bufferViews[i];
        const std::string field = str("bufferViews[", i, "]");
        checkIndex(field + ".buffer", view.buffer, mModel.buffers.size(), "buffers");
        const std::size_t size = mModel.buffers[std::size_t(view.buffer)].data.size();
        if (view.byteLength == 0) fail(field + ".byteLength", "0; must be at least 1");
        if (view.byteOffset > size || view.byteLength > size - view.byteOffset)
            fail(field + ".byteLength", "byteOffset ", view.byteOffset, " + byteLength ",
                 view.byteLength, " run past the end of buffer ", view.buffer, " (", size,
                 " bytes)");
        if (view.byteStride != 0 &&
            (view.byteStride < 4 || view.byteStride > 252 || view.byteStride % 4 != 0))
            fail(field + ".byteStride", view.byteStride, " is not a multiple of 4 in [4, 252]");
    }
}

void GltfReader::checkAccessors() const {
    for (std::size_t i = 0; i < mModel.accessors.size(); ++i) {
        const tinygltf::Accessor& a = mModel.accessors[i];
        const std::string field = str("accessors[", i, "]");
        if (componentBytes(a.componentType) == 0)
            fail(field + ".componentType", a.componentType, " (", componentName(a.componentType),
                 ") is not a glTF 2.0 accessor component type");
        if (a.count == 0) fail(field + ".count", "0; must be at least 1");
        if (a.bufferView < 0) continue; // no data: rejected where it would be read
        checkIndex(field + ".bufferView", a.bufferView, mModel.bufferViews.size(), "buffer views");
        const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(a.bufferView)];
        const std::size_t element = elementBytes(a.componentType, a.type);
        const std::size_t stride = view.byteStride != 0 ? view.byteStride : element;
        if (stride < element)
            fail(str("bufferViews[", a.bufferView, "].byteStride"), stride, " is smaller than the ",
                 element, "-byte elements of ", field);
        const std::size_t length = view.byteLength;
        // byteOffset + stride * (count - 1) + element <= length, without overflow.
        if (a.byteOffset > length || element > length - a.byteOffset ||
            a.count - 1 > (length - a.byteOffset - element) / stride)
            fail(field + ".count", a.count, " elements of ", element, " bytes (stride ", stride,
                 ") from byteOffset ", a.byteOffset, " do not fit in buffer view ", a.bufferView,
                 " (", length, " bytes)");
    }
}

TextureLibrary GltfReader::decodeImages() {
    TextureLibrary library;
    for (std::size_t i = 0; i < mModel.images.size(); ++i) {
        tinygltf::Image& image = mModel.images[i];
        const std::string field = str("images[", i, "]");
        if (image.bufferView >= 0) {
            checkIndex(field + ".bufferView", image.bufferView, mModel.bufferViews.size(),
                       "buffer views");
            const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(image.bufferView)];
            const auto& data = mModel.buffers[std::size_t(view.buffer)].data;
            const std::string what = decodeRgba8(&data[view.byteOffset], view.byteLength, image);
            if (!what.empty() && !skipUnusedImage(mImages, int(i), what, image)) fail(field, what);
        }
        if (image.image.empty()) fail(field, "no pixel data");
        reportSkippedImages();
        library.images.push_back(Image{image.name.empty() ? image.uri : image.name, image.width,
                                       image.height, std::move(image.image), true});
    }
    return library;
}

AccessorData GltfReader::useAccessor(const std::string& usage, int index, int type,
                                     std::initializer_list<int> componentTypes) const {
    checkIndex(usage, index, mModel.accessors.size(), "accessors");
    const tinygltf::Accessor& a = mModel.accessors[std::size_t(index)];
    const std::string field = str("accessors[", index, "]");
    if (a.type != type)
        fail(field + ".type", typeName(a.type), " but ", usage, " needs ", typeName(type));
    if (std::find(componentTypes.begin(), componentTypes.end(), a.componentType) ==
        componentTypes.end())
        fail(field + ".componentType", componentName(a.componentType), " is not allowed for ",
             usage);
    const std::size_t element = elementBytes(a.componentType, a.type);
    if (!a.sparse.isSparse && a.bufferView >= 0) {
        const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(a.bufferView)];
        return {mModel.buffers[std::size_t(view.buffer)].data.data() + view.byteOffset +
                    a.byteOffset,
                view.byteStride != 0 ? view.byteStride : element, a.count, a.componentType};
    }
    // Without a buffer view the elements are zeros; a sparse accessor then replaces some of
    // them (glTF 2.0 section 3.6.2.3). Both are laid out tightly in memory kept for the read.
    if (a.count > kGltfMaxFileBytes / element)
        fail(field + ".count", a.count, " elements of ", element,
             " bytes would take more than a file may hold (", kGltfMaxFileBytes, " bytes)");
    std::vector<unsigned char>& dense = mDenseAccessors.emplace_back(a.count * element, 0);
    if (a.bufferView >= 0) {
        const AccessorData base = rawView(index, element);
        for (std::size_t i = 0; i < a.count; ++i)
            std::copy_n(base.data + i * base.stride, element, dense.data() + i * element);
    }
    if (a.sparse.isSparse) applySparse(index, element, dense);
    return {dense.data(), element, a.count, a.componentType};
}

AccessorData GltfReader::rawView(int index, std::size_t element) const {
    const tinygltf::Accessor& a = mModel.accessors[std::size_t(index)];
    const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(a.bufferView)];
    return {mModel.buffers[std::size_t(view.buffer)].data.data() + view.byteOffset + a.byteOffset,
            view.byteStride != 0 ? view.byteStride : element, a.count, a.componentType};
}

void GltfReader::applySparse(int index, std::size_t element,
                             std::vector<unsigned char>& dense) const {
    const tinygltf::Accessor& a = mModel.accessors[std::size_t(index)];
    const std::string field = str("accessors[", index, "].sparse");
    const auto& sparse = a.sparse;
    if (sparse.count < 1 || std::size_t(sparse.count) > a.count)
        fail(field + ".count", sparse.count, " is not in [1, ", a.count, "]");
    const std::size_t count = std::size_t(sparse.count);
    // A view holding `count` tightly packed items of `bytes` each from `offset`, or a failure.
    const auto block = [&](const std::string& where, int viewIndex, int offset,
                           std::size_t bytes) -> const unsigned char* {
        checkIndex(where + ".bufferView", viewIndex, mModel.bufferViews.size(), "buffer views");
        const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(viewIndex)];
        if (offset < 0 || std::size_t(offset) > view.byteLength ||
            count > (view.byteLength - std::size_t(offset)) / bytes)
            fail(where + ".byteOffset", count, " items of ", bytes, " bytes from ", offset,
                 " do not fit in buffer view ", viewIndex, " (", view.byteLength, " bytes)");
        return mModel.buffers[std::size_t(view.buffer)].data.data() + view.byteOffset +
               std::size_t(offset);
    };
    const int indexType = sparse.indices.componentType;
    if (indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        fail(field + ".indices.componentType", componentName(indexType),
             " is not an unsigned integer type");
    const std::size_t indexBytes = componentBytes(indexType);
    const unsigned char* indices =
        block(field + ".indices", sparse.indices.bufferView, sparse.indices.byteOffset, indexBytes);
    const unsigned char* values =
        block(field + ".values", sparse.values.bufferView, sparse.values.byteOffset, element);
    std::size_t previous = 0;
    for (std::size_t i = 0; i < count; ++i) {
        const unsigned char* p = indices + i * indexBytes;
        const std::size_t target = indexBytes == 1   ? p[0]
                                   : indexBytes == 2 ? load<std::uint16_t>(p)
                                                     : load<std::uint32_t>(p);
        if (target >= a.count || (i > 0 && target <= previous))
            fail(field + ".indices", "element ", i, " is ", target,
                 ": indices must increase and stay below the count ", a.count);
        previous = target;
        std::copy_n(values + i * element, element, dense.data() + target * element);
    }
}

std::vector<glm::vec3> GltfReader::readVec3(const std::string& usage, int index) const {
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_VEC3, {TINYGLTF_COMPONENT_TYPE_FLOAT});
    std::vector<glm::vec3> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        out[i] = {load<float>(p), load<float>(p + 4), load<float>(p + 8)};
        if (!isFinite(out[i])) fail(usage, "element ", i, " is not finite");
    }
    return out;
}

std::vector<glm::vec2> GltfReader::readTexcoords(const std::string& usage, int index) const {
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_VEC2,
                    {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT});
    if (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT &&
        !mModel.accessors[std::size_t(index)].normalized)
        fail(str("accessors[", index, "].normalized"), usage, " stored as ",
             componentName(a.componentType), " must be normalized");
    std::vector<glm::vec2> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
            out[i] = {load<float>(p), load<float>(p + 4)};
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            out[i] = glm::vec2(float(p[0]), float(p[1])) / 255.f;
            break;
        default:
            out[i] = glm::vec2(float(load<std::uint16_t>(p)), float(load<std::uint16_t>(p + 2))) /
                     65535.f;
        }
        if (!std::isfinite(out[i].x) || !std::isfinite(out[i].y))
            fail(usage, "element ", i, " is not finite");
    }
    return out;
}

std::vector<std::uint32_t> GltfReader::readIndices(const std::string& usage, int index,
                                                   std::size_t vertexCount) const {
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_SCALAR,
                    {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT});
    std::vector<std::uint32_t> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            out[i] = p[0];
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            out[i] = load<std::uint16_t>(p);
            break;
        default:
            out[i] = load<std::uint32_t>(p);
        }
        if (out[i] >= vertexCount)
            fail(usage, "element ", i, " is ", out[i], ", not below the vertex count ",
                 vertexCount);
    }
    return out;
}

std::vector<RawPrimitive> GltfReader::readMesh(int meshIndex) const {
    const tinygltf::Mesh& mesh = mModel.meshes[std::size_t(meshIndex)];
    std::vector<RawPrimitive> primitives;
    for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
        const tinygltf::Primitive& primitive = mesh.primitives[p];
        RawPrimitive raw;
        raw.field = str("meshes[", meshIndex, "].primitives[", p, "]");
        const int mode = primitive.mode < 0 ? TINYGLTF_MODE_TRIANGLES : primitive.mode;
        if (mode == TINYGLTF_MODE_POINTS || mode == TINYGLTF_MODE_LINE ||
            mode == TINYGLTF_MODE_LINE_LOOP || mode == TINYGLTF_MODE_LINE_STRIP) {
            logWarning(mLabel, ": ", raw.field, ".mode: ", modeName(mode),
                       " has no surface to light; skipped");
            continue;
        }
        if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
            mode != TINYGLTF_MODE_TRIANGLE_FAN)
            fail(raw.field + ".mode", mode, " is not a glTF 2.0 primitive mode");
        const auto attribute = [&](const char* name) {
            const auto it = primitive.attributes.find(name);
            return it == primitive.attributes.end() ? -1 : it->second;
        };
        const std::string attributes = raw.field + ".attributes.";
        const int position = attribute("POSITION");
        if (position < 0) { // allowed by glTF, but nothing to draw or light
            logWarning(mLabel, ": ", attributes, "POSITION: missing; the primitive is skipped");
            continue;
        }
        if (attribute("COLOR_0") >= 0)
            logWarning(mLabel, ": ", attributes,
                       "COLOR_0: vertex colours are not imported (baseColorFactor is the albedo)");
        raw.mesh.positions = readVec3(attributes + "POSITION", position);
        const std::size_t count = raw.mesh.positions.size();
        const auto checkCount = [&](const std::string& field, std::size_t n) {
            if (n != count) fail(field, n, " elements but POSITION has ", count);
        };
        if (const int normal = attribute("NORMAL"); normal >= 0) {
            raw.mesh.normals = readVec3(attributes + "NORMAL", normal);
            checkCount(attributes + "NORMAL", raw.mesh.normals.size());
        }
        if (const int uv = attribute("TEXCOORD_0"); uv >= 0) {
            raw.mesh.uvs = readTexcoords(attributes + "TEXCOORD_0", uv);
            checkCount(attributes + "TEXCOORD_0", raw.mesh.uvs.size());
        }
        std::vector<std::uint32_t> order;
        if (primitive.indices >= 0) {
            order = readIndices(raw.field + ".indices", primitive.indices, count);
        } else {
            order.resize(count);
            for (std::size_t i = 0; i < count; ++i)
                order[i] = std::uint32_t(i);
        }
        const std::string orderField =
            primitive.indices >= 0 ? raw.field + ".indices" : attributes + "POSITION";
        if (mode == TINYGLTF_MODE_TRIANGLES) {
            if (order.size() % 3 != 0)
                fail(orderField, order.size(), " vertices is not a multiple of 3");
            raw.mesh.indices = std::move(order);
        } else { // a strip or a fan, as a list (glTF 2.0 section 3.7.2.1)
            for (std::size_t i = 0; i + 2 < order.size(); ++i) {
                if (mode == TINYGLTF_MODE_TRIANGLE_STRIP)
                    raw.mesh.indices.insert(raw.mesh.indices.end(),
                                            {order[i], order[i + 1 + i % 2], order[i + 2 - i % 2]});
                else
                    raw.mesh.indices.insert(raw.mesh.indices.end(),
                                            {order[i + 1], order[i + 2], order[0]});
            }
        }
        if (primitive.material != -1)
            checkIndex(raw.field + ".material", primitive.material, mModel.materials.size(),
                       "materials");
        raw.material = primitive.material;
        if (!primitive.targets.empty())
            logWarning(mLabel, ": ", raw.field, ".targets: morph targets are ignored");
        primitives.push_back(std::move(raw));
    }
    return primitives;
}

Material GltfReader::readMaterial(int index) const {
    const tinygltf::Material& m = mModel.materials[std::size_t(index)];
    const std::string field = str("materials[", index, "]");
    const std::string pbr = field + ".pbrMetallicRoughness";
    const auto unit = [&](const std::string& name, double value) {
        if (!(value >= 0.0 && value <= 1.0)) fail(name, value, " is outside [0, 1]");
        return float(value);
    };
    const auto color = [&](const std::string& name, const std::vector<double>& values,
                           std::size_t size) {
        if (values.size() != size) fail(name, values.size(), " numbers; needs ", size);
        glm::vec3 c;
        for (int i = 0; i < 3; ++i)
            c[i] = unit(str(name, "[", i, "]"), values[std::size_t(i)]);
        return c;
    };

    if (m.alphaMode == "MASK" || m.alphaMode == "BLEND")
        logWarning(mLabel, ": ", field, ".alphaMode: ", m.alphaMode,
                   " is drawn and lit as OPAQUE (cut-outs block light)");
    if (m.pbrMetallicRoughness.baseColorTexture.extensions.count("KHR_texture_transform"))
        logWarning(mLabel, ": ", pbr, ".baseColorTexture: KHR_texture_transform is ignored");
    Material material;
    material.baseColor = color(pbr + ".baseColorFactor", m.pbrMetallicRoughness.baseColorFactor, 4);
    unit(pbr + ".baseColorFactor[3]", m.pbrMetallicRoughness.baseColorFactor[3]); // alpha
    material.metallic = unit(pbr + ".metallicFactor", m.pbrMetallicRoughness.metallicFactor);
    material.roughness = unit(pbr + ".roughnessFactor", m.pbrMetallicRoughness.roughnessFactor);
    if (!m.emissiveFactor.empty())
        material.emission = color(field + ".emissiveFactor", m.emissiveFactor, 3);
    if (const auto it = m.extensions.find(std::string(kEmissiveStrengthExtension));
        it != m.extensions.end() && it->second.Has("emissiveStrength")) {
        const std::string name =
            str(field, ".extensions.", kEmissiveStrengthExtension, ".emissiveStrength");
        const tinygltf::Value& strength = it->second.Get("emissiveStrength");
        const double value = strength.IsNumber() ? strength.GetNumberAsDouble() : -1.0;
        if (!(value >= 0.0 && value <= kMaxRadiometricValue))
            fail(name, value, " is not a number from 0 to ", kMaxRadiometricValue);
        material.emission *= float(value);
    }
    const tinygltf::TextureInfo& texture = m.pbrMetallicRoughness.baseColorTexture;
    if (texture.index != -1) {
        checkIndex(pbr + ".baseColorTexture.index", texture.index, mModel.textures.size(),
                   "textures");
        const int source = mModel.textures[std::size_t(texture.index)].source;
        if (source == -1) { // allowed (an extension may name the image): no texture here
            logWarning(mLabel, ": textures[", texture.index,
                       "].source: missing; the material is drawn untextured");
            return material;
        }
        checkIndex(str("textures[", texture.index, "].source"), source, mModel.images.size(),
                   "images");
        if (texture.texCoord != 0)
            logWarning(mLabel, ": ", pbr, ".baseColorTexture.texCoord: set ", texture.texCoord,
                       " is not imported; TEXCOORD_0 is used");
        material.baseColorTexture = source;
    }
    return material;
}

std::optional<Camera> GltfReader::readCamera(int index) const {
    const tinygltf::Camera& c = mModel.cameras[std::size_t(index)];
    const std::string field = str("cameras[", index, "]");
    if (c.type == "orthographic") {
        logWarning(mLabel, ": ", field, ": orthographic cameras are not supported; skipped");
        return std::nullopt;
    }
    if (c.type != "perspective")
        fail(field + ".type", "'", c.type, "' is not perspective or orthographic");
    const tinygltf::PerspectiveCamera& p = c.perspective;
    if (!(p.yfov > 0.0 && p.yfov < std::numbers::pi))
        fail(field + ".perspective.yfov", p.yfov, " is not in (0, pi)");
    if (!(p.znear > 0.0 && p.znear < 1e30))
        fail(field + ".perspective.znear", p.znear, " is not > 0");
    if (p.zfar != 0.0 && !(p.zfar > p.znear && p.zfar < 1e30))
        fail(field + ".perspective.zfar", p.zfar, " is not beyond znear ", p.znear);
    // Valid glTF, but past what float projection and depth resolve (a black frame): within
    // 0.002 rad of a half turn, nearer than a micrometre, or a depth range under 0.1%.
    Camera camera;
    camera.yfov = float(std::clamp(p.yfov, 1e-3, std::numbers::pi - 2e-3));
    camera.znear = float(std::max(p.znear, 1e-6));
    if (p.zfar != 0.0)
        camera.zfar = std::max(float(p.zfar), 1.001f * camera.znear);
    else if (camera.zfar < 1.001f * camera.znear) // absent (infinite): the component's
        camera.zfar = 1e4f * camera.znear;        // default, unless znear is beyond it
    if (camera.yfov != float(p.yfov) || camera.znear != float(p.znear) ||
        (p.zfar != 0.0 && camera.zfar != float(p.zfar)))
        logWarning(mLabel, ": ", field, ".perspective: adjusted to yfov ", camera.yfov, ", znear ",
                   camera.znear, ", zfar ", camera.zfar, " (what float depth can resolve)");
    return camera;
}

Light GltfReader::readLight(int index) const {
    const tinygltf::Light& l = mModel.lights[std::size_t(index)];
    const std::string field = str("extensions.", kLightsExtension, ".lights[", index, "]");
    glm::vec3 color(1.f);
    if (!l.color.empty()) {
        if (l.color.size() != 3) fail(field + ".color", l.color.size(), " numbers; needs 3");
        for (int i = 0; i < 3; ++i) {
            const double c = l.color[std::size_t(i)];
            if (!(c >= 0.0 && c <= 1.0))
                fail(str(field, ".color[", i, "]"), c, " is outside [0, 1]");
            color[i] = float(c);
        }
    }
    if (!(l.intensity >= 0.0 && l.intensity <= kMaxRadiometricValue))
        fail(field + ".intensity", l.intensity, " is not a number from 0 to ", kMaxRadiometricValue,
             " (W/sr, or W/m^2 for a directional light)");
    const float intensity = float(l.intensity);
    if (l.type == "point") return PointLight{color, intensity};
    if (l.type == "directional") return DirectionalLight{color, intensity};
    if (l.type != "spot") fail(field + ".type", "'", l.type, "' is not point, spot or directional");
    const double inner = l.spot.innerConeAngle;
    const double outer = l.spot.outerConeAngle;
    if (!(outer > 0.0 && outer <= std::numbers::pi / 2))
        fail(field + ".spot.outerConeAngle", outer, " is not in (0, pi/2]");
    if (!(inner >= 0.0 && inner < outer))
        fail(field + ".spot.innerConeAngle", inner, " is not in [0, outerConeAngle)");
    return SpotLight{color, intensity, float(inner), float(outer)};
}

std::vector<int> GltfReader::checkNodeGraph() const {
    const std::size_t count = mModel.nodes.size();
    std::vector<int> parents(count, -1);
    for (std::size_t i = 0; i < count; ++i) {
        const auto& children = mModel.nodes[i].children;
        for (std::size_t j = 0; j < children.size(); ++j) {
            const std::string field = str("nodes[", i, "].children[", j, "]");
            const int child = children[j];
            checkIndex(field, child, count, "nodes");
            if (parents[std::size_t(child)] >= 0)
                fail(field, "node ", child, " already has parent node ",
                     parents[std::size_t(child)]);
            parents[std::size_t(child)] = int(i);
        }
    }
    // Every node must reach a root by following parents; depths come along on the way.
    constexpr int kUnknown = -1, kOnPath = -2;
    std::vector<int> depth(count, kUnknown);
    std::vector<int> path;
    for (std::size_t start = 0; start < count; ++start) {
        int node = int(start);
        while (node >= 0 && depth[std::size_t(node)] == kUnknown) {
            depth[std::size_t(node)] = kOnPath;
            path.push_back(node);
            node = parents[std::size_t(node)];
        }
        if (node >= 0 && depth[std::size_t(node)] == kOnPath)
            fail(str("nodes[", parents[std::size_t(node)], "].children"), "node ", node,
                 " is its own ancestor (a cycle)");
        int d = node < 0 ? 0 : depth[std::size_t(node)] + 1;
        for (auto it = path.rbegin(); it != path.rend(); ++it, ++d) {
            if (d >= kGltfMaxNodeDepth)
                fail(str("nodes[", *it, "]"), "hierarchy deeper than ", kGltfMaxNodeDepth,
                     " levels");
            depth[std::size_t(*it)] = d;
        }
        path.clear();
    }
    return parents;
}

std::vector<int> GltfReader::sceneRoots(const std::vector<int>& parents) const {
    std::vector<int> roots;
    if (mModel.scenes.empty()) { // no scene: every root node
        for (std::size_t i = 0; i < parents.size(); ++i)
            if (parents[i] < 0) roots.push_back(int(i));
        return roots;
    }
    if (mModel.defaultScene != -1)
        checkIndex("scene", mModel.defaultScene, mModel.scenes.size(), "scenes");
    const int scene = std::max(mModel.defaultScene, 0);
    const std::vector<int>& nodes = mModel.scenes[std::size_t(scene)].nodes;
    std::vector<bool> listed(parents.size(), false);
    for (std::size_t j = 0; j < nodes.size(); ++j) {
        const std::string field = str("scenes[", scene, "].nodes[", j, "]");
        checkIndex(field, nodes[j], parents.size(), "nodes");
        if (const int parent = parents[std::size_t(nodes[j])]; parent >= 0)
            fail(field, "node ", nodes[j], " is not a root (child of node ", parent, ")");
        if (listed[std::size_t(nodes[j])]) fail(field, "node ", nodes[j], " is listed twice");
        listed[std::size_t(nodes[j])] = true;
        roots.push_back(nodes[j]);
    }
    return roots;
}

Transform GltfReader::localTransform(int index) const {
    const tinygltf::Node& node = mModel.nodes[std::size_t(index)];
    const std::string field = str("nodes[", index, "]");
    const auto floats = [&](const std::string& name, const std::vector<double>& values,
                            std::size_t size) {
        if (values.size() != size) fail(name, values.size(), " numbers; needs ", size);
        std::vector<float> out(size);
        for (std::size_t i = 0; i < size; ++i) {
            out[i] = float(values[i]);
            if (!std::isfinite(out[i])) fail(name, "element ", i, " is not finite");
        }
        return out;
    };

    if (!node.matrix.empty()) {
        if (!node.translation.empty() || !node.rotation.empty() || !node.scale.empty())
            fail(field + ".matrix", "given together with translation, rotation or scale");
        const std::vector<float> m = floats(field + ".matrix", node.matrix, 16);
        glm::mat4 matrix; // both glTF and glm are column-major
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r)
                matrix[c][r] = m[std::size_t(c * 4 + r)];
        const std::optional<Transform> trs = decomposeTrs(matrix);
        if (!trs)
            fail(field + ".matrix",
                 "not a translation-rotation-scale matrix (shear, projection or zero scale)");
        return *trs;
    }
    Transform t;
    if (!node.translation.empty()) {
        const std::vector<float> v = floats(field + ".translation", node.translation, 3);
        t.translation = {v[0], v[1], v[2]};
    }
    if (!node.rotation.empty()) {
        const std::vector<float> q = floats(field + ".rotation", node.rotation, 4);
        const glm::quat rotation(q[3], q[0], q[1], q[2]); // glTF stores (x, y, z, w)
        const float length = glm::length(rotation);
        if (!(length > 0.5f && length < 2.f))
            fail(field + ".rotation", "length ", length, " is not a unit quaternion");
        t.rotation = rotation / length;
    }
    if (!node.scale.empty()) {
        const std::vector<float> s = floats(field + ".scale", node.scale, 3);
        t.scale = {s[0], s[1], s[2]};
    }
    return t;
}

bool GltfReader::nodeStandIn(int index) const {
    const tinygltf::Value& extras = mModel.nodes[std::size_t(index)].extras;
    if (!extras.IsObject() || !extras.Has("standIn")) return false;
    const tinygltf::Value& standIn = extras.Get("standIn");
    if (!standIn.IsBool()) fail(str("nodes[", index, "].extras.standIn"), "must be true or false");
    if (nodeLight(index) < 0)
        fail(str("nodes[", index, "].extras.standIn"), "set on a node without a light");
    return standIn.Get<bool>();
}

bool GltfReader::nodePointCache(int index) const {
    const tinygltf::Value& extras = mModel.nodes[std::size_t(index)].extras;
    if (!extras.IsObject() || !extras.Has("pointCache")) return false;
    const std::string field = str("nodes[", index, "].extras.pointCache");
    const tinygltf::Value& value = extras.Get("pointCache");
    if (!value.IsBool()) fail(field, "must be true or false");
    if (mModel.nodes[std::size_t(index)].mesh == -1) fail(field, "set on a node without a mesh");
    return value.Get<bool>();
}

std::optional<Mobility> GltfReader::nodeMobility(int index) const {
    const tinygltf::Value& extras = mModel.nodes[std::size_t(index)].extras;
    if (!extras.IsObject()) return std::nullopt;
    const std::string field = str("nodes[", index, "].extras");
    const bool hasAvatar = extras.Has("avatar");
    const bool hasMobility = extras.Has("mobility");
    if (hasAvatar && hasMobility) fail(field, "'avatar' and 'mobility' exclude each other");
    if (hasAvatar) {
        const tinygltf::Value& avatar = extras.Get("avatar");
        if (!avatar.IsBool()) fail(field + ".avatar", "must be true or false");
        return avatar.Get<bool>() ? std::optional(Mobility::Avatar) : std::nullopt;
    }
    if (!hasMobility) return std::nullopt;
    const tinygltf::Value& mobility = extras.Get("mobility");
    if (mobility.IsString() && mobility.Get<std::string>() == "static") return Mobility::Static;
    if (mobility.IsString() && mobility.Get<std::string>() == "mobile") return Mobility::Mobile;
    fail(field + ".mobility",
         mobility.IsString() ? str("'", mobility.Get<std::string>(), "'") : "a non-string",
         " is not \"static\" or \"mobile\"");
}

int GltfReader::nodeLight(int index) const {
    const tinygltf::Node& node = mModel.nodes[std::size_t(index)];
    const auto it = node.extensions.find(std::string(kLightsExtension));
    if (it == node.extensions.end()) return -1;
    const std::string field = str("nodes[", index, "].extensions.", kLightsExtension, ".light");
    if (!it->second.Has("light") || !it->second.Get("light").IsInt())
        fail(field, "missing or not an integer");
    const int light = it->second.Get("light").GetNumberAsInt();
    checkIndex(field, light, mModel.lights.size(), "lights");
    return light;
}

std::vector<EntityRecord> GltfReader::traverse(const std::vector<int>& roots) {
    std::vector<EntityRecord> records;
    mNodeRecord.assign(mModel.nodes.size(), -1);
    int activeCameraIndex = std::numeric_limits<int>::max();
    std::size_t activeRecord = 0;
    // Depth first, parents before children, children in file order: (node, parent record).
    std::vector<std::pair<int, int>> stack;
    for (auto it = roots.rbegin(); it != roots.rend(); ++it)
        stack.emplace_back(*it, -1);
    while (!stack.empty()) {
        const auto [index, parent] = stack.back();
        stack.pop_back();
        const tinygltf::Node& node = mModel.nodes[std::size_t(index)];
        const std::string field = str("nodes[", index, "]");
        const int self = int(records.size());
        mNodeRecord[std::size_t(index)] = self;
        bool hidden = false; // a mesh node scaled to nothing
        {
            EntityRecord record;
            record.name = node.name.empty() ? field : node.name;
            record.transform = localTransform(index);
            record.parent = parent;
            const glm::mat4 parentWorld =
                parent >= 0 ? records[std::size_t(parent)].world : glm::mat4(1.f);
            const Transform& t = record.transform;
            record.world = parentWorld * glm::translate(glm::mat4(1.f), t.translation) *
                           glm::toMat4(t.rotation) * glm::scale(glm::mat4(1.f), t.scale);
            if (!isFinite(record.world))
                fail(field, "world transform overflows (translation or scale too large)");
            if (node.mesh != -1) hidden = !checkMeshScale(field, record.world);
            record.mobility = nodeMobility(index).value_or(
                parent >= 0 ? records[std::size_t(parent)].mobility : Mobility::Static);
            if (node.camera != -1) {
                checkIndex(field + ".camera", node.camera, mModel.cameras.size(), "cameras");
                record.camera = readCamera(node.camera);
                for (int c = 0; c < 3 && record.camera; ++c)
                    if (!(glm::length(glm::vec3(record.world[c])) > 1e-12f)) {
                        logWarning(mLabel, ": ", field,
                                   ": a camera whose node scales to zero sees nothing; skipped");
                        record.camera.reset();
                    }
                if (record.camera && node.camera < activeCameraIndex) {
                    activeCameraIndex = node.camera;
                    activeRecord = records.size();
                }
            }
            if (const int light = nodeLight(index); light >= 0) record.light = readLight(light);
            record.lightStandIn = nodeStandIn(index);
            record.pointCacheShaded = nodePointCache(index);
            if (record.pointCacheShaded && record.mobility != Mobility::Static)
                fail(field + ".extras.pointCache", "the point cache shades static meshes only");
            records.push_back(std::move(record));
        }
        if (node.mesh != -1 && !hidden) {
            checkIndex(field + ".mesh", node.mesh, mModel.meshes.size(), "meshes");
            if (node.skin != -1)
                logWarning(mLabel, ": ", field,
                           ".skin: skinning is not supported; the mesh is "
                           "imported in its bind pose");
            auto& raw = mRawMeshes[std::size_t(node.mesh)];
            if (!raw) raw = readMesh(node.mesh);
            if (raw->size() == 1) {
                records[std::size_t(self)].source = &raw->front();
            } else {
                for (std::size_t p = 0; p < raw->size(); ++p) {
                    EntityRecord primitive;
                    primitive.name = str(records[std::size_t(self)].name, "#", p);
                    primitive.parent = self;
                    primitive.world = records[std::size_t(self)].world;
                    primitive.mobility = records[std::size_t(self)].mobility;
                    primitive.pointCacheShaded = records[std::size_t(self)].pointCacheShaded;
                    primitive.source = &(*raw)[p];
                    primitive.primitiveOnly = true;
                    records.push_back(std::move(primitive));
                }
            }
        }
        for (auto it = node.children.rbegin(); it != node.children.rend(); ++it)
            stack.emplace_back(*it, self);
    }
    if (activeCameraIndex != std::numeric_limits<int>::max())
        records[activeRecord].camera->active = true;
    return records;
}

void GltfReader::processMeshes(ImportedScene& scene) const {
    const auto worldAabb = [](const Mesh& mesh, const glm::mat4& world) {
        Aabb box;
        for (const glm::vec3& p : mesh.positions)
            box.extend(glm::vec3(world * glm::vec4(p, 1.f)));
        return box;
    };
    Aabb rawBounds;
    for (const EntityRecord& r : scene.records) {
        if (!r.source) continue;
        const Aabb box = worldAabb(r.source->mesh, r.world);
        if (!isFinite(box.min) || !isFinite(box.max))
            fail(r.source->field, "world-space positions overflow");
        rawBounds.extend(box);
    }
    if (!rawBounds.empty()) {
        const double size = glm::length(glm::dvec3(rawBounds.extent()));
        if (!(size <= kSceneMaxSize))
            fail("", "the scene is ", size, " m across, more than the ", kSceneMaxSize,
                 " m qgi lights (are its units millimetres?)");
    }
    float maxEdge = mOptions.maxEdgeLength;
    if (maxEdge == 0.f && !rawBounds.empty()) maxEdge = glm::length(rawBounds.extent()) / 50.f;
    scene.info.maxEdgeLength = maxEdge;

    std::vector<Material> materials(mModel.materials.size());
    for (std::size_t i = 0; i < materials.size(); ++i)
        materials[i] = readMaterial(int(i));

    // Instances under the same scale share one processed mesh. Every instance is a copy in the
    // scene, so the triangle limit counts instances: a small file of many instances must not
    // refine into more than memory holds.
    std::map<std::pair<const RawPrimitive*, float>, Mesh> processed;
    double triangles = 0.0;
    for (EntityRecord& r : scene.records) {
        if (!r.source) continue;
        const glm::mat3 linear(r.world);
        const float scale =
            std::max({glm::length(linear[0]), glm::length(linear[1]), glm::length(linear[2])});
        const float bound = maxEdge > 0.f && scale > 0.f ? maxEdge / scale : 0.f;
        auto [it, inserted] = processed.try_emplace({r.source, bound});
        if (inserted) {
            MeshProcessingOptions options;
            options.maxEdgeLength = bound;
            // Meshes are processed in their own units: the welding distance and the area below
            // which a triangle is dropped are world-space sizes (a room modelled in
            // micrometres under a scale of 1e6 is a room).
            if (scale > 0.f) {
                options.weldDistance /= scale;
                options.minTriangleArea /= scale * scale;
            }
            options.maxTriangles = std::max(kSceneMaxTriangles - triangles, 0.0);
            try {
                it->second = processMesh(r.source->mesh, options);
            } catch (const Error& e) {
                fail(r.source->field, e.what(),
                     triangles > 0.0 ? str(" (", triangles, " triangles in the scene before it)")
                                     : std::string());
            }
        }
        triangles += double(it->second.indices.size() / 3);
        if (triangles > kSceneMaxTriangles)
            fail(r.source->field, "the scene holds more than ", kSceneMaxTriangles,
                 " triangles after refinement (instances counted); raise the edge bound");
        if (it->second.indices.empty()) {
            logWarning(mLabel, ": ", r.source->field, ": no triangles with area; skipped");
            continue;
        }
        r.mesh = it->second;
        if (r.source->material >= 0) r.material = materials[std::size_t(r.source->material)];
        const Aabb box = worldAabb(*r.mesh, r.world);
        scene.info.bounds.extend(box);
        if (r.mobility == Mobility::Avatar) r.avatarRadius = 0.5f * glm::length(box.extent());
    }
    checkPrecision(scene.info.bounds);
}

std::vector<float> GltfReader::readScalars(const std::string& usage, int index) const {
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_SCALAR, {TINYGLTF_COMPONENT_TYPE_FLOAT});
    std::vector<float> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        out[i] = load<float>(a.data + i * a.stride);
        if (!std::isfinite(out[i])) fail(usage, "element ", i, " is not finite");
    }
    return out;
}

std::vector<glm::vec4> GltfReader::readRotations(const std::string& usage, int index) const {
    // Floats, or normalized integers of either sign (glTF allows all for rotations). Not
    // normalised here: a cubic spline's tangents are not rotations.
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_VEC4,
                    {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_BYTE,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_SHORT,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT});
    std::vector<glm::vec4> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        for (int c = 0; c < 4; ++c) {
            switch (a.componentType) {
            case TINYGLTF_COMPONENT_TYPE_FLOAT:
                out[i][c] = load<float>(p + 4 * c);
                break;
            case TINYGLTF_COMPONENT_TYPE_BYTE:
                out[i][c] = std::max(float(load<std::int8_t>(p + c)) / 127.f, -1.f);
                break;
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
                out[i][c] = float(p[c]) / 255.f;
                break;
            case TINYGLTF_COMPONENT_TYPE_SHORT:
                out[i][c] = std::max(float(load<std::int16_t>(p + 2 * c)) / 32767.f, -1.f);
                break;
            default:
                out[i][c] = float(load<std::uint16_t>(p + 2 * c)) / 65535.f;
            }
        }
        if (!isFinite(glm::vec3(out[i])) || !std::isfinite(out[i].w))
            fail(usage, "element ", i, " is not finite");
    }
    return out;
}

void GltfReader::readAnimations(std::vector<EntityRecord>& records) const {
    // A node may only move if no static mesh moves with it (the static BVH, the disc index and
    // the point cache are built once).
    std::vector<bool> staticBelow(records.size(), false);
    for (std::size_t r = records.size(); r-- > 0;) {
        if (records[r].source && records[r].mobility == Mobility::Static) staticBelow[r] = true;
        if (staticBelow[r] && records[r].parent >= 0)
            staticBelow[std::size_t(records[r].parent)] = true;
    }
    struct Channel {
        std::vector<float> times;
        std::vector<glm::vec4> values; // xyz (translation) or a quaternion's xyzw
        bool step = false;
        std::string field;
    };
    struct Animated {
        std::optional<Channel> translation, rotation;
    };
    std::map<int, Animated> nodes;
    bool warnedScale = false;
    for (std::size_t a = 0; a < mModel.animations.size(); ++a) {
        const tinygltf::Animation& animation = mModel.animations[a];
        for (std::size_t c = 0; c < animation.channels.size(); ++c) {
            const tinygltf::AnimationChannel& channel = animation.channels[c];
            const std::string field = str("animations[", a, "].channels[", c, "]");
            if (channel.target_node < 0) continue; // targets something else (an extension)
            checkIndex(field + ".target.node", channel.target_node, mModel.nodes.size(), "nodes");
            const std::string& path = channel.target_path;
            if (path == "scale" || path == "weights") {
                if (!warnedScale)
                    logWarning(mLabel, ": ", field, ".target.path: ", path,
                               " animation is not imported (qgi's mobiles are rigid)");
                warnedScale = true;
                continue;
            }
            if (path != "translation" && path != "rotation")
                fail(field + ".target.path", "'", path, "' is not a glTF 2.0 animation path");
            checkIndex(field + ".sampler", channel.sampler, animation.samplers.size(), "samplers");
            const tinygltf::AnimationSampler& sampler =
                animation.samplers[std::size_t(channel.sampler)];
            const std::string samplerField =
                str("animations[", a, "].samplers[", channel.sampler, "]");
            const std::string& interpolation = sampler.interpolation;
            if (interpolation != "LINEAR" && interpolation != "STEP" &&
                interpolation != "CUBICSPLINE")
                fail(samplerField + ".interpolation", "'", interpolation,
                     "' is not LINEAR, STEP or CUBICSPLINE");
            Channel out;
            out.field = field;
            out.step = interpolation == "STEP";
            out.times = readScalars(samplerField + ".input", sampler.input);
            for (std::size_t k = 0; k < out.times.size(); ++k)
                if (out.times[k] < 0.f || (k > 0 && !(out.times[k] > out.times[k - 1])))
                    fail(samplerField + ".input", "times must be >= 0 and strictly increasing (", k,
                         ": ", out.times[k], ")");
            if (path == "translation") {
                for (const glm::vec3& v : readVec3(samplerField + ".output", sampler.output))
                    out.values.emplace_back(v, 0.f);
            } else {
                out.values = readRotations(samplerField + ".output", sampler.output);
            }
            // A cubic spline stores (in-tangent, value, out-tangent) per key: keep the values
            // and join them linearly.
            if (interpolation == "CUBICSPLINE") {
                if (out.values.size() != 3 * out.times.size())
                    fail(samplerField + ".output", out.values.size(), " values for ",
                         out.times.size(), " cubic-spline keys; needs three per key");
                std::vector<glm::vec4> values;
                for (std::size_t k = 0; k < out.times.size(); ++k)
                    values.push_back(out.values[3 * k + 1]);
                out.values = std::move(values);
            }
            if (out.values.size() != out.times.size())
                fail(samplerField + ".output", out.values.size(), " values for ", out.times.size(),
                     " key times");
            if (path == "rotation")
                for (std::size_t k = 0; k < out.values.size(); ++k) {
                    const float length = glm::length(out.values[k]);
                    if (!(length > 1e-6f))
                        fail(samplerField + ".output", "key ", k, " is not a rotation (zero)");
                    out.values[k] /= length;
                }
            Animated& node = nodes[channel.target_node];
            std::optional<Channel>& slot = path == "translation" ? node.translation : node.rotation;
            if (slot) {
                logWarning(mLabel, ": ", field, ": a second ", path, " channel for nodes[",
                           channel.target_node, "]; only ", slot->field, " is imported");
                continue;
            }
            slot = std::move(out);
        }
    }

    // Value of a channel at time t: holds its ends, linear (slerp) or held between keys.
    const auto sample = [](const Channel& c, float t, bool rotation) {
        if (t <= c.times.front()) return c.values.front();
        if (t >= c.times.back()) return c.values.back();
        const std::size_t k =
            std::size_t(std::upper_bound(c.times.begin(), c.times.end(), t) - c.times.begin());
        const glm::vec4& a = c.values[k - 1];
        const glm::vec4& b = c.values[k];
        if (c.step) return a;
        const float u = (t - c.times[k - 1]) / (c.times[k] - c.times[k - 1]);
        if (!rotation) return glm::mix(a, b, u);
        const glm::quat q =
            glm::slerp(glm::quat(a.w, a.x, a.y, a.z), glm::quat(b.w, b.x, b.y, b.z), u);
        return glm::vec4(q.x, q.y, q.z, q.w);
    };
    for (auto& [index, animated] : nodes) {
        const std::string field = str("nodes[", index, "]");
        const int record = mNodeRecord[std::size_t(index)];
        if (record < 0) continue; // not in the scene
        if (staticBelow[std::size_t(record)]) {
            logWarning(mLabel, ": ", field,
                       " is animated but moves static meshes; its animation "
                       "is ignored (tag them {\"mobility\": \"mobile\"})");
            continue;
        }
        // Keys at every time of either channel; a held (STEP) value also gets a key just
        // before the next time, so that linear blending between keys keeps it.
        std::vector<float> times;
        for (const std::optional<Channel>* c : {&animated.translation, &animated.rotation}) {
            if (!*c) continue;
            const auto& t = (*c)->times;
            times.insert(times.end(), t.begin(), t.end());
            if ((*c)->step)
                for (std::size_t k = 1; k < t.size(); ++k)
                    times.push_back(t[k] - std::min(1e-3f, 0.01f * (t[k] - t[k - 1])));
        }
        std::sort(times.begin(), times.end());
        times.erase(std::unique(times.begin(), times.end()), times.end());
        const Transform& rest = records[std::size_t(record)].transform;
        PathFollower path;
        path.loop = true;
        for (const float t : times) {
            PathKey key;
            key.time = t;
            key.position = animated.translation ? glm::vec3(sample(*animated.translation, t, false))
                                                : rest.translation;
            if (animated.rotation) {
                const glm::vec4 q = sample(*animated.rotation, t, true);
                key.rotation = glm::normalize(glm::quat(q.w, q.x, q.y, q.z));
            } else {
                key.rotation = rest.rotation;
            }
            path.keys.push_back(key);
        }
        readPathExtras(index, path);
        records[std::size_t(record)].path = std::move(path);
    }
}

void GltfReader::readPathExtras(int index, PathFollower& path) const {
    const tinygltf::Value& extras = mModel.nodes[std::size_t(index)].extras;
    if (!extras.IsObject() || !extras.Has("qgiPath")) return;
    const std::string field = str("nodes[", index, "].extras.qgiPath");
    const tinygltf::Value& p = extras.Get("qgiPath");
    if (!p.IsObject()) fail(field, "must be an object {\"loop\": bool, \"timeOffset\": seconds}");
    if (p.Has("loop")) {
        if (!p.Get("loop").IsBool()) fail(field + ".loop", "must be true or false");
        path.loop = p.Get("loop").Get<bool>();
    }
    if (p.Has("timeOffset")) {
        const tinygltf::Value& offset = p.Get("timeOffset");
        if (!offset.IsNumber() || !std::isfinite(offset.GetNumberAsDouble()))
            fail(field + ".timeOffset", "must be a finite number of seconds");
        path.timeOffset = float(offset.GetNumberAsDouble());
    }
}

bool GltfReader::checkMeshScale(const std::string& field, const glm::mat4& world) const {
    // Within these a mesh keeps float precision in its own units and in world units alike.
    // A scale towards zero is how files hide a mesh (or flatten it to nothing): it is left
    // out. A huge one is a mistake that would fail later, deep in a lighting system.
    constexpr double kMinScale = 1e-8, kMaxScale = 1e8;
    const glm::dvec3 scale(glm::length(glm::dvec3(world[0])), glm::length(glm::dvec3(world[1])),
                           glm::length(glm::dvec3(world[2])));
    for (int a = 0; a < 3; ++a)
        if (!(scale[a] <= kMaxScale))
            fail(field, "world scale (", scale.x, ", ", scale.y, ", ", scale.z,
                 ") of a mesh node is above ", kMaxScale);
    for (int a = 0; a < 3; ++a)
        if (!(scale[a] >= kMinScale)) {
            logWarning(mLabel, ": ", field, ": world scale (", scale.x, ", ", scale.y, ", ",
                       scale.z, ") hides its mesh; skipped");
            return false;
        }
    return true;
}

void GltfReader::checkPrecision(const Aabb& bounds) const {
    // Far from the origin, floats are coarse: positions there are a grid of spacing ulp(x).
    // Against the scene's own size, a spacing of 1e-3 leaves rays and discs meaningless and
    // 1e-5 costs visible precision (a 10 m scene 80 km away).
    if (bounds.empty()) return;
    const float far =
        std::max(glm::compMax(glm::abs(bounds.min)), glm::compMax(glm::abs(bounds.max)));
    const float spacing = std::nextafter(far, std::numeric_limits<float>::max()) - far;
    const float size = glm::length(bounds.extent());
    if (!(size > 0.f)) return;
    if (spacing > 1e-3f * size)
        fail("", "the scene lies ", far, " m from the origin, where float positions are ", spacing,
             " m apart, too coarse for its size of ", size, " m; move it near the origin");
    if (spacing > 1e-5f * size)
        logWarning(mLabel, ": the scene lies ", far,
                   " m from the origin, where float positions are ", spacing,
                   " m apart: lighting loses precision; move it near the origin");
}

ImportedScene GltfReader::read() {
    if (!(mOptions.maxEdgeLength >= 0.f && std::isfinite(mOptions.maxEdgeLength)))
        qgi::fail("scene options: maxEdgeLength ", mOptions.maxEdgeLength, " must be >= 0");
    std::string extension = mPath.extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    if (extension != ".gltf" && extension != ".glb")
        fail("", "unknown extension '", extension, "'; expected .gltf or .glb");
    const bool glb = extension == ".glb";

    const std::vector<unsigned char> bytes = readFile();
    const std::string_view json =
        glb ? glbJsonChunk(bytes)
            : std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    if (const int depth = jsonNestingDepth(json); depth > kGltfMaxJsonDepth)
        fail("JSON", "nesting depth ", depth, " exceeds the limit of ", kGltfMaxJsonDepth);
    checkUris(json);
    loadModel(bytes, json, glb);

    checkAsset();
    checkBufferViews();
    checkAccessors();
    ImportedScene scene;
    scene.textures = decodeImages();
    mRawMeshes.resize(mModel.meshes.size());
    scene.records = traverse(sceneRoots(checkNodeGraph()));
    readAnimations(scene.records);
    processMeshes(scene);
    scene.info.name = mPath.stem().string();
    scene.info.source = mPath.string();
    return scene;
}

/// Creates the entities and resources. Nothing here depends on the file; should it still fail
/// (out of memory), everything created is removed again.
void populate(Registry& registry, ImportedScene& scene) {
    std::vector<Entity> entities(scene.records.size());
    try {
        for (std::size_t i = 0; i < scene.records.size(); ++i) {
            EntityRecord& r = scene.records[i];
            if (r.primitiveOnly && !r.mesh) continue; // its primitive had no triangles
            const Entity e = registry.create();
            entities[i] = e;
            registry.emplace<Name>(e, std::move(r.name));
            r.transform.parent = r.parent >= 0 ? entities[std::size_t(r.parent)] : kNullEntity;
            registry.emplace<Transform>(e, r.transform);
            registry.emplace<WorldTransform>(e, r.world);
            if (r.camera) registry.emplace<Camera>(e, *r.camera);
            std::visit(
                [&](const auto& light) {
                    using T = std::decay_t<decltype(light)>;
                    if constexpr (!std::is_same_v<T, std::monostate>) registry.emplace<T>(e, light);
                },
                r.light);
            if (r.lightStandIn) registry.emplace<LightStandIn>(e);
            if (r.path) registry.emplace<PathFollower>(e, std::move(*r.path));
            if (!r.mesh) continue;
            registry.emplace<Mesh>(e, std::move(*r.mesh));
            registry.emplace<Material>(e, r.material);
            switch (r.mobility) {
            case Mobility::Static:
                registry.emplace<StaticMesh>(e);
                if (r.pointCacheShaded) registry.emplace<PointCacheShaded>(e);
                break;
            case Mobility::Mobile:
                registry.emplace<MobileMesh>(e);
                break;
            case Mobility::Avatar:
                registry.emplace<Avatar>(e, r.avatarRadius);
                break;
            }
        }
        registry.ctx().emplace<SceneInfo>(std::move(scene.info));
        registry.ctx().emplace<TextureLibrary>(std::move(scene.textures));
    } catch (...) {
        for (const Entity e : entities)
            registry.destroy(e);
        registry.ctx().erase<SceneInfo>();
        registry.ctx().erase<TextureLibrary>();
        throw;
    }
}

} // namespace

void importGltf(Registry& registry, const fs::path& path, const SceneOptions& options) {
    QGI_ASSERT(registry.aliveCount() == 0 && !registry.ctx().contains<SceneInfo>(),
               "importGltf needs an empty registry");
    ImportedScene scene = GltfReader(path, options).read();
    populate(registry, scene);
}

} // namespace qgi
