#include "systems/vlf/VlfScene.h"

#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/Name.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Hash.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/Distance.h"
#include "runtime/math/Pose.h"
#include "systems/vlf/DirectionSet.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>

namespace qgi::vlf {
namespace {

bool finite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

std::string who(const Registry& registry, Entity e) {
    const Name* name = registry.tryGet<Name>(e);
    return name ? str("static mesh '", name->value, "'") : str("static mesh entity ", e.index);
}

} // namespace

VlfScene::Material VlfScene::fromComponent(const qgi::Material& m) {
    Material vm;
    vm.diffuse = m.baseColor;
    vm.emission = m.emission;
    vm.specular = m.specular;
    vm.phongExponent = m.phongExponent;
    const bool explicitSpecular = m.specular != glm::vec3(0.f);
    // A rough metal (roughness >= kDiffuseRoughness: a lobe of n_s about 4 or less, glTF's default
    // roughness 1 among them) scatters nearly as widely as a diffuse surface: it stays diffuse
    // with albedo baseColor, rather than costing a directional field it would blur anyway.
    if (!explicitSpecular && m.metallic > 0.f && std::isfinite(m.metallic) &&
        std::isfinite(m.roughness) && m.roughness < kDiffuseRoughness) {
        // glTF metallic-roughness read as diffuse + modified Phong: the metal fraction
        // becomes the lobe (k_s = metallic, grey), the rest stays diffuse; Beckmann
        // alpha = roughness^2 matches Phong n_s = 2 / alpha^2 - 2; roughness 0 is a mirror.
        const float metallic = std::min(m.metallic, 1.f);
        vm.specular = glm::vec3(metallic);
        vm.diffuse = m.baseColor * (1.f - metallic);
        const float alpha = m.roughness * m.roughness;
        vm.phongExponent = alpha <= 1e-3f ? 0.f : std::max(1.f, 2.f / (alpha * alpha) - 2.f);
    }
    return vm;
}

glm::vec3 PunctualLight::intensityTowards(const glm::vec3& d) const {
    if (cosOuter < -1.f) return intensity;
    return intensity * spotFalloff(glm::dot(d, axis), cosInner, cosOuter);
}

std::unique_ptr<VlfScene> VlfScene::fromRegistry(const Registry& registry, EmbreeDevice* device,
                                                 bool traced) {
    std::vector<Triangle> triangles;
    std::vector<std::uint32_t> group;
    std::vector<Material> materials;
    std::vector<Entity> entities;
    registry.view<const StaticMesh, const Mesh, const WorldTransform, const qgi::Material>().each(
        [&](Entity e, const StaticMesh&, const Mesh& mesh, const WorldTransform& world,
            const qgi::Material& m) {
            for (std::uint32_t index : mesh.indices)
                if (index >= mesh.positions.size())
                    fail(who(registry, e), ": Mesh.indices has ", index, " out of range");
            if (mesh.indices.size() % 3 != 0)
                fail(who(registry, e), ": Mesh.indices is not a multiple of 3");
            Material vm = fromComponent(m);
            if (!finite(vm.diffuse) || !finite(vm.emission) || !finite(vm.specular) ||
                !std::isfinite(vm.phongExponent) || vm.phongExponent < 0.f)
                fail(who(registry, e), ": Material has a non-finite or negative field");
            // A surface that reflects more than it receives makes every bounce brighter.
            for (int c = 0; c < 3; ++c)
                if (vm.diffuse[c] < 0.f || vm.specular[c] < 0.f || vm.emission[c] < 0.f ||
                    vm.diffuse[c] + vm.specular[c] > 1.f + 1e-6f)
                    fail(who(registry, e), ": Material reflects more than it receives or has a ",
                         "negative part (channel ", c, ": diffuse ", vm.diffuse[c], ", specular ",
                         vm.specular[c], ", emission ", vm.emission[c],
                         "); baseColor + specular must lie in [0, 1] and emission be >= 0");
            const std::uint32_t g = std::uint32_t(materials.size());
            materials.push_back(vm);
            entities.push_back(e);
            for (std::size_t i = 0; i + 2 < mesh.indices.size(); i += 3) {
                Triangle t;
                t.p0 = glm::vec3(world.matrix * glm::vec4(mesh.positions[mesh.indices[i]], 1.f));
                t.p1 =
                    glm::vec3(world.matrix * glm::vec4(mesh.positions[mesh.indices[i + 1]], 1.f));
                t.p2 =
                    glm::vec3(world.matrix * glm::vec4(mesh.positions[mesh.indices[i + 2]], 1.f));
                if (!finite(t.p0) || !finite(t.p1) || !finite(t.p2))
                    fail(who(registry, e), ": a vertex is not finite in world space");
                triangles.push_back(t);
                group.push_back(g);
            }
        });
    std::vector<PunctualLight> lights;
    registry.view<const PointLight, const WorldTransform>().each(
        [&](Entity e, const PointLight& p, const WorldTransform& w) {
            if (registry.has<LightStandIn>(e) || !isUsableLightPosition(w.matrix[3])) return;
            PunctualLight l;
            l.position = glm::vec3(w.matrix[3]);
            l.intensity = p.color * p.intensity;
            lights.push_back(l);
        });
    registry.view<const SpotLight, const WorldTransform>().each(
        [&](Entity e, const SpotLight& s, const WorldTransform& w) {
            if (registry.has<LightStandIn>(e) || !isUsableLightPosition(w.matrix[3])) return;
            PunctualLight l;
            l.position = glm::vec3(w.matrix[3]);
            l.intensity = s.color * s.intensity;
            l.axis = glm::normalize(-glm::vec3(w.matrix[2]));
            l.cosInner = std::cos(s.innerConeAngle);
            l.cosOuter = std::cos(s.outerConeAngle);
            lights.push_back(l);
        });
    registry.view<const DirectionalLight, const WorldTransform>().each(
        [&](Entity e, const DirectionalLight& d, const WorldTransform& w) {
            if (registry.has<LightStandIn>(e)) return;
            PunctualLight l;
            l.kind = PunctualLight::Kind::Directional;
            l.intensity = d.color * d.irradiance;
            l.axis = glm::normalize(-glm::vec3(w.matrix[2]));
            lights.push_back(l);
        });
    const SceneInfo* info = registry.ctx().find<SceneInfo>();
    auto scene =
        std::make_unique<VlfScene>(std::move(triangles), group, materials, std::move(lights),
                                   info ? info->environment : glm::vec3(0.f), device, traced);
    scene->mEntities = std::move(entities);
    return scene;
}

VlfScene::VlfScene(std::vector<Triangle> triangles, const std::vector<std::uint32_t>& group,
                   const std::vector<Material>& materials, std::vector<PunctualLight> lights,
                   const glm::vec3& environment, EmbreeDevice* device, bool traced)
    : mLights(std::move(lights)), mEnvironment(environment),
      mOwnDevice(device || !traced ? nullptr : std::make_unique<EmbreeDevice>()),
      mDevice(device ? device : mOwnDevice.get()) {
    if (group.size() != triangles.size()) fail("VlfScene: one group per triangle is needed");
    if (!finite(environment)) fail("VlfScene: the environment radiance is not finite");
    for (const PunctualLight& l : mLights)
        if (!finite(l.position) || !finite(l.intensity) || !finite(l.axis))
            fail("VlfScene: a punctual light has a non-finite field");
    // Faces: triangles of one group sharing a plane (normal to 1e-3, offset to 0.1 mm).
    std::map<std::tuple<std::uint32_t, int, int, int, long>, std::uint32_t> faceOf;
    for (std::size_t i = 0; i < triangles.size(); ++i) {
        Triangle t = triangles[i];
        if (group[i] >= materials.size()) fail("VlfScene: triangle ", i, " has no material");
        const glm::vec3 c = glm::cross(t.p1 - t.p0, t.p2 - t.p0);
        const float len = glm::length(c);
        if (!(len > 1e-12f)) continue; // degenerate: no area, never hit
        const glm::vec3 n = c / len;
        const float offset = glm::dot(n, t.p0);
        const auto key = std::make_tuple(
            group[i], int(std::lround(n.x * 1000.f)), int(std::lround(n.y * 1000.f)),
            int(std::lround(n.z * 1000.f)), long(std::lround(offset * 1e4f)));
        auto [it, added] = faceOf.try_emplace(key, std::uint32_t(mFaces.size()));
        if (added) {
            Face f;
            f.normal = n;
            f.offset = offset;
            const Material& m = materials[group[i]];
            f.diffuse = m.diffuse;
            f.emission = m.emission;
            f.specular = m.specular;
            f.phongExponent = m.phongExponent;
            const SubfieldFrame frame = makeSubfieldFrame(n);
            f.axisU = frame.u;
            f.axisV = frame.v;
            mFaces.push_back(f);
            mFaceGroups.push_back(group[i]);
        }
        t.face = it->second;
        mFaces[t.face].triangles.push_back(std::uint32_t(mTriangles.size()));
        mFaces[t.face].area += 0.5f * len;
        mTriangles.push_back(t);
    }
    if (mTriangles.empty()) fail("VlfScene: the scene has no static triangles to bake");
    for (Face& f : mFaces) {
        glm::vec2 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
        for (std::uint32_t ti : f.triangles)
            for (const glm::vec3& p : {mTriangles[ti].p0, mTriangles[ti].p1, mTriangles[ti].p2}) {
                const glm::vec2 q(glm::dot(p, f.axisU), glm::dot(p, f.axisV));
                lo = glm::min(lo, q);
                hi = glm::max(hi, q);
            }
        f.origin = lo.x * f.axisU + lo.y * f.axisV + f.offset * f.normal;
        f.extentU = hi.x - lo.x;
        f.extentV = hi.y - lo.y;
    }
    for (const Triangle& t : mTriangles) {
        mBounds.extend(t.p0);
        mBounds.extend(t.p1);
        mBounds.extend(t.p2);
    }
    Fnv1aHasher h;
    for (const Triangle& t : mTriangles)
        h.add(t);
    for (const Face& f : mFaces) {
        h.add(f.diffuse);
        h.add(f.emission);
        h.add(f.specular);
        h.add(f.phongExponent);
        h.add(std::uint64_t(f.triangles.size()));
    }
    for (const PunctualLight& l : mLights)
        h.add(l);
    h.add(mEnvironment);
    mHash = h.value();
    if (traced) buildEmbree();
}

void VlfScene::buildEmbree() {
    // The device may be the RayScene's: earlier errors were logged; this build reports its own,
    // and leaves none pending for the next user of the device.
    mDevice->takeError();
    const RTCDevice device = mDevice->handle();
    GeometryHandle geometry(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE));
    auto* vertices = static_cast<glm::vec3*>(
        rtcSetNewGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                sizeof(glm::vec3), mTriangles.size() * 3));
    auto* indices = static_cast<std::uint32_t*>(
        rtcSetNewGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(std::uint32_t), mTriangles.size()));
    if (!vertices || !indices) fail("VlfScene: Embree could not allocate its buffers");
    for (std::size_t i = 0; i < mTriangles.size(); ++i) {
        vertices[3 * i] = mTriangles[i].p0;
        vertices[3 * i + 1] = mTriangles[i].p1;
        vertices[3 * i + 2] = mTriangles[i].p2;
        for (int k = 0; k < 3; ++k)
            indices[3 * i + k] = std::uint32_t(3 * i + k);
    }
    rtcCommitGeometry(geometry.get());
    mScene = SceneHandle(rtcNewScene(device));
    rtcSetSceneFlags(mScene.get(), RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(mScene.get(), RTC_BUILD_QUALITY_HIGH);
    rtcAttachGeometry(mScene.get(), geometry.get());
    rtcCommitScene(mScene.get());
    if (const auto error = mDevice->takeError())
        fail("VlfScene: Embree could not build the bake's scene: ", error->message);
}

namespace {

/// Distance from p to triangle (a, b, c), metres (0 on it).
float distanceToTriangle(const glm::vec3& p, const glm::vec3& a, const glm::vec3& b,
                         const glm::vec3& c) {
    const glm::vec3 n = glm::cross(b - a, c - a);
    const float n2 = glm::dot(n, n);
    if (!(n2 > 0.f)) return std::numeric_limits<float>::max();
    // Inside the prism over the triangle: the distance to its plane.
    if (glm::dot(glm::cross(b - a, p - a), n) >= 0.f &&
        glm::dot(glm::cross(c - b, p - b), n) >= 0.f &&
        glm::dot(glm::cross(a - c, p - c), n) >= 0.f)
        return std::abs(glm::dot(p - a, n)) / std::sqrt(n2);
    // Otherwise the nearest point lies on an edge.
    return std::min(
        {distanceToSegment(p, a, b), distanceToSegment(p, b, c), distanceToSegment(p, c, a)});
}

} // namespace

std::optional<std::uint32_t> VlfScene::faceAt(const glm::vec3& x, const glm::vec3& n,
                                              float tolerance) const {
    std::optional<std::uint32_t> best;
    float bestDistance = tolerance;
    for (std::uint32_t f = 0; f < mFaces.size(); ++f) {
        const Face& face = mFaces[f];
        if (glm::dot(face.normal, n) < 0.99f) continue;
        if (std::abs(glm::dot(face.normal, x) - face.offset) > bestDistance) continue;
        for (std::uint32_t ti : face.triangles) {
            const Triangle& t = mTriangles[ti];
            const float d = distanceToTriangle(x, t.p0, t.p1, t.p2);
            if (d <= bestDistance) {
                bestDistance = d;
                best = f;
                if (d == 0.f) return best;
            }
        }
    }
    return best;
}

Crossing VlfScene::firstHit(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh{};
    rh.ray.org_x = o.x;
    rh.ray.org_y = o.y;
    rh.ray.org_z = o.z;
    rh.ray.dir_x = d.x;
    rh.ray.dir_y = d.y;
    rh.ray.dir_z = d.z;
    rh.ray.tnear = tMin;
    rh.ray.tfar = tMax;
    rh.ray.mask = ~0u;
    rh.ray.flags = 0;
    rh.ray.time = 0.f;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(mScene.get(), &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return {0.f, UINT32_MAX};
    return {rh.ray.tfar, mTriangles[rh.hit.primID].face};
}

std::size_t VlfScene::crossings(const glm::vec3& o, const glm::vec3& d, float tMax, Crossing* out,
                                std::size_t maxCrossings, float merge) const {
    std::size_t count = 0;
    float tMin = 0.f;
    // Bounded: every step advances by at least `merge`, so a line cannot loop forever.
    while (count < maxCrossings) {
        const Crossing c = firstHit(o, d, tMin, tMax);
        if (c.face == UINT32_MAX) break;
        if (count == 0 || c.t - out[count - 1].t >= merge || c.face != out[count - 1].face)
            out[count++] = c;
        tMin = c.t + merge;
    }
    return count;
}

bool VlfScene::occludedRay(const glm::vec3& origin, const glm::vec3& dir, float tNear,
                           float tFar) const {
    QGI_ASSERT(mScene.get(), "a VlfScene made without rays is not traced");
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRay ray{};
    ray.org_x = origin.x;
    ray.org_y = origin.y;
    ray.org_z = origin.z;
    ray.dir_x = dir.x;
    ray.dir_y = dir.y;
    ray.dir_z = dir.z;
    ray.tnear = tNear;
    ray.tfar = tFar;
    ray.mask = ~0u;
    rtcOccluded1(mScene.get(), &context, &ray);
    return ray.tfar < 0.f;
}

bool VlfScene::occluded(const glm::vec3& origin, const glm::vec3& dir, float tFar) const {
    return occludedRay(origin, dir, 0.f, tFar);
}

bool VlfScene::occluded(const glm::vec3& a, const glm::vec3& b) const {
    const glm::vec3 d = b - a;
    const float len = glm::length(d);
    if (!(len > 0.f)) return false;
    return occludedRay(a, d / len, 1e-4f * len, len * (1.f - 1e-4f));
}

} // namespace qgi::vlf
