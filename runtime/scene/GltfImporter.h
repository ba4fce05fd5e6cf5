#pragma once
/** glTF 2.0 import (`importGltf` in SceneLoader.h), through tinygltf.
 *
 *  Mapping (README.md, "Scene conventions"):
 *  - Nodes of the default scene (scene 0 when none is named; every root node when the file has
 *    no scenes) become entities with Name, Transform (a `matrix` is decomposed into TRS) and
 *    WorldTransform (parent world * local), parents before children.
 *  - A mesh's triangle primitives become Mesh entities: the node's own entity when the mesh has
 *    one primitive, otherwise one child entity per primitive. POSITION, NORMAL and TEXCOORD_0
 *    are read (indexed or not, every index and texcoord component type the spec allows) and run
 *    through processMesh with an edge bound of SceneOptions::maxEdgeLength world metres, or
 *    1/50 of the scene's diagonal when that is 0 (recorded in SceneInfo). The bound is divided
 *    by the node's largest world scale, so refinement is even in world space. Primitives left
 *    without triangles are skipped with a warning.
 *  - Materials: baseColorFactor rgb -> baseColor, baseColorTexture -> TextureLibrary image,
 *    emissiveFactor x KHR_materials_emissive_strength -> emission W/(m^2 sr), metallicFactor,
 *    roughnessFactor. A primitive without a material gets Material{} (grey, diffuse) rather than
 *    glTF's default white metal: untextured test geometry is what omits materials.
 *  - KHR_lights_punctual: intensity x color read as W/sr for point and spot lights and as W/m^2
 *    for directional lights, with no photometric conversion; `range` is ignored (infinite).
 *  - Perspective cameras -> Camera; the node that uses the lowest camera index is active
 *    (first in traversal order on ties). Orthographic cameras are skipped with a warning.
 *  - Node extras: {"mobility": "static" | "mobile"} and {"avatar": true}, inherited from the
 *    nearest ancestor that says either; default static. Mesh entities get StaticMesh, MobileMesh
 *    or Avatar (radius: half the diagonal of the mesh's world bounds). {"pointCache": true} on a
 *    static mesh node (not inherited) adds PointCacheShaded; {"active": false} on a mobile mesh
 *    node (not inherited) imports it out of the world (MobileMesh::active: a pooled object);
 *    {"standIn": true} on a light node adds LightStandIn.
 *  - Animations: translation and rotation channels become a looping PathFollower on their
 *    node (keys at every time of either channel; LINEAR blends, STEP holds, CUBICSPLINE keeps
 *    its values and blends them linearly; all animations of the file play together). Scale
 *    and morph-weight channels are skipped with a warning (mobiles are rigid), and so is the
 *    animation of a node that would move a static mesh. Node extras {"qgiPath": {"loop": bool,
 *    "timeOffset": s}} set what glTF cannot say (the exporter writes them).
 *  - Resources: SceneInfo (name = file stem, source = path) and TextureLibrary (every image of
 *    the file, decoded to 8-bit RGBA, in file order).
 *
 *  Hostile input: before tinygltf sees a byte, the importer checks the file size, the GLB header,
 *  the JSON's nesting depth (tinygltf recurses and overflows the stack) and every buffer and
 *  image URI (relative, inside the file's folder, present, of the declared size; base64 data
 *  URIs well formed), and the JSON type of every field it reads (tinygltf would quietly put a
 *  default in place of a string intensity, a fractional index or a negative offset). After
 *  parsing it checks what tinygltf does not: every index, every byte range of buffer views and
 *  accessors, component types per attribute, index values, finite numbers and their ranges
 *  (colours in [0, 1], lights and emission up to kMaxRadiometricValue, usable cameras), the
 *  node graph (one parent per node, no cycles, bounded depth), the bytes decoded from all
 *  accessors together (kGltfMaxDecodedBytes) and the triangles the primitives declare
 *  (kSceneMaxTriangles), both before decoding, the total triangle count after
 *  refinement with every instance counted (kSceneMaxTriangles) and the float precision left at
 *  the scene's distance from the origin. Any failure throws
 *  qgi::Error with one line `<file>: <field path>: <what>`, and the registry is left as it was:
 *  entities are created only after the whole file has been read and checked.
 */

#include "components/Transform.h"
#include "runtime/scene/MeshProcessing.h"

#include <glm/mat4x4.hpp>

#include <cstdint>
#include <optional>
#include <string_view>

namespace qgi {

/// Deepest JSON nesting the importer hands to tinygltf.
inline constexpr int kGltfMaxJsonDepth = 64;
/// Largest light intensity (W/sr; W/m^2 for directional lights) and emitted radiance
/// (W/(m^2 sr)) accepted: far above any real light, far below float overflow in the photon
/// powers and irradiance sums built from them.
inline constexpr double kMaxRadiometricValue = 1e9;
/// Largest scene accepted, metres across its bounds' diagonal (a thousand kilometres: a file
/// beyond that has the wrong units, and float normals and areas would overflow).
inline constexpr double kSceneMaxSize = 1e6;
/// Largest .gltf, .glb, external buffer or image file the importer reads, bytes.
inline constexpr std::uintmax_t kGltfMaxFileBytes = std::uintmax_t(1) << 30;
/// Most bytes the importer decodes from one file's accessors, all together: the dense copies
/// of sparse accessors and of accessors without a buffer view (zeros), and the vertices,
/// indices and keys read from them (an accessor read by two meshes counts twice). A few lines
/// of JSON can declare a hundred million zeros; this bounds what they cost before anything is
/// allocated. A level of a few million triangles decodes to a few hundred MB.
inline constexpr std::uintmax_t kGltfMaxDecodedBytes = std::uintmax_t(3) << 29; // 1.5 GiB
/// Deepest node hierarchy accepted: the transform system walks at most 256 ancestors, and mesh
/// primitives may add one level below their node.
inline constexpr int kGltfMaxNodeDepth = 128;
/// Largest texture side and pixel count decoded, to bound memory before decoding.
inline constexpr int kGltfMaxImageSide = 16384;
inline constexpr std::int64_t kGltfMaxImagePixels = std::int64_t(1) << 26;

/// Deepest nesting of JSON arrays and objects in `text`, found without parsing: brackets
/// inside strings (escapes included) do not count. Malformed text gives a meaningless but
/// finite answer; the parser reports the syntax error afterwards.
int jsonNestingDepth(std::string_view text);

/// Splits an affine matrix into translation, rotation and scale (a mirroring matrix gets a
/// negative x scale). nullopt when the matrix is not finite, projective, sheared (columns not
/// orthogonal within 1e-4 after normalisation) or has a zero-length column. `parent` stays null.
std::optional<Transform> decomposeTrs(const glm::mat4& matrix);

} // namespace qgi
