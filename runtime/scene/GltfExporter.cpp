// glTF 2.0 export (`exportGltf` in SceneLoader.h), through tinygltf, in the conventions the
// importer reads (GltfImporter.h):
//  - every entity with a Transform becomes a node with TRS and its Name; Transform::parent
//    gives the children lists. Entities without a Transform have no place in the node tree and
//    are not written.
//  - a Mesh becomes a glTF mesh of one indexed primitive (POSITION with min/max, NORMAL,
//    TEXCOORD_0 when present, UNSIGNED_INT indices) with its own material; all data lives in one
//    buffer, embedded as base64 in a .gltf or as the BIN chunk of a .glb.
//  - node extras say {"mobility": "static" | "mobile"} or {"avatar": true} on every mesh node,
//    so no tag depends on inheritance, {"pointCache": true} on PointCacheShaded ones and
//    {"active": false} on mobiles out of the world.
//  - a PathFollower becomes LINEAR translation and rotation channels of one animation, with its
//    loop and time offset in the node's extras {"qgiPath": {...}}.
//  - emission above 1 is split into emissiveFactor (max component 1) and
//    KHR_materials_emissive_strength; lights go to KHR_lights_punctual (one per node); the
//    active camera is written as cameras[0], which the importer makes active.
//  - TextureLibrary images are embedded as PNG data URIs (tinygltf's writer, through stb), one
//    texture per image, so Material::baseColorTexture keeps its index.
//  - the scene's suggested exposure (SceneInfo::exposure), when not 1, goes to the scene's
//    extras {"exposure": x}.

#include "runtime/scene/SceneLoader.h"

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
#include "components/Transform.h"
#include "runtime/core/Log.h"
#include "runtime/io/AtomicFile.h"
#include "runtime/scene/SceneInfo.h"
#include "runtime/scene/SceneQueries.h"
#include "runtime/scene/TextureLibrary.h"

#include <tiny_gltf.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>
#include <unordered_map>

namespace qgi {

namespace {

const std::string kLightsExtension = "KHR_lights_punctual";
const std::string kEmissiveStrengthExtension = "KHR_materials_emissive_strength";

/// Appends `count` elements to `buffer` as a new buffer view with an accessor over it; returns
/// the accessor's index. Every element type written is a multiple of 4 bytes, so views stay
/// aligned.
template <typename T>
int addAccessor(tinygltf::Model& model, std::vector<unsigned char>& buffer,
                const std::vector<T>& elements, int componentType, int type, int target) {
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = buffer.size();
    view.byteLength = elements.size() * sizeof(T);
    view.target = target;
    const auto* bytes = reinterpret_cast<const unsigned char*>(elements.data());
    buffer.insert(buffer.end(), bytes, bytes + view.byteLength);
    model.bufferViews.push_back(std::move(view));

    tinygltf::Accessor accessor;
    accessor.bufferView = int(model.bufferViews.size() - 1);
    accessor.componentType = componentType;
    accessor.count = elements.size();
    accessor.type = type;
    model.accessors.push_back(std::move(accessor));
    return int(model.accessors.size() - 1);
}

int addMesh(tinygltf::Model& model, std::vector<unsigned char>& buffer, const Mesh& mesh,
            int material, const std::string& name) {
    QGI_ASSERT(mesh.normals.empty() || mesh.normals.size() == mesh.positions.size());
    QGI_ASSERT(mesh.uvs.empty() || mesh.uvs.size() == mesh.positions.size());
    tinygltf::Primitive primitive;
    primitive.mode = TINYGLTF_MODE_TRIANGLES;
    primitive.material = material;

    const int position = addAccessor(model, buffer, mesh.positions, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                     TINYGLTF_TYPE_VEC3, TINYGLTF_TARGET_ARRAY_BUFFER);
    Aabb box; // the spec requires POSITION bounds
    for (const glm::vec3& p : mesh.positions)
        box.extend(p);
    model.accessors[std::size_t(position)].minValues = {box.min.x, box.min.y, box.min.z};
    model.accessors[std::size_t(position)].maxValues = {box.max.x, box.max.y, box.max.z};
    primitive.attributes["POSITION"] = position;
    if (!mesh.normals.empty())
        primitive.attributes["NORMAL"] =
            addAccessor(model, buffer, mesh.normals, TINYGLTF_COMPONENT_TYPE_FLOAT,
                        TINYGLTF_TYPE_VEC3, TINYGLTF_TARGET_ARRAY_BUFFER);
    if (!mesh.uvs.empty())
        primitive.attributes["TEXCOORD_0"] =
            addAccessor(model, buffer, mesh.uvs, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2,
                        TINYGLTF_TARGET_ARRAY_BUFFER);
    primitive.indices =
        addAccessor(model, buffer, mesh.indices, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                    TINYGLTF_TYPE_SCALAR, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);

    tinygltf::Mesh out;
    out.name = name;
    out.primitives.push_back(std::move(primitive));
    model.meshes.push_back(std::move(out));
    return int(model.meshes.size() - 1);
}

/// Sets extras[key] = value on a node, keeping its other extras.
void addExtra(tinygltf::Node& node, const std::string& key, tinygltf::Value value) {
    tinygltf::Value::Object extras = node.extras.IsObject()
                                         ? node.extras.Get<tinygltf::Value::Object>()
                                         : tinygltf::Value::Object{};
    extras[key] = std::move(value);
    node.extras = tinygltf::Value(std::move(extras));
}

/// A scripted path as glTF animation channels on `node` (LINEAR translation and rotation over
/// the path's key times), in the file's one animation. What glTF cannot say, the loop and the
/// time offset, goes to the node's extras as {"qgiPath": {"loop": bool, "timeOffset": s}}.
void addPathAnimation(tinygltf::Model& model, std::vector<unsigned char>& buffer,
                      const PathFollower& path, int node) {
    std::vector<float> times;
    std::vector<glm::vec3> positions;
    std::vector<glm::vec4> rotations; // x, y, z, w as glTF stores them
    for (const PathKey& k : path.keys) {
        // glTF key times strictly increase: a key at the time of the one before (a jump, to
        // PathFollower) keeps only the first.
        if (!times.empty() && !(k.time > times.back())) continue;
        times.push_back(k.time);
        positions.push_back(k.position);
        rotations.push_back({k.rotation.x, k.rotation.y, k.rotation.z, k.rotation.w});
    }
    const int input =
        addAccessor(model, buffer, times, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR, 0);
    model.accessors[std::size_t(input)].minValues = {times.front()};
    model.accessors[std::size_t(input)].maxValues = {times.back()};
    if (model.animations.empty()) model.animations.emplace_back().name = "qgi paths";
    tinygltf::Animation& animation = model.animations.front();
    const auto channel = [&](const char* target, int output) {
        tinygltf::AnimationSampler sampler;
        sampler.input = input;
        sampler.output = output;
        sampler.interpolation = "LINEAR";
        animation.samplers.push_back(std::move(sampler));
        tinygltf::AnimationChannel out;
        out.sampler = int(animation.samplers.size() - 1);
        out.target_node = node;
        out.target_path = target;
        animation.channels.push_back(std::move(out));
    };
    channel("translation", addAccessor(model, buffer, positions, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                       TINYGLTF_TYPE_VEC3, 0));
    channel("rotation", addAccessor(model, buffer, rotations, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                    TINYGLTF_TYPE_VEC4, 0));
    addExtra(model.nodes[std::size_t(node)], "qgiPath",
             tinygltf::Value(tinygltf::Value::Object{
                 {"loop", tinygltf::Value(path.loop)},
                 {"timeOffset", tinygltf::Value(double(path.timeOffset))}}));
}

tinygltf::Material toGltf(const Material& m) {
    tinygltf::Material out;
    out.pbrMetallicRoughness.baseColorFactor = {m.baseColor.r, m.baseColor.g, m.baseColor.b, 1.0};
    out.pbrMetallicRoughness.metallicFactor = m.metallic;
    out.pbrMetallicRoughness.roughnessFactor = m.roughness;
    out.pbrMetallicRoughness.baseColorTexture.index = m.baseColorTexture;
    // emissiveFactor is limited to [0, 1]; the strength extension carries the rest.
    const float strength = std::max({m.emission.r, m.emission.g, m.emission.b});
    const glm::vec3 factor = strength > 1.f ? m.emission / strength : m.emission;
    out.emissiveFactor = {factor.r, factor.g, factor.b};
    if (strength > 1.f)
        out.extensions[kEmissiveStrengthExtension] = tinygltf::Value(
            tinygltf::Value::Object{{"emissiveStrength", tinygltf::Value(double(strength))}});
    return out;
}

tinygltf::Value mobilityExtras(const Registry& registry, Entity e) {
    using Object = tinygltf::Value::Object;
    if (registry.has<Avatar>(e)) return tinygltf::Value(Object{{"avatar", tinygltf::Value(true)}});
    const char* mobility = registry.has<MobileMesh>(e) ? "mobile" : "static";
    Object extras{{"mobility", tinygltf::Value(std::string(mobility))}};
    if (registry.has<PointCacheShaded>(e)) extras["pointCache"] = tinygltf::Value(true);
    if (outOfWorld(registry, e)) extras["active"] = tinygltf::Value(false);
    return tinygltf::Value(std::move(extras));
}

tinygltf::Light toGltf(const char* type, const glm::vec3& color, float intensity) {
    tinygltf::Light light;
    light.type = type;
    light.color = {color.r, color.g, color.b};
    light.intensity = intensity;
    return light;
}

} // namespace

void exportGltf(const Registry& registry, const std::filesystem::path& path) {
    const std::string label = path.filename().string();
    std::string extension = path.extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    if (extension != ".gltf" && extension != ".glb")
        fail(label, ": unknown extension '", extension, "'; expected .gltf or .glb");

    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "qgi";
    std::vector<unsigned char> buffer;

    const std::vector<Entity> entities = registry.view<const Transform>().entities();
    std::unordered_map<Entity, int> nodeOf;
    for (const Entity e : entities)
        nodeOf.emplace(e, int(nodeOf.size()));
    model.nodes.resize(entities.size());
    std::vector<int> roots;
    std::vector<std::pair<const Camera*, int>> cameras; // (camera, node)

    for (std::size_t i = 0; i < entities.size(); ++i) {
        const Entity e = entities[i];
        tinygltf::Node& node = model.nodes[i];
        if (const Name* name = registry.tryGet<Name>(e)) node.name = name->value;
        const Transform& t = registry.get<Transform>(e);
        node.translation = {t.translation.x, t.translation.y, t.translation.z};
        node.rotation = {t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w};
        node.scale = {t.scale.x, t.scale.y, t.scale.z};
        if (const auto parent = nodeOf.find(t.parent); parent != nodeOf.end())
            model.nodes[std::size_t(parent->second)].children.push_back(int(i));
        else
            roots.push_back(int(i));

        const Mesh* mesh = registry.tryGet<Mesh>(e);
        if (mesh && !mesh->indices.empty()) {
            const Material* material = registry.tryGet<Material>(e);
            const Material m = material ? *material : Material{};
            model.materials.push_back(toGltf(m));
            node.mesh = addMesh(model, buffer, *mesh, int(model.materials.size() - 1), node.name);
            node.extras = mobilityExtras(registry, e);
        }

        std::vector<tinygltf::Light> lights;
        if (const auto* l = registry.tryGet<PointLight>(e))
            lights.push_back(toGltf("point", l->color, l->intensity));
        if (const auto* l = registry.tryGet<SpotLight>(e)) {
            lights.push_back(toGltf("spot", l->color, l->intensity));
            lights.back().spot.innerConeAngle = l->innerConeAngle;
            lights.back().spot.outerConeAngle = l->outerConeAngle;
        }
        if (const auto* l = registry.tryGet<DirectionalLight>(e))
            lights.push_back(toGltf("directional", l->color, l->irradiance));
        if (lights.size() > 1)
            logWarning(label, ": node '", node.name, "' has ", lights.size(),
                       " lights; glTF allows one per node, only the first is written");
        if (!lights.empty() && registry.has<LightStandIn>(e))
            addExtra(node, "standIn", tinygltf::Value(true));
        if (!lights.empty()) {
            node.extensions[kLightsExtension] = tinygltf::Value(
                tinygltf::Value::Object{{"light", tinygltf::Value(int(model.lights.size()))}});
            model.lights.push_back(std::move(lights.front()));
        }

        if (const Camera* camera = registry.tryGet<Camera>(e)) cameras.emplace_back(camera, int(i));
        if (const PathFollower* follower = registry.tryGet<PathFollower>(e);
            follower && !follower->keys.empty())
            addPathAnimation(model, buffer, *follower, int(i));
    }

    std::stable_partition(cameras.begin(), cameras.end(),
                          [](const auto& c) { return c.first->active; });
    for (const auto& [camera, node] : cameras) {
        tinygltf::Camera out;
        out.type = "perspective";
        out.perspective.yfov = camera->yfov;
        out.perspective.znear = camera->znear;
        // No far plane: zfar absent (0 to tinygltf), as glTF writes an infinite projection.
        out.perspective.zfar = std::isfinite(camera->zfar) ? camera->zfar : 0.0;
        model.nodes[std::size_t(node)].camera = int(model.cameras.size());
        model.cameras.push_back(std::move(out));
    }

    if (const auto* library = registry.ctx().find<TextureLibrary>()) {
        for (const Image& image : library->images) {
            QGI_ASSERT(image.width > 0 && image.height > 0 &&
                           image.rgba.size() == std::size_t(image.width) * image.height * 4,
                       "texture '", image.name, "' has inconsistent sizes");
            tinygltf::Image out;
            out.name = image.name;
            out.width = image.width;
            out.height = image.height;
            out.component = 4;
            out.bits = 8;
            out.pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
            out.image = image.rgba;
            out.mimeType = "image/png";
            tinygltf::Texture texture;
            texture.source = int(model.images.size());
            model.images.push_back(std::move(out));
            model.textures.push_back(std::move(texture));
        }
    }
    for (const tinygltf::Material& m : model.materials)
        QGI_ASSERT(m.pbrMetallicRoughness.baseColorTexture.index < int(model.textures.size()),
                   "a material refers to a texture the TextureLibrary does not hold");
    if (std::any_of(model.materials.begin(), model.materials.end(), [](const auto& m) {
            return m.extensions.count(kEmissiveStrengthExtension) != 0;
        }))
        model.extensionsUsed.push_back(kEmissiveStrengthExtension);

    if (!buffer.empty()) {
        tinygltf::Buffer out;
        out.data = std::move(buffer);
        model.buffers.push_back(std::move(out));
    }
    tinygltf::Scene scene;
    scene.nodes = std::move(roots);
    if (const SceneInfo* info = registry.ctx().find<SceneInfo>(); info && info->exposure != 1.f)
        scene.extras = tinygltf::Value(
            tinygltf::Value::Object{{"exposure", tinygltf::Value(double(info->exposure))}});
    model.scenes.push_back(std::move(scene));
    model.defaultScene = 0;

    // Encoded in memory (buffers and images embedded), then written as a whole: tinygltf's own
    // file writer does not notice a full disk.
    tinygltf::TinyGLTF writer;
    std::ostringstream encoded;
    bool written = false;
    try {
        written = writer.WriteGltfSceneToStream(&model, encoded, /*prettyPrint*/ true,
                                                /*writeBinary*/ extension == ".glb");
    } catch (const std::exception& e) {
        fail(label, ": cannot write: ", e.what());
    }
    if (!written) fail(label, ": cannot encode '", path.string(), "'");
    writeFileAtomically(path, encoded.view(), "glTF");
}

} // namespace qgi
