#include "systems/detp/ReceiverSet.h"

#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/Pose.h"

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

namespace qgi {
namespace {

bool isFinite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

std::string describe(const Registry& registry, Entity e, bool mobile) {
    std::string out = str("DETP: ", mobile ? "MobileMesh" : "StaticMesh", " entity ", e.index);
    if (const Name* name = registry.tryGet<Name>(e)) out += str(" '", name->value, "'");
    return out;
}

glm::mat3 normalMatrix(const glm::mat4& pose) {
    return glm::transpose(glm::inverse(glm::mat3(pose)));
}

float triangleArea(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
    return 0.5f * glm::length(glm::cross(b - a, c - a));
}

/// The Mesh of a receiver, checked so every estimator can rely on it.
const Mesh& checkedMesh(const Registry& registry, Entity e, bool mobile) {
    const std::string who = describe(registry, e, mobile);
    const Mesh* mesh = registry.tryGet<Mesh>(e);
    if (!mesh) fail(who, ": has no Mesh");
    const WorldTransform* world = registry.tryGet<WorldTransform>(e);
    if (!world) fail(who, ": has no WorldTransform (run the transform system first)");
    if (!isUsablePose(world->matrix))
        fail(who, ": WorldTransform.matrix is not finite and invertible, or reaches past ",
             kMaxPoseReach, " m");
    if (mesh->normals.size() != mesh->positions.size())
        fail(who, ": Mesh.normals has ", mesh->normals.size(), " entries for ",
             mesh->positions.size(), " positions");
    for (std::size_t i = 0; i < mesh->positions.size(); ++i) {
        if (!isFinite(mesh->positions[i])) fail(who, ": Mesh.positions[", i, "] is not finite");
        const float length = glm::length(mesh->normals[i]);
        if (!std::isfinite(length) || length == 0.f)
            fail(who, ": Mesh.normals[", i, "] is zero or not finite");
    }
    if (mesh->indices.size() % 3 != 0)
        fail(who, ": Mesh.indices has ", mesh->indices.size(), " entries, not a multiple of 3");
    for (std::size_t i = 0; i < mesh->indices.size(); ++i)
        if (mesh->indices[i] >= mesh->positions.size())
            fail(who, ": Mesh.indices[", i, "] = ", mesh->indices[i], " is out of range (",
                 mesh->positions.size(), " positions)");
    return *mesh;
}

/// Whether every tangent plane (position, normal) has every position behind it, within
/// ReceiverSet::kConvexTolerance of the positions' bounding diagonal.
bool tangentPlanesSupport(std::span<const glm::vec3> positions,
                          std::span<const glm::vec3> normals) {
    if (positions.empty()) return false;
    // Vertices with the same normal (bit for bit) share one test: every position behind the
    // plane of the one lowest along it. A box of any refinement has a few distinct normals.
    using Bits = std::array<std::uint32_t, 3>;
    const auto bits = [&](std::uint32_t v) { return std::bit_cast<Bits>(normals[v]); };
    std::vector<std::uint32_t> order(positions.size());
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(),
              [&](std::uint32_t a, std::uint32_t b) { return bits(a) < bits(b); });
    std::vector<std::uint32_t> groupStart;
    for (std::size_t i = 0; i < order.size(); ++i)
        if (i == 0 || bits(order[i]) != bits(order[i - 1])) groupStart.push_back(std::uint32_t(i));
    if (groupStart.size() * positions.size() > ReceiverSet::kConvexCheckPairs) return false;
    groupStart.push_back(std::uint32_t(order.size()));

    Aabb bounds;
    for (const glm::vec3& p : positions)
        bounds.extend(p);
    const float tolerance = ReceiverSet::kConvexTolerance * glm::length(bounds.extent());
    // About the mesh's centre, so a mesh modelled far from its own origin keeps its precision.
    const glm::vec3 centre = bounds.center();
    for (std::size_t g = 0; g + 1 < groupStart.size(); ++g) {
        const glm::vec3 n = glm::normalize(normals[order[groupStart[g]]]);
        float plane = std::numeric_limits<float>::infinity();
        for (std::uint32_t i = groupStart[g]; i < groupStart[g + 1]; ++i)
            plane = std::min(plane, glm::dot(n, positions[order[i]] - centre) + tolerance);
        for (const glm::vec3& p : positions)
            if (glm::dot(n, p - centre) > plane) return false;
    }
    return true;
}

/// A mesh whose vertex normals point against the winding of most of its triangles was most
/// likely exported with flipped normals: its discs face away from the side its faces show,
/// so it reads dark. Named in a warning (the normals are used as they are).
void warnIfNormalsOppose(const Registry& registry, Entity e, bool mobile, const Mesh& mesh) {
    std::size_t faces = 0, opposed = 0;
    for (std::size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
        const std::uint32_t a = mesh.indices[t], b = mesh.indices[t + 1], c = mesh.indices[t + 2];
        const glm::vec3 n = glm::cross(mesh.positions[b] - mesh.positions[a],
                                       mesh.positions[c] - mesh.positions[a]);
        const float side = glm::dot(n, mesh.normals[a] + mesh.normals[b] + mesh.normals[c]);
        if (side == 0.f || !std::isfinite(side)) continue;
        ++faces;
        opposed += side < 0.f ? 1 : 0;
    }
    if (2 * opposed > faces)
        logWarning(describe(registry, e, mobile), ": Mesh.normals point against the winding of ",
                   opposed, " of its ", faces,
                   " triangles (flipped normals?); its vertices are "
                   "lit from the side the normals face");
}

} // namespace

void ReceiverSet::build(Registry& registry) {
    const std::vector<Entity> statics = registry.view<const StaticMesh>().entities();
    const std::vector<Entity> mobiles = registry.view<const MobileMesh>().entities();
    for (const Entity e : statics)
        if (registry.has<MobileMesh>(e))
            fail(describe(registry, e, false), ": is also tagged MobileMesh");

    // Everything goes into a fresh set, so a failure leaves this one as it was.
    ReceiverSet set;
    std::size_t vertexTotal = 0, triangleTotal = 0;
    for (const bool mobile : {false, true}) {
        for (const Entity e : mobile ? mobiles : statics) {
            const Mesh& mesh = checkedMesh(registry, e, mobile);
            vertexTotal += mesh.positions.size();
            triangleTotal += mesh.indices.size() / 3;
            if (vertexTotal >= std::numeric_limits<std::uint32_t>::max() ||
                triangleTotal >= std::numeric_limits<std::uint32_t>::max())
                fail(describe(registry, e, mobile), ": more than 2^32 vertices or triangles");
            Receiver receiver;
            receiver.entity = e;
            receiver.mobile = mobile;
            receiver.firstVertex = std::uint32_t(set.mPositions.size());
            receiver.vertexCount = std::uint32_t(mesh.positions.size());
            receiver.firstTriangle = std::uint32_t(set.mTriangles.size());
            receiver.triangleCount = std::uint32_t(mesh.indices.size() / 3);
            receiver.convex = mobile && tangentPlanesSupport(mesh.positions, mesh.normals);
            warnIfNormalsOppose(registry, e, mobile, mesh);
            if (!mobile) set.mStaticVertexCount += receiver.vertexCount;
            set.mPositions.insert(set.mPositions.end(), mesh.positions.begin(),
                                  mesh.positions.end());
            set.mNormals.insert(set.mNormals.end(), mesh.normals.begin(), mesh.normals.end());
            if (mobile) {
                set.mLocalPositions.insert(set.mLocalPositions.end(), mesh.positions.begin(),
                                           mesh.positions.end());
                set.mLocalNormals.insert(set.mLocalNormals.end(), mesh.normals.begin(),
                                         mesh.normals.end());
            }
            for (std::size_t t = 0; t < receiver.triangleCount; ++t)
                set.mTriangles.push_back(glm::uvec3(mesh.indices[3 * t], mesh.indices[3 * t + 1],
                                                    mesh.indices[3 * t + 2]) +
                                         receiver.firstVertex);
            set.mTriangleAreas.resize(set.mTriangles.size());
            set.mIndex.emplace(e, std::uint32_t(set.mReceivers.size()));
            set.mReceivers.push_back(receiver);
            set.placeReceiver(std::uint32_t(set.mReceivers.size() - 1),
                              registry.get<WorldTransform>(e).matrix);
            // A normal that a valid matrix maps to zero cannot happen; one that underflows can.
            for (std::uint32_t v = receiver.firstVertex; v < set.mNormals.size(); ++v)
                if (!isFinite(set.mNormals[v]))
                    fail(describe(registry, e, mobile), ": Mesh.normals[", v - receiver.firstVertex,
                         "] has no world-space direction");
        }
    }

    for (const Receiver& receiver : set.mReceivers) {
        auto* out = registry.tryGet<VertexIrradiance>(receiver.entity);
        if (!out) out = &registry.emplace<VertexIrradiance>(receiver.entity);
        out->irradiance.assign(receiver.vertexCount, glm::vec3(0.f));
        out->dirty.push_back({0, receiver.vertexCount});
    }
    *this = std::move(set);
}

void ReceiverSet::placeReceiver(std::uint32_t index, const glm::mat4& pose) {
    Receiver& receiver = mReceivers[index];
    receiver.pose = pose;
    const glm::mat3 toWorldNormal = normalMatrix(pose);
    const std::uint32_t local = receiver.mobile ? mStaticVertexCount : 0;
    // Static receivers are placed once, from the Mesh copy already in the world arrays.
    const glm::vec3* positions = receiver.mobile ? &mLocalPositions[receiver.firstVertex - local]
                                                 : &mPositions[receiver.firstVertex];
    const glm::vec3* normals = receiver.mobile ? &mLocalNormals[receiver.firstVertex - local]
                                               : &mNormals[receiver.firstVertex];
    receiver.bounds = Aabb{};
    for (std::uint32_t i = 0; i < receiver.vertexCount; ++i) {
        const std::uint32_t v = receiver.firstVertex + i;
        mPositions[v] = glm::vec3(pose * glm::vec4(positions[i], 1.f));
        mNormals[v] = glm::normalize(toWorldNormal * normals[i]);
        receiver.bounds.extend(mPositions[v]);
    }
    for (std::uint32_t t = receiver.firstTriangle;
         t < receiver.firstTriangle + receiver.triangleCount; ++t) {
        const glm::uvec3& c = mTriangles[t];
        mTriangleAreas[t] = triangleArea(mPositions[c.x], mPositions[c.y], mPositions[c.z]);
    }
}

bool ReceiverSet::refreshPose(const Registry& registry, std::uint32_t receiver) {
    QGI_ASSERT(mReceivers[receiver].mobile, "only mobiles move");
    const WorldTransform* world = registry.tryGet<WorldTransform>(mReceivers[receiver].entity);
    if (!world || !isUsablePose(world->matrix)) return false;
    placeReceiver(receiver, world->matrix);
    return true;
}

std::int64_t ReceiverSet::find(Entity entity) const {
    const auto it = mIndex.find(entity);
    return it == mIndex.end() ? -1 : std::int64_t(it->second);
}

void ReceiverSet::publish(Registry& registry, std::span<const glm::vec3> irradiance,
                          std::span<const std::uint32_t> sortedVertices) const {
    std::size_t r = 0;
    VertexIrradiance* out = nullptr;
    std::size_t outReceiver = mReceivers.size(); // the receiver `out` belongs to
    for (const std::uint32_t v : sortedVertices) {
        while (v >= mReceivers[r].firstVertex + mReceivers[r].vertexCount)
            ++r;
        if (r != outReceiver) {
            out = registry.tryGet<VertexIrradiance>(mReceivers[r].entity);
            outReceiver = r;
        }
        const std::uint32_t local = v - mReceivers[r].firstVertex;
        if (!out || local >= out->irradiance.size()) continue; // removed since build()
        out->irradiance[local] = irradiance[v];
        if (!out->dirty.empty() && out->dirty.back().end == local)
            out->dirty.back().end = local + 1;
        else
            out->dirty.push_back({local, local + 1});
    }
}

void ReceiverSet::publishReceiver(Registry& registry, std::span<const glm::vec3> irradiance,
                                  std::uint32_t index) const {
    const Receiver& receiver = mReceivers[index];
    auto* out = registry.tryGet<VertexIrradiance>(receiver.entity);
    if (!out || out->irradiance.size() != receiver.vertexCount) return; // changed since build()
    std::copy_n(irradiance.begin() + receiver.firstVertex, receiver.vertexCount,
                out->irradiance.begin());
    out->dirty.push_back({0, receiver.vertexCount});
}

} // namespace qgi
