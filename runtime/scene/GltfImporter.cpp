// glTF import: GltfReader::read() and what it does after tinygltf has parsed the file (asset,
// meshes, materials, cameras, lights, the node graph and its traversal, mesh processing), then
// populate() and importGltf. The earlier checks, images, accessors and animations live in the
// files named in GltfReader.h.

#include "runtime/scene/GltfImporter.h"

#include "components/Avatar.h"
#include "components/LightStandIn.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointCacheShaded.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Finite.h"
#include "runtime/core/Log.h"
#include "runtime/scene/GltfReader.h"
#include "runtime/scene/MeshProcessing.h"
#include "runtime/scene/SceneLoader.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtx/component_wise.hpp>
#include <glm/gtx/quaternion.hpp>
#include <glm/mat3x3.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iomanip>
#include <limits>
#include <map>
#include <numbers>
#include <set>
#include <sstream>

namespace qgi {

namespace fs = std::filesystem;

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

namespace gltf_detail {

namespace {

const char* modeName(int mode) {
    static constexpr const char* kNames[] = {"POINTS",      "LINES",     "LINE_LOOP",
                                             "LINE_STRIP",  "TRIANGLES", "TRIANGLE_STRIP",
                                             "TRIANGLE_FAN"};
    return mode >= 0 && mode < 7 ? kNames[mode] : "unknown";
}

} // namespace

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
    // tinygltf requires a skin's inverseBindMatrices, which glTF 2.0 leaves optional (identity
    // matrices). qgi draws skinned meshes in their bind pose and never reads them: not an
    // error here.
    for (const std::string_view optional : {"'inverseBindMatrices' property is missing in Skin.\n"})
        for (std::size_t at; (at = error.find(optional)) != std::string::npos;)
            error.erase(at, optional.size());
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
        // The triangles the primitive declares follow from the accessors' counts: a file whose
        // primitives declare more than a scene may hold is refused before any is decoded (an
        // accessor of zeros with no buffer view costs the file nothing).
        checkIndex(attributes + "POSITION", position, mModel.accessors.size(), "accessors");
        if (primitive.indices >= 0)
            checkIndex(raw.field + ".indices", primitive.indices, mModel.accessors.size(),
                       "accessors");
        const int orderAccessor = primitive.indices >= 0 ? primitive.indices : position;
        const std::size_t corners = mModel.accessors[std::size_t(orderAccessor)].count;
        const std::uintmax_t declared = mode == TINYGLTF_MODE_TRIANGLES ? corners / 3
                                        : corners > 2                   ? corners - 2
                                                                        : 0;
        if (double(mDeclaredTriangles + declared) > kSceneMaxTriangles)
            fail(raw.field, "accessors[", orderAccessor, "].count ", corners, " makes ", declared,
                 " triangles, which would bring the file's primitives to ",
                 mDeclaredTriangles + declared, " triangles, more than the limit of ",
                 kSceneMaxTriangles);
        mDeclaredTriangles += declared;
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
    // An absent zfar is glTF's infinite projection: nothing beyond a set distance is cut off,
    // however large the level.
    camera.zfar = p.zfar != 0.0 ? std::max(float(p.zfar), 1.001f * camera.znear)
                                : std::numeric_limits<float>::infinity();
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
    // Checked as the floats the lights systems read: cones apart in double can meet in float.
    const float inner = float(l.spot.innerConeAngle);
    const float outer = float(l.spot.outerConeAngle);
    if (!(outer > 0.f && outer <= glm::half_pi<float>()))
        fail(field + ".spot.outerConeAngle", l.spot.outerConeAngle, " is not in (0, pi/2]");
    if (!(inner >= 0.f && inner < outer))
        fail(field + ".spot.innerConeAngle", l.spot.innerConeAngle,
             " is not in [0, outerConeAngle) (compared as 32-bit floats)");
    return SpotLight{color, intensity, inner, outer};
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

float GltfReader::sceneExposure() const {
    if (mModel.scenes.empty()) return 1.f;
    const int index = std::max(mModel.defaultScene, 0);
    const tinygltf::Value& extras = mModel.scenes[std::size_t(index)].extras;
    if (!extras.IsObject() || !extras.Has("exposure")) return 1.f;
    const tinygltf::Value& exposure = extras.Get("exposure");
    // Checked as the float it becomes: 1e-300 is positive in double but 0 in float.
    const float value = exposure.IsNumber() ? float(exposure.GetNumberAsDouble()) : -1.f;
    if (!(value > 0.f && value <= 1e6f))
        fail(str("scenes[", index, "].extras.exposure"),
             "must be a number in (0, 1e6] (as a 32-bit float)");
    return value;
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

bool GltfReader::nodeMeshFlag(int index, const char* key, bool absent) const {
    const tinygltf::Value& extras = mModel.nodes[std::size_t(index)].extras;
    if (!extras.IsObject() || !extras.Has(key)) return absent;
    const std::string field = str("nodes[", index, "].extras.", key);
    const tinygltf::Value& value = extras.Get(key);
    if (!value.IsBool()) fail(field, "must be true or false");
    if (mModel.nodes[std::size_t(index)].mesh == -1) fail(field, "set on a node without a mesh");
    return value.Get<bool>();
}

bool GltfReader::nodePointCache(int index) const {
    return nodeMeshFlag(index, "pointCache", false);
}

bool GltfReader::nodeActive(int index) const {
    return nodeMeshFlag(index, "active", true);
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

namespace {

/// Edit distance between a and b, case ignored (insertions, deletions, substitutions).
std::size_t editDistance(std::string_view a, std::string_view b) {
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j)
        row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diagonal = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t above = row[j];
            const bool same = std::tolower(static_cast<unsigned char>(a[i - 1])) ==
                              std::tolower(static_cast<unsigned char>(b[j - 1]));
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (same ? 0 : 1)});
            diagonal = above;
        }
    }
    return row[b.size()];
}

} // namespace

void GltfReader::warnMisspeltExtras(int index) const {
    // Extras are free for any tool (Blender writes custom properties there): only a key within
    // two edits of one qgi reads, and not it, is worth a word.
    static constexpr std::string_view kKeys[] = {"mobility", "avatar",  "pointCache",
                                                 "active",   "standIn", "qgiPath"};
    const tinygltf::Value& extras = mModel.nodes[std::size_t(index)].extras;
    if (!extras.IsObject()) return;
    for (const std::string& key : extras.Keys()) {
        if (std::find(std::begin(kKeys), std::end(kKeys), key) != std::end(kKeys)) continue;
        for (const std::string_view known : kKeys)
            if (editDistance(key, known) <= 2) {
                logWarning(mLabel, ": nodes[", index, "].extras.", key,
                           ": not a key qgi reads; did you mean '", known,
                           "'? (the node is read without it)");
                break;
            }
    }
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
        warnMisspeltExtras(index);
        {
            // Checked on every node, animated or not: a malformed tag is an error wherever it
            // is, not only where an animation happens to read it.
            PathFollower unused;
            readPathExtras(index, unused);
        }
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
            record.active = nodeActive(index);
            if (!record.active && record.mobility != Mobility::Mobile)
                fail(field + ".extras.active",
                     "only a mobile mesh can be out of the world (set \"mobility\": \"mobile\")");
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
                    primitive.active = records[std::size_t(self)].active;
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

namespace {

Aabb unite(Aabb a, const Aabb& b) {
    if (!b.empty()) {
        a.extend(b.min);
        a.extend(b.max);
    }
    return a;
}

/// A mesh far from all the others stretches the scene, and with it the default mesh edge
/// bound (a 50th of its diagonal) every mesh is refined to: a stray object 400 km off leaves
/// a room a few triangles. Names the first mesh that stretches the scene to more than ten
/// times what the others span, and is itself under a tenth of it.
void warnOfOutliers(const std::string& label,
                    const std::vector<std::pair<const EntityRecord*, Aabb>>& records,
                    const Aabb& all, float maxEdge) {
    const std::size_t n = records.size();
    if (n < 3) return; // of two meshes far apart, neither is the stray one
    std::vector<Aabb> before(n + 1), after(n + 1); // unions of records [0, i) and [i, n)
    for (std::size_t i = 0; i < n; ++i)
        before[i + 1] = unite(before[i], records[i].second);
    for (std::size_t i = n; i > 0; --i)
        after[i - 1] = unite(after[i], records[i - 1].second);
    const double diagonal = glm::length(glm::dvec3(all.extent()));
    for (std::size_t i = 0; i < n; ++i) {
        const Aabb rest = unite(before[i], after[i + 1]);
        const Aabb& own = records[i].second;
        const double restDiagonal = glm::length(glm::dvec3(rest.extent()));
        if (!(10.0 * restDiagonal < diagonal &&
              10.0 * glm::length(glm::dvec3(own.extent())) < diagonal))
            continue;
        const EntityRecord& r = *records[i].first;
        logWarning(label, ": ", r.name.empty() ? r.source->field : r.name, " lies ",
                   glm::length(glm::dvec3(own.center()) - glm::dvec3(rest.center())),
                   " m from the rest of the scene, which it stretches from ", restDiagonal, " to ",
                   diagonal, " m across: the default mesh edge bound, a 50th of that, is ", maxEdge,
                   " m. Move it, or set the edge bound (--max-edge, "
                   "SceneOptions::maxEdgeLength)");
        return;
    }
}

} // namespace

void GltfReader::processMeshes(ImportedScene& scene) const {
    const auto worldAabb = [](const Mesh& mesh, const glm::mat4& world) {
        Aabb box;
        for (const glm::vec3& p : mesh.positions)
            box.extend(glm::vec3(world * glm::vec4(p, 1.f)));
        return box;
    };
    // The scene's size, which sets the default edge bound (and from it the disc radius): of
    // the triangles processing will keep. A degenerate one is dropped, so it must not stretch
    // the scene (a 20 km line beside a room made the room's edge bound 400 m).
    const double minArea = double(MeshProcessingOptions{}.minTriangleArea);
    Aabb rawBounds;
    std::set<std::string> needlesNamed; // once per source mesh, not per instance
    std::vector<std::pair<const EntityRecord*, Aabb>> recordBounds; // of the kept triangles
    for (const EntityRecord& r : scene.records) {
        if (!r.source) continue;
        Aabb kept;
        const Mesh& mesh = r.source->mesh;
        const Aabb box = worldAabb(mesh, r.world);
        if (!isFinite(box.min) || !isFinite(box.max))
            fail(r.source->field, "world-space positions overflow");
        const auto corner = [&](std::size_t k) {
            return glm::dvec3(r.world * glm::vec4(mesh.positions[mesh.indices[k]], 1.f));
        };
        // A needle (area, but a height under a millionth of its longest edge: a vertex far
        // off, say) is dropped like a degenerate triangle; unlike one it takes area with it.
        std::size_t needles = 0;
        double needleArea = 0.0;
        for (std::size_t k = 0; k + 2 < mesh.indices.size(); k += 3) {
            const glm::dvec3 a = corner(k), b = corner(k + 1), c = corner(k + 2);
            if (!hasArea(a, b, c, minArea)) {
                const double area = 0.5 * glm::length(glm::cross(b - a, c - a));
                if (area >= minArea) {
                    ++needles;
                    needleArea += area;
                }
                continue;
            }
            kept.extend(glm::vec3(a));
            kept.extend(glm::vec3(b));
            kept.extend(glm::vec3(c));
        }
        if (!kept.empty()) {
            rawBounds.extend(kept.min);
            rawBounds.extend(kept.max);
            recordBounds.emplace_back(&r, kept);
        }
        if (needles > 0 && needlesNamed.insert(r.source->field).second)
            logWarning(mLabel, ": ", r.source->field, ": ", needles,
                       " triangle(s) too thin to light (narrower than a millionth of their "
                       "longest edge; ",
                       needleArea, " m^2 in all) are dropped");
    }
    if (!rawBounds.empty()) {
        const double size = glm::length(glm::dvec3(rawBounds.extent()));
        if (!(size <= kSceneMaxSize)) {
            std::ostringstream across; // enough digits that a size just past the limit shows it
            across << std::setprecision(9) << size;
            fail("", "the scene is ", across.str(), " m across, more than the ", kSceneMaxSize,
                 " m qgi lights (are its units millimetres?)");
        }
    }
    float maxEdge = mOptions.maxEdgeLength;
    if (maxEdge == 0.f && !rawBounds.empty()) {
        maxEdge = glm::length(rawBounds.extent()) / 50.f;
        warnOfOutliers(mLabel, recordBounds, rawBounds, maxEdge);
    }
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
            // Instances of one mesh differ by their scale: name the node too.
            logWarning(mLabel, ": ", r.source->field, " under node '", r.name,
                       "': no triangles with area at its scale; skipped");
            continue;
        }
        r.mesh = it->second;
        if (r.source->material >= 0) r.material = materials[std::size_t(r.source->material)];
        const Aabb box = worldAabb(*r.mesh, r.world);
        if (r.active) scene.info.bounds.extend(box); // a pooled mobile out may wait anywhere
        if (r.mobility == Mobility::Avatar) r.avatarRadius = 0.5f * glm::length(box.extent());
    }
    checkPrecision(scene.info.bounds);
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
    scene.info.exposure = sceneExposure();
    return scene;
}

namespace {

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
                registry.emplace<MobileMesh>(e, MobileMesh{r.active});
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

} // namespace gltf_detail

void importGltf(Registry& registry, const fs::path& path, const SceneOptions& options) {
    QGI_ASSERT(registry.aliveCount() == 0 && !registry.ctx().contains<SceneInfo>(),
               "importGltf needs an empty registry");
    gltf_detail::ImportedScene scene = gltf_detail::GltfReader(path, options).read();
    gltf_detail::populate(registry, scene);
}

} // namespace qgi
