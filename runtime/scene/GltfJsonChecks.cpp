// glTF import, before tinygltf sees a byte: the file's size, the GLB container, the JSON's
// nesting depth and the JSON type of every field the importer reads, and every buffer and
// image URI (relative and inside the scene's folder, present, of the declared size; data URIs
// in well-formed base64).

#include "runtime/scene/GltfReader.h"

#include <nlohmann/json.hpp>

#include <cctype>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>

namespace qgi {

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

namespace gltf_detail {

namespace {

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

} // namespace

std::string oneLine(std::string text) {
    constexpr std::size_t kMaxLength = 300;
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back())))
        text.pop_back();
    std::replace_if(
        text.begin(), text.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
    return printableExcerpt(text, kMaxLength);
}

std::vector<unsigned char> GltfReader::readFile() const {
    std::error_code error;
    // A pipe, a device or a folder: "not supported" from file_size would not say why.
    if (fs::exists(mPath, error) && !fs::is_regular_file(mPath, error))
        fail("", "'", mPath.string(), "' is not a regular file");
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
        // tinygltf refuses a stride out of range saying only "must be the multiple of 4".
        if (const auto stride = o.find("byteStride"); stride != o.end()) {
            const auto value = stride->get<std::uint64_t>();
            if (value < 4 || value > 252 || value % 4 != 0)
                fail(join(at, "byteStride"), value, " is not a multiple of 4 in [4, 252]");
        }
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
    if (!fs::is_regular_file(file, error)) {
        // URIs read '+' as a space: a file named with a plus is found only as %2B.
        if (uri.find('+') != uri.npos) {
            if (fs::is_regular_file(resolveUri(field, uri, false), error))
                fail(field, "'", uri, "' names '", file.filename().string(),
                     "' (a URI reads '+' as a space); to name the file with a plus, write it as "
                     "%2B");
        }
        if (fs::exists(file, error)) fail(field, "'", uri, "' is not a regular file");
        fail(field, "'", uri, "' not found next to the scene");
    }
    // A link (the file, or a folder on its way) may lead anywhere: the file must really lie in
    // the scene's folder, as named or as its own link resolves (a scene given through a link
    // whose files are links beside the real one).
    std::error_code fileError, folderError, sceneError;
    const fs::path real = fs::canonical(file, fileError);
    if (fileError) fail(field, "cannot resolve '", uri, "': ", fileError.message());
    const auto within = [&](const fs::path& folder) {
        const fs::path inside = real.lexically_relative(folder);
        return !inside.empty() && *inside.begin() != "..";
    };
    const fs::path folder = fs::canonical(mFolder, folderError);
    const fs::path sceneFolder = fs::canonical(mPath, sceneError).parent_path();
    if (!(!folderError && within(folder)) && !(!sceneError && within(sceneFolder)))
        fail(field, "'", uri, "' is a link that leaves the scene's folder");
    const std::uintmax_t size = fs::file_size(file, error);
    if (error) fail(field, "cannot read '", uri, "': ", error.message());
    if (size > kGltfMaxFileBytes)
        fail(field, "'", uri, "' has ", size, " bytes, more than the limit of ", kGltfMaxFileBytes);
    if (byteLength && size != byteLength->get<std::uint64_t>())
        fail(lengthField, byteLength->get<std::uint64_t>(), " but '", uri, "' has ", size,
             " bytes");
}

fs::path GltfReader::resolveUri(const std::string& field, const std::string& uri,
                                bool plusIsSpace) const {
    // Decode exactly as tinygltf will ('+' is a space, %XX a byte), so the file checked here
    // is the file it opens.
    std::string path;
    for (std::size_t i = 0; i < uri.size(); ++i) {
        if (uri[i] == '+' && plusIsSpace) {
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

} // namespace gltf_detail
} // namespace qgi
