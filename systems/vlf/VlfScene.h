#pragma once

#include "runtime/ecs/Entity.h"
#include "runtime/raytrace/EmbreeDevice.h"
#include "runtime/raytrace/EmbreeHandle.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

namespace qgi {
class Registry;
struct Material;
} // namespace qgi

namespace qgi::vlf {

/// A planar face of the static scene: the coplanar triangles of one mesh with one material.
/// The VLF stores light per face (thesis: planar convex polygons); a face's irradiance map lives
/// in its plane frame (origin, axisU, axisV), metres.
struct Face {
    glm::vec3 normal{0.f, 1.f, 0.f};      ///< unit, world space, on the front (lit) side
    float offset = 0.f;                   ///< plane: dot(normal, x) = offset, metres
    glm::vec3 origin{0.f};                ///< corner of the face's bounding rectangle in its plane
    glm::vec3 axisU{1.f, 0.f, 0.f};       ///< unit, in the plane
    glm::vec3 axisV{0.f, 0.f, 1.f};       ///< unit, in the plane, cross(axisU, axisV) = normal
    float extentU = 0.f, extentV = 0.f;   ///< size of the bounding rectangle, metres
    float area = 0.f;                     ///< sum of its triangle areas, m^2
    glm::vec3 diffuse{0.f};               ///< k_d: diffuse albedo, linear RGB
    glm::vec3 emission{0.f};              ///< emitted radiance, W/(m^2 sr)
    glm::vec3 specular{0.f};              ///< k_s of the modified Phong lobe
    float phongExponent = 0.f;            ///< n_s; 0: ideal mirror
    std::vector<std::uint32_t> triangles; ///< indices into VlfScene::triangles()

    bool isSpecular() const { return specular.x > 0.f || specular.y > 0.f || specular.z > 0.f; }
    bool isMirror() const { return isSpecular() && phongExponent <= 0.f; }
};

/// A point, spot or directional light, in world space, for the bake's direct-light pass.
struct PunctualLight {
    enum class Kind : std::uint32_t { Local, Directional };
    Kind kind = Kind::Local; ///< Local: a point or spot light at `position`
    glm::vec3 position{0.f};
    /// Local: radiant intensity on the axis x colour, W/sr. Directional: irradiance on a
    /// surface facing the light x colour, W/m^2.
    glm::vec3 intensity{0.f};
    glm::vec3 axis{0.f, 0.f, -1.f}; ///< spot, directional: unit direction the light travels
    float cosInner = -2.f;          ///< spot: full intensity where cos(angle) >= cosInner
    float cosOuter = -2.f;          ///< spot: zero where cos(angle) <= cosOuter; -2: point
    /// Local: radiant intensity towards unit direction `d` (from the light), W/sr
    /// (spotFalloff for a spot).
    glm::vec3 intensityTowards(const glm::vec3& d) const;
};

/// One crossing of a line with a face: `t` along the line (metres) and the face.
struct Crossing {
    float t = 0.f;
    std::uint32_t face = 0;
};

/** The static geometry the VLF is baked from: world-space triangles grouped into planar faces,
 *  punctual lights and the environment radiance, plus an Embree scene of the triangles for the
 *  bake's visibility (every crossing of a line, by repeated intersect-and-advance).
 *  Immutable after construction; queries are thread safe.                                   */
class VlfScene {
public:
    struct Triangle {
        glm::vec3 p0, p1, p2;
        std::uint32_t face = 0;
    };

    /// Faces from StaticMesh + Mesh + WorldTransform + Material; PointLight / SpotLight /
    /// DirectionalLight with a WorldTransform (LightStandIn lights are skipped: their surface
    /// emits already); the
    /// environment from SceneInfo when present. Mobiles and avatars are not part of the VLF.
    /// `device`: the Embree device to build on (the RayScene's, so the engine keeps one); null:
    /// the scene makes its own. `traced` false: faces only, no Embree scene (for counting them;
    /// crossings and occlusion must not be asked). Throws qgi::Error on an empty scene or
    /// non-finite data, naming the entity.
    static std::unique_ptr<VlfScene>
    fromRegistry(const Registry& registry, EmbreeDevice* device = nullptr, bool traced = true);

    /// Groups `triangles` (their `face` field is ignored) into planar faces by `group`
    /// (triangles of one group with one plane form a face) with `materials[group]`.
    struct Material {
        glm::vec3 diffuse{0.f}, emission{0.f}, specular{0.f};
        float phongExponent = 0.f;
    };
    /// Roughness from which a metal counts as diffuse (n_s = 2 / roughness^4 - 2 of about 4 or
    /// less).
    static constexpr float kDiffuseRoughness = 0.75f;
    /// The VLF's reading of a Material component: `specular` and `phongExponent` when set;
    /// otherwise glTF metallic-roughness mapped to k_s = metallic, k_d = baseColor *
    /// (1 - metallic), n_s = 2 / roughness^4 - 2 (Beckmann-Phong match; roughness 0: mirror),
    /// except that a metal of roughness kDiffuseRoughness or more stays diffuse (k_d =
    /// baseColor, no lobe).
    static Material fromComponent(const qgi::Material& material);
    /// `device` and `traced` as for fromRegistry(); the device must outlive the scene.
    VlfScene(std::vector<Triangle> triangles, const std::vector<std::uint32_t>& group,
             const std::vector<Material>& materials, std::vector<PunctualLight> lights,
             const glm::vec3& environment, EmbreeDevice* device = nullptr, bool traced = true);

    const std::vector<Face>& faces() const { return mFaces; }
    /// The group (fromRegistry: the index into entities()) of each face.
    const std::vector<std::uint32_t>& faceGroups() const { return mFaceGroups; }
    /// fromRegistry: the mesh entity of each group; empty for scenes built from triangles.
    const std::vector<Entity>& entities() const { return mEntities; }
    const std::vector<Triangle>& triangles() const { return mTriangles; }
    const std::vector<PunctualLight>& lights() const { return mLights; }
    const glm::vec3& environment() const { return mEnvironment; }
    const Aabb& bounds() const { return mBounds; }
    /// 64-bit hash of everything the bake reads from the scene (geometry, faces, materials,
    /// lights, environment), for cache keys.
    std::uint64_t contentHash() const { return mHash; }

    /// The face that holds world point `x` on the side of unit normal `n`: among the faces
    /// whose normal is within 8 degrees of n, the one whose triangles come nearest to x
    /// (distance in metres: off the plane and, in the plane, outside the triangles), or
    /// nullopt when none comes within `tolerance` metres. A plane test alone is not enough:
    /// a non-planar quad (the cornell box's red wall) makes two faces whose planes agree to a
    /// millimetre near their shared edge and whose bounding rectangles both cover the whole
    /// quad, and a face's irradiance map holds nothing outside its triangles. Brute force
    /// over the candidate faces' triangles: for tools and tests, not per-frame lookups.
    std::optional<std::uint32_t> faceAt(const glm::vec3& x, const glm::vec3& n,
                                        float tolerance = 1e-3f) const;

    /// Every crossing of the segment origin + t * dir, t in [0, tMax] (dir unit), sorted by t;
    /// crossings closer than `merge` to the previous one are dropped (a shared edge hit
    /// twice). Writes at most `maxCrossings` (further ones are dropped). Returns the count.
    std::size_t crossings(const glm::vec3& origin, const glm::vec3& dir, float tMax, Crossing* out,
                          std::size_t maxCrossings, float merge) const;
    /// First crossing after tMin, or none (face = UINT32_MAX).
    Crossing firstHit(const glm::vec3& origin, const glm::vec3& dir, float tMin, float tMax) const;
    /// Whether the open segment between a and b is blocked.
    bool occluded(const glm::vec3& a, const glm::vec3& b) const;
    /// Whether anything lies along origin + t dir, t in [0, tFar] (dir unit): a ray from a
    /// point already lifted off its surface, to a light at any distance.
    bool occluded(const glm::vec3& origin, const glm::vec3& dir, float tFar) const;

private:
    void buildEmbree();
    bool occludedRay(const glm::vec3& origin, const glm::vec3& dir, float tNear, float tFar) const;

    std::vector<Triangle> mTriangles;
    std::vector<Face> mFaces;
    std::vector<std::uint32_t> mFaceGroups;
    std::vector<Entity> mEntities;
    std::vector<PunctualLight> mLights;
    glm::vec3 mEnvironment{0.f};
    Aabb mBounds;
    std::uint64_t mHash = 0;
    std::unique_ptr<EmbreeDevice> mOwnDevice; ///< when no device was given
    EmbreeDevice* mDevice = nullptr;
    SceneHandle mScene; // released before the device it was made on
};

} // namespace qgi::vlf
