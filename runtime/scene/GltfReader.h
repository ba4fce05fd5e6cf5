#pragma once
/** Internal to the glTF importer (GltfImporter.h says what it does): GltfReader, which reads
 *  one file into an ImportedScene, and the records and helpers its translation units share.
 *  Included only by runtime/scene/Gltf*.cpp; not part of the runtime's interface.
 *
 *  GltfReader's members are defined in
 *    GltfJsonChecks.cpp  before tinygltf: the file, the GLB container, JSON types and URIs
 *    GltfImages.cpp      which images are drawn, decoding, undecodable images nothing draws
 *    GltfAccessors.cpp   buffer view and accessor checks, accessor reads (sparse included)
 *    GltfAnimations.cpp  animation channels -> PathFollower
 *    GltfImporter.cpp    read() and the rest: tinygltf, meshes, materials, cameras, lights,
 *                        the node graph, mesh processing, then populate()
 */

#include "runtime/scene/GltfImporter.h"

#include "components/Camera.h"
#include "components/DirectionalLight.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/PathFollower.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/TextureLibrary.h"

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <nlohmann/json_fwd.hpp>
#include <tiny_gltf.h>

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <deque>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace qgi::gltf_detail {

namespace fs = std::filesystem;

static_assert(std::endian::native == std::endian::little, "glTF buffers are little endian");

inline constexpr std::string_view kLightsExtension = "KHR_lights_punctual";
inline constexpr std::string_view kEmissiveStrengthExtension = "KHR_materials_emissive_strength";

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
    bool lightStandIn = false;        ///< node extras {"standIn": true}: see LightStandIn
    bool pointCacheShaded = false;    ///< node extras {"pointCache": true}: see PointCacheShaded
    bool active = true;               ///< node extras {"active": false}: see MobileMesh::active
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

/// Replaces line breaks with spaces, then escapes other control bytes (printable() in Log.h),
/// and bounds the length (tinygltf quotes whole data URIs): for messages from a library. In
/// GltfJsonChecks.cpp.
std::string oneLine(std::string text);

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

/// tinygltf's image callback; `user` is an ImageDecoding. In GltfImages.cpp.
bool decodeImageCallback(tinygltf::Image* image, int index, std::string*, std::string*, int, int,
                         const unsigned char* bytes, int size, void* user);

/// Reads one glTF file into an ImportedScene, checking everything on the way.
class GltfReader {
public:
    GltfReader(const fs::path& path, const SceneOptions& options)
        : mPath(path), mFolder(fs::absolute(path).parent_path()), mLabel(path.filename().string()),
          mOptions(options) {}

    ImportedScene read();

private:
    /// Throws "<file>: <field>: <what>" with control bytes escaped (printable() in Log.h): a
    /// message may quote the file (a key, a name, an image's chunk type) and stays one line.
    template <typename... Args>
    [[noreturn]] void fail(std::string_view field, Args&&... what) const {
        if (field.empty()) throw Error(printable(str(mLabel, ": ", std::forward<Args>(what)...)));
        throw Error(printable(str(mLabel, ": ", field, ": ", std::forward<Args>(what)...)));
    }
    void checkIndex(std::string_view field, int index, std::size_t count,
                    std::string_view what) const {
        if (index < 0 || std::size_t(index) >= count)
            fail(field, "index ", index, " out of range (", count, " ", what, ")");
    }

    // Before tinygltf (GltfJsonChecks.cpp): the raw file, the GLB container, the JSON syntax
    // and every URI.
    std::vector<unsigned char> readFile() const;
    std::string_view glbJsonChunk(const std::vector<unsigned char>& bytes) const;
    /// Parses the JSON (syntax errors end here, with line and column), then checks the URIs
    /// of every buffer and image.
    void checkUris(std::string_view json);
    /// The JSON types of the fields qgi reads (tinygltf quietly puts a default in place of a
    /// value of the wrong type: a string intensity, a float index, a negative offset).
    void checkTypes(const nlohmann::json& document) const;
    void checkUri(const nlohmann::json& object, const std::string& section, std::size_t index,
                  bool isBuffer) const;
    /// The file a relative URI names inside the scene's folder, decoded as tinygltf decodes it
    /// (plusIsSpace: '+' reads as a space; false only to explain a file that was not found);
    /// throws for anything else.
    fs::path resolveUri(const std::string& field, const std::string& uri,
                        bool plusIsSpace = true) const;

    // Images (GltfImages.cpp).
    /// Which images a material draws (ImageDecoding::used); after checkTypes.
    void findUsedImages(const nlohmann::json& document);
    /// Warns about the images replaced by skipUnusedImage since the last call.
    void reportSkippedImages();
    TextureLibrary decodeImages();

    // Buffer views and accessors (GltfAccessors.cpp): what tinygltf does not check, then reads.
    void checkBufferViews() const;
    void checkAccessors() const;
    /// A range-checked accessor used as `usage` (a field path), of the given type and one of
    /// the given component types, that the caller decodes into `decodedElement` bytes an
    /// element: counted against kGltfMaxDecodedBytes (with any dense copy made here) before
    /// anything is allocated.
    AccessorData useAccessor(const std::string& usage, int index, int type,
                             std::initializer_list<int> componentTypes,
                             std::size_t decodedElement) const;
    /// Accessor `index`'s own buffer view, as stored.
    AccessorData rawView(int index, std::size_t element) const;
    /// Writes a sparse accessor's substitutions over its dense elements.
    void applySparse(int index, std::size_t element, std::vector<unsigned char>& dense) const;
    std::vector<glm::vec3> readVec3(const std::string& usage, int index) const;
    std::vector<glm::vec2> readTexcoords(const std::string& usage, int index) const;
    std::vector<std::uint32_t> readIndices(const std::string& usage, int index,
                                           std::size_t vertexCount) const;
    std::vector<float> readScalars(const std::string& usage, int index) const;
    std::vector<glm::vec4> readRotations(const std::string& usage, int index) const;

    // Animations (GltfAnimations.cpp).
    /// Turns the animations' translation and rotation channels into PathFollowers on the
    /// records of their nodes (see the header).
    void readAnimations(std::vector<EntityRecord>& records) const;
    /// Node extras {"qgiPath": {"loop": bool, "timeOffset": s}} (what glTF cannot say).
    void readPathExtras(int index, PathFollower& path) const;

    // The parse and the conversion to components (GltfImporter.cpp).
    void loadModel(const std::vector<unsigned char>& bytes, std::string_view json, bool glb);
    void checkAsset() const;
    std::vector<RawPrimitive> readMesh(int meshIndex) const;
    Material readMaterial(int index) const;
    std::optional<Camera> readCamera(int index) const;
    Light readLight(int index) const;
    /// Parent of every node (-1 for roots), after checking children indices, single parents,
    /// cycles and depth.
    std::vector<int> checkNodeGraph() const;
    std::vector<int> sceneRoots(const std::vector<int>& parents) const;
    /// Warns of a node extras key that looks like a misspelt qgi key ("mobilty").
    void warnMisspeltExtras(int index) const;
    /// The scene's extras {"exposure": x} (a finite x > 0), else 1.
    float sceneExposure() const;
    Transform localTransform(int index) const;
    std::optional<Mobility> nodeMobility(int index) const;
    bool nodeStandIn(int index) const;
    /// Node extras {key: bool} on a node with a mesh; `absent` when the extras do not say.
    bool nodeMeshFlag(int index, const char* key, bool absent) const;
    bool nodePointCache(int index) const;
    /// Node extras {"active": bool} (default true), on a node with a mesh.
    bool nodeActive(int index) const;
    int nodeLight(int index) const;
    /// One record per node below `roots` (and per primitive of multi-primitive meshes).
    std::vector<EntityRecord> traverse(const std::vector<int>& roots);
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
    /// Bytes decoded from accessors so far (kGltfMaxDecodedBytes).
    mutable std::uintmax_t mDecodedBytes = 0;
    /// Triangles the primitives read so far declare, before processing (kSceneMaxTriangles).
    mutable std::uintmax_t mDeclaredTriangles = 0;
};

} // namespace qgi::gltf_detail
