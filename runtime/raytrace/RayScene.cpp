#include "runtime/raytrace/RayScene.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Finite.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/Pose.h"

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>
#include <glm/vector_relational.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

namespace qgi {
namespace {

// Top-level instance IDs: the static world is 0, mobile i is i + 1.
constexpr unsigned kStaticInstance = 0;
constexpr std::size_t kPacketSize = 8;

static_assert(alignof(RTCRayHit8) >= 32, "RTCRayHit8 must be 32-byte aligned (DEPENDENCY-FACTS)");

std::string describe(const Registry& registry, Entity e, const char* kind) {
    std::string out = str("RayScene: ", kind, " entity ", e.index);
    if (const Name* name = registry.tryGet<Name>(e)) out += str(" '", name->value, "'");
    return out;
}

/// The Mesh and world matrix of a mesh entity, checked so Embree only ever sees finite
/// triangles with valid indices.
struct CheckedMesh {
    const Mesh& mesh;
    const glm::mat4& world;
};

CheckedMesh checkedMesh(const Registry& registry, Entity e, const char* kind) {
    const Mesh* mesh = registry.tryGet<Mesh>(e);
    const WorldTransform* world = registry.tryGet<WorldTransform>(e);
    if (!mesh) fail(describe(registry, e, kind), ": has no Mesh");
    if (!world)
        fail(describe(registry, e, kind),
             ": has no WorldTransform (run the transform system first)");
    if (!isFinite(world->matrix))
        fail(describe(registry, e, kind), ": WorldTransform.matrix is not finite");
    if (mesh->indices.size() % 3 != 0)
        fail(describe(registry, e, kind), ": Mesh.indices has ", mesh->indices.size(),
             " entries, not a multiple of 3");
    for (std::size_t i = 0; i < mesh->positions.size(); ++i)
        if (!isFinite(mesh->positions[i]))
            fail(describe(registry, e, kind), ": Mesh.positions[", i, "] is not finite");
    for (std::size_t i = 0; i < mesh->indices.size(); ++i)
        if (mesh->indices[i] >= mesh->positions.size())
            fail(describe(registry, e, kind), ": Mesh.indices[", i, "] = ", mesh->indices[i],
                 " is out of range (", mesh->positions.size(), " positions)");
    return {*mesh, world->matrix};
}

/// A committed triangle geometry holding `mesh` transformed by `toScene`.
GeometryHandle newTriangles(RTCDevice device, const Mesh& mesh, const glm::mat4& toScene,
                            const std::string& who) {
    GeometryHandle geometry(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE));
    auto* vertices = static_cast<glm::vec3*>(
        rtcSetNewGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                sizeof(glm::vec3), mesh.positions.size()));
    auto* triangles = static_cast<std::uint32_t*>(
        rtcSetNewGeometryBuffer(geometry.get(), RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(std::uint32_t), mesh.indices.size() / 3));
    if (!vertices || !triangles) fail(who, ": Embree could not allocate its buffers");
    for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
        vertices[i] = glm::vec3(toScene * glm::vec4(mesh.positions[i], 1.f));
        if (!isFinite(vertices[i]) ||
            glm::any(glm::greaterThan(glm::abs(vertices[i]), glm::vec3(kMaxPoseReach))))
            fail(who, ": Mesh.positions[", i, "] is not finite or lies farther than ",
                 kMaxPoseReach, " m from the origin");
    }
    std::copy(mesh.indices.begin(), mesh.indices.end(), triangles);
    rtcCommitGeometry(geometry.get());
    return geometry;
}

GeometryHandle newInstance(RTCDevice device, RTCScene scene, const glm::mat4& pose) {
    GeometryHandle instance(rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE));
    rtcSetGeometryInstancedScene(instance.get(), scene);
    rtcSetGeometryTransform(instance.get(), 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &pose[0][0]);
    rtcCommitGeometry(instance.get());
    return instance;
}

RTCRayHit toEmbree(const Ray& ray) {
    RTCRayHit rh;
    rh.ray.org_x = ray.origin.x;
    rh.ray.org_y = ray.origin.y;
    rh.ray.org_z = ray.origin.z;
    rh.ray.tnear = ray.tnear;
    rh.ray.dir_x = ray.direction.x;
    rh.ray.dir_y = ray.direction.y;
    rh.ray.dir_z = ray.direction.z;
    rh.ray.time = 0.f;
    rh.ray.tfar = ray.tfar;
    rh.ray.mask = ~0u;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    return rh;
}

/// Fills the first rays.size() lanes of an 8-wide packet and marks them valid.
void toEmbree(std::span<const Ray> rays, RTCRay8& packet, std::array<int, 8>& valid) {
    for (std::size_t i = 0; i < kPacketSize; ++i) {
        valid[i] = i < rays.size() ? -1 : 0;
        const Ray& ray = rays[std::min(i, rays.size() - 1)]; // idle lanes repeat the last ray
        packet.org_x[i] = ray.origin.x;
        packet.org_y[i] = ray.origin.y;
        packet.org_z[i] = ray.origin.z;
        packet.tnear[i] = ray.tnear;
        packet.dir_x[i] = ray.direction.x;
        packet.dir_y[i] = ray.direction.y;
        packet.dir_z[i] = ray.direction.z;
        packet.time[i] = 0.f;
        packet.tfar[i] = ray.tfar;
        packet.mask[i] = ~0u;
        packet.id[i] = 0;
        packet.flags[i] = 0;
    }
}

RTCIntersectContext newContext() {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    return context;
}

} // namespace

struct RayScene::FilterContext {
    RTCIntersectContext embree; // first: Embree hands the filter a pointer to it
    const RayScene* scene;
    AcceptFn accept;
    void* user;
};

RayScene::RayScene(const RaySceneSettings& settings)
    : mSettings(settings), mDevice(settings.deviceConfig) {
    // An empty committed top level: queries before build() miss instead of failing.
    mTop = newScene(RTC_BUILD_QUALITY_LOW, RTC_SCENE_FLAG_DYNAMIC);
    rtcCommitScene(mTop.get());
}

SceneHandle RayScene::newScene(RTCBuildQuality quality, RTCSceneFlags extraFlags) const {
    // Filtered queries need the flag on every scene, instanced ones included, or Embree
    // aborts; it costs no measurable throughput.
    int flags = RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION | extraFlags;
    if (mSettings.robust) flags |= RTC_SCENE_FLAG_ROBUST;
    SceneHandle scene(rtcNewScene(mDevice.handle()));
    rtcSetSceneFlags(scene.get(), RTCSceneFlags(flags));
    rtcSetSceneBuildQuality(scene.get(), quality);
    return scene;
}

void RayScene::build(const Registry& registry) {
    mDevice.takeError(); // earlier errors were logged; this build reports only its own
    const RTCDevice device = mDevice.handle();

    // Everything is built into locals first, so a failure leaves the previous scene intact.
    SceneHandle staticScene = newScene(mSettings.buildQuality, RTC_SCENE_FLAG_NONE);
    std::vector<StaticGeometry> staticGeometries;
    std::size_t staticTriangles = 0;
    registry.view<const StaticMesh>().each([&](Entity e, const StaticMesh&) {
        if (registry.has<MobileMesh>(e))
            fail(describe(registry, e, "StaticMesh"), ": is also tagged MobileMesh");
        const CheckedMesh checked = checkedMesh(registry, e, "StaticMesh");
        if (checked.mesh.indices.empty()) return;
        const GeometryHandle geometry =
            newTriangles(device, checked.mesh, checked.world, describe(registry, e, "StaticMesh"));
        rtcAttachGeometryByID(staticScene.get(), geometry.get(), unsigned(staticGeometries.size()));
        // A mirroring matrix flips the winding of the world-space triangles, and with it
        // Embree's normal; the sign restores the object's front side.
        const bool mirrored = glm::determinant(glm::mat3(checked.world)) < 0.f;
        staticGeometries.push_back({e, mirrored ? -1.f : 1.f});
        staticTriangles += checked.mesh.indices.size() / 3;
    });
    rtcCommitScene(staticScene.get());

    SceneHandle top = newScene(RTC_BUILD_QUALITY_LOW, RTC_SCENE_FLAG_DYNAMIC);
    if (!staticGeometries.empty()) {
        const GeometryHandle instance = newInstance(device, staticScene.get(), glm::mat4(1.f));
        rtcAttachGeometryByID(top.get(), instance.get(), kStaticInstance);
    }

    std::vector<Mobile> mobiles;
    std::unordered_map<Entity, std::uint32_t> mobileIndex;
    registry.view<const MobileMesh>().each([&](Entity e, const MobileMesh&) {
        const CheckedMesh checked = checkedMesh(registry, e, "MobileMesh");
        if (checked.mesh.indices.empty()) return;
        std::string who = describe(registry, e, "MobileMesh");
        if (!isUsablePose(checked.world))
            fail(who, ": WorldTransform.matrix is not invertible or reaches past ", kMaxPoseReach,
                 " m");
        Mobile mobile{e,
                      newScene(mSettings.buildQuality, RTC_SCENE_FLAG_NONE),
                      {},
                      checked.world,
                      glm::transpose(glm::inverse(glm::mat3(checked.world))),
                      std::move(who)};
        const GeometryHandle geometry =
            newTriangles(device, checked.mesh, glm::mat4(1.f), mobile.who);
        rtcAttachGeometryByID(mobile.scene.get(), geometry.get(), 0);
        rtcCommitScene(mobile.scene.get());
        mobile.instance = newInstance(device, mobile.scene.get(), checked.world);
        activateMobile(mobile, registry.get<MobileMesh>(e).active);
        const auto index = std::uint32_t(mobiles.size());
        rtcAttachGeometryByID(top.get(), mobile.instance.get(), kStaticInstance + 1 + index);
        mobileIndex.emplace(e, index);
        mobiles.push_back(std::move(mobile));
    });
    rtcCommitScene(top.get());

    if (const auto error = mDevice.takeError())
        fail("RayScene: Embree failed to build the scene: ", error->message);

    mTop = std::move(top);
    mStatic = std::move(staticScene);
    mStaticGeometries = std::move(staticGeometries);
    mMobiles = std::move(mobiles);
    mMobileIndex = std::move(mobileIndex);
    mStaticTriangleCount = staticTriangles;
    logInfo("RayScene: ", mStaticTriangleCount, " static triangles in ", mStaticGeometries.size(),
            " meshes, ", mMobiles.size(), " mobiles");
}

bool RayScene::placeMobile(Mobile& mobile, const glm::mat4& pose) {
    if (!isUsablePose(pose)) {
        logWarning(mobile.who,
                   ": ignoring a pose that is not finite and invertible or reaches "
                   "past ",
                   kMaxPoseReach, " m; it stays where it was");
        return false;
    }
    rtcSetGeometryTransform(mobile.instance.get(), 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR,
                            &pose[0][0]);
    rtcCommitGeometry(mobile.instance.get());
    mobile.pose = pose;
    mobile.normalMatrix = glm::transpose(glm::inverse(glm::mat3(pose)));
    return true;
}

std::size_t RayScene::syncMoved(const Registry& registry) {
    std::size_t moved = 0;
    for (const Entity e : registry.changed<WorldTransform>()) {
        const auto it = mMobileIndex.find(e);
        if (it == mMobileIndex.end()) continue;
        const WorldTransform* world = registry.tryGet<WorldTransform>(e);
        if (world && placeMobile(mMobiles[it->second], world->matrix)) ++moved;
    }
    for (const Entity e : registry.changed<MobileMesh>()) {
        const auto it = mMobileIndex.find(e);
        const MobileMesh* mobile = registry.tryGet<MobileMesh>(e);
        if (it != mMobileIndex.end() && mobile &&
            activateMobile(mMobiles[it->second], mobile->active))
            ++moved;
    }
    if (moved > 0) rtcCommitScene(mTop.get());
    return moved;
}

bool RayScene::activateMobile(Mobile& mobile, bool active) {
    if (mobile.active == active) return false;
    if (active)
        rtcEnableGeometry(mobile.instance.get());
    else
        rtcDisableGeometry(mobile.instance.get());
    mobile.active = active;
    return true;
}

bool RayScene::setMobilePose(Entity mobile, const glm::mat4& pose) {
    const auto it = mMobileIndex.find(mobile);
    if (it == mMobileIndex.end() || !placeMobile(mMobiles[it->second], pose)) return false;
    rtcCommitScene(mTop.get());
    return true;
}

const RayScene::Mobile& RayScene::mobileOf(Entity entity) const {
    const auto it = mMobileIndex.find(entity);
    QGI_ASSERT(it != mMobileIndex.end(), "entity ", entity.index,
               " is not a mobile of the ray scene");
    return mMobiles[it->second];
}

const glm::mat4& RayScene::mobilePose(Entity mobile) const {
    return mobileOf(mobile).pose;
}

bool RayScene::mobileActive(Entity mobile) const {
    return mobileOf(mobile).active;
}

Hit RayScene::makeHit(const RTCHit& hit, float t) const {
    Hit out;
    out.t = t;
    out.primitive = hit.primID;
    out.barycentrics = {hit.u, hit.v};
    const glm::vec3 ng(hit.Ng_x, hit.Ng_y, hit.Ng_z);
    if (hit.instID[0] == kStaticInstance) {
        const StaticGeometry& geometry = mStaticGeometries[hit.geomID];
        out.entity = geometry.entity;
        out.normal = geometry.normalSign * glm::normalize(ng);
    } else {
        // Embree reports an instance's Ng in object space, unnormalised.
        const Mobile& mobile = mMobiles[hit.instID[0] - kStaticInstance - 1];
        out.entity = mobile.entity;
        out.normal = glm::normalize(mobile.normalMatrix * ng);
    }
    return out;
}

std::optional<Hit> RayScene::intersect(const Ray& ray) const {
    RTCIntersectContext context = newContext();
    RTCRayHit rh = toEmbree(ray);
    rtcIntersect1(mTop.get(), &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
    return makeHit(rh.hit, rh.ray.tfar);
}

bool RayScene::occluded(const Ray& ray) const {
    RTCIntersectContext context = newContext();
    RTCRayHit rh = toEmbree(ray);
    rtcOccluded1(mTop.get(), &context, &rh.ray);
    return rh.ray.tfar < 0.f; // Embree sets tfar to -inf on a hit
}

void RayScene::intersect(std::span<const Ray> rays, std::span<std::optional<Hit>> hits) const {
    QGI_ASSERT(hits.size() == rays.size(), "one hit slot per ray");
    RTCIntersectContext context = newContext();
    for (std::size_t first = 0; first < rays.size(); first += kPacketSize) {
        const std::size_t count = std::min(kPacketSize, rays.size() - first);
        RTCRayHit8 packet;
        alignas(32) std::array<int, 8> valid;
        toEmbree(rays.subspan(first, count), packet.ray, valid);
        std::fill(std::begin(packet.hit.geomID), std::end(packet.hit.geomID),
                  RTC_INVALID_GEOMETRY_ID);
        rtcIntersect8(valid.data(), mTop.get(), &context, &packet);
        for (std::size_t i = 0; i < count; ++i) {
            if (packet.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) {
                hits[first + i].reset();
                continue;
            }
            RTCHit hit;
            hit.Ng_x = packet.hit.Ng_x[i];
            hit.Ng_y = packet.hit.Ng_y[i];
            hit.Ng_z = packet.hit.Ng_z[i];
            hit.u = packet.hit.u[i];
            hit.v = packet.hit.v[i];
            hit.primID = packet.hit.primID[i];
            hit.geomID = packet.hit.geomID[i];
            hit.instID[0] = packet.hit.instID[0][i];
            hits[first + i] = makeHit(hit, packet.ray.tfar[i]);
        }
    }
}

void RayScene::occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const {
    QGI_ASSERT(occluded.size() == rays.size(), "one result slot per ray");
    RTCIntersectContext context = newContext();
    for (std::size_t first = 0; first < rays.size(); first += kPacketSize) {
        const std::size_t count = std::min(kPacketSize, rays.size() - first);
        RTCRay8 packet;
        alignas(32) std::array<int, 8> valid;
        toEmbree(rays.subspan(first, count), packet, valid);
        rtcOccluded8(valid.data(), mTop.get(), &context, &packet);
        for (std::size_t i = 0; i < count; ++i)
            occluded[first + i] = packet.tfar[i] < 0.f ? 1 : 0;
    }
}

void RayScene::filterCandidates(const RTCFilterFunctionNArguments* args) {
    const auto* context = reinterpret_cast<const FilterContext*>(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        RTCHit hit;
        hit.Ng_x = RTCHitN_Ng_x(args->hit, args->N, i);
        hit.Ng_y = RTCHitN_Ng_y(args->hit, args->N, i);
        hit.Ng_z = RTCHitN_Ng_z(args->hit, args->N, i);
        hit.u = RTCHitN_u(args->hit, args->N, i);
        hit.v = RTCHitN_v(args->hit, args->N, i);
        hit.primID = RTCHitN_primID(args->hit, args->N, i);
        hit.geomID = RTCHitN_geomID(args->hit, args->N, i);
        hit.instID[0] = RTCHitN_instID(args->hit, args->N, i, 0);
        // The candidate's distance is in the ray's tfar while the filter runs.
        const Hit candidate = context->scene->makeHit(hit, RTCRayN_tfar(args->ray, args->N, i));
        if (!context->accept(context->user, candidate)) args->valid[i] = 0;
    }
}

std::optional<Hit> RayScene::intersectWithFilter(const Ray& ray, AcceptFn accept,
                                                 void* user) const {
    FilterContext context{newContext(), this, accept, user};
    context.embree.filter = &RayScene::filterCandidates;
    RTCRayHit rh = toEmbree(ray);
    rtcIntersect1(mTop.get(), &context.embree, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
    return makeHit(rh.hit, rh.ray.tfar);
}

bool RayScene::occludedWithFilter(const Ray& ray, AcceptFn accept, void* user) const {
    FilterContext context{newContext(), this, accept, user};
    context.embree.filter = &RayScene::filterCandidates;
    RTCRayHit rh = toEmbree(ray);
    rtcOccluded1(mTop.get(), &context.embree, &rh.ray);
    return rh.ray.tfar < 0.f;
}

std::optional<Hit> RayScene::intersectMobile(Entity mobile, const glm::mat4& pose,
                                             const Ray& ray) const {
    if (!isUsablePose(pose)) return std::nullopt;
    // An affine map keeps the ray parameter: trace the object-space ray, keep t as it is.
    const glm::mat4 toObject = glm::inverse(pose);
    Ray local = ray;
    local.origin = glm::vec3(toObject * glm::vec4(ray.origin, 1.f));
    local.direction = glm::mat3(toObject) * ray.direction;
    return intersectMobileLocal(mobile, toObject, local);
}

std::optional<Hit> RayScene::intersectMobileLocal(Entity mobile, const glm::mat4& toObject,
                                                  const Ray& objectRay) const {
    const Mobile& m = mobileOf(mobile);
    RTCIntersectContext context = newContext();
    RTCRayHit rh = toEmbree(objectRay);
    rtcIntersect1(m.scene.get(), &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
    Hit hit;
    hit.t = rh.ray.tfar;
    hit.entity = mobile;
    hit.primitive = rh.hit.primID;
    hit.barycentrics = {rh.hit.u, rh.hit.v};
    hit.normal = glm::normalize(glm::transpose(glm::mat3(toObject)) *
                                glm::vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z));
    return hit;
}

bool RayScene::occludedByMobile(Entity mobile, const Ray& objectRay) const {
    RTCIntersectContext context = newContext();
    RTCRayHit rh = toEmbree(objectRay);
    rtcOccluded1(mobileOf(mobile).scene.get(), &context, &rh.ray);
    return rh.ray.tfar < 0.f; // Embree sets tfar to -inf on a hit
}

} // namespace qgi
