#include "systems/detp/ImpactCounter.h"

#include "runtime/core/Error.h"
#include "systems/detp/ReceiverSet.h"
#include "systems/photon_update/PhotonStore.h"

#include <algorithm>

namespace qgi {

void ImpactCounter::reset(const ReceiverSet& receivers) {
    const std::span<const glm::uvec3> triangles = receivers.triangles();
    const std::size_t vertexCount = receivers.vertexCount();
    mTriangles.assign(triangles.begin(), triangles.end());
    mTrianglePower.assign(triangles.size(), CompensatedSum{});
    mUpdateCount.assign(triangles.size(), 0);
    mMaxUpdates = 0;
    mTriangleArea.assign(receivers.triangleAreas().begin(), receivers.triangleAreas().end());

    // Vertex -> incident triangles, compressed rows.
    mRingStart.assign(vertexCount + 1, 0);
    for (const glm::uvec3& t : triangles)
        for (int c = 0; c < 3; ++c)
            ++mRingStart[t[c] + 1];
    for (std::size_t v = 0; v < vertexCount; ++v)
        mRingStart[v + 1] += mRingStart[v];
    mRingTriangles.resize(mRingStart[vertexCount]);
    std::vector<std::uint32_t> fill(mRingStart.begin(), mRingStart.end() - 1);
    for (std::uint32_t t = 0; t < triangles.size(); ++t)
        for (int c = 0; c < 3; ++c)
            mRingTriangles[fill[triangles[t][c]]++] = t;

    mRingArea.assign(vertexCount, 0.0);
    for (std::size_t v = 0; v < vertexCount; ++v)
        for (std::uint32_t i = mRingStart[v]; i < mRingStart[v + 1]; ++i)
            mRingArea[v] += double(mTriangleArea[mRingTriangles[i]]);

    mTouchedTriangles.clear();
    mTriangleTouched.assign(triangles.size(), 0);
    mVertexTouched.assign(vertexCount, 0);
}

void ImpactCounter::accumulate(const ReceiverSet& receivers, const PhotonSegments& segments,
                               std::span<const std::uint32_t> indices, double sign) {
    const auto all = receivers.receivers();
    Entity lastEntity;
    std::int64_t lastReceiver = -1;
    for (const std::uint32_t s : indices) {
        const Entity hit = segments.hitEntity[s];
        if (hit.isNull()) continue;
        if (hit != lastEntity) { // consecutive segments often land on the same mesh
            lastEntity = hit;
            lastReceiver = receivers.find(hit);
        }
        if (lastReceiver < 0) continue; // not a receiver (nothing to light)
        const auto& receiver = all[std::size_t(lastReceiver)];
        QGI_ASSERT(segments.hitPrimitive[s] < receiver.triangleCount, "segment ", s,
                   " hit triangle ", segments.hitPrimitive[s], " of a mesh with ",
                   receiver.triangleCount);
        add(receiver.firstTriangle + segments.hitPrimitive[s], segments.power[s], sign);
    }
}

void ImpactCounter::add(std::uint32_t t, const glm::vec3& power, double sign) {
    mTrianglePower[t].add(sign * glm::dvec3(power));
    mMaxUpdates = std::max(mMaxUpdates, ++mUpdateCount[t]);
    if (!mTriangleTouched[t]) {
        mTriangleTouched[t] = 1;
        mTouchedTriangles.push_back(t);
    }
}

void ImpactCounter::moveImpact(const ReceiverSet& receivers, Entity hit, std::uint32_t from,
                               std::uint32_t to, const glm::vec3& power) {
    const std::int64_t r = receivers.find(hit);
    if (r < 0) return; // not a receiver
    const auto& receiver = receivers.receivers()[std::size_t(r)];
    QGI_ASSERT(from < receiver.triangleCount && to < receiver.triangleCount,
               "impact moved between triangles ", from, " and ", to, " of a mesh with ",
               receiver.triangleCount);
    add(receiver.firstTriangle + from, power, -1.0);
    add(receiver.firstTriangle + to, power, 1.0);
}

void ImpactCounter::clearTriangles(const ReceiverSet::Receiver& receiver) {
    for (std::uint32_t t = receiver.firstTriangle;
         t < receiver.firstTriangle + receiver.triangleCount; ++t) {
        mTrianglePower[t] = CompensatedSum{};
        mUpdateCount[t] = 0;
        if (!mTriangleTouched[t]) {
            mTriangleTouched[t] = 1;
            mTouchedTriangles.push_back(t);
        }
    }
}

void ImpactCounter::takeTouchedVertices(std::vector<std::uint32_t>& out) {
    out.clear();
    for (const std::uint32_t t : mTouchedTriangles) {
        mTriangleTouched[t] = 0;
        for (int c = 0; c < 3; ++c) {
            const std::uint32_t v = mTriangles[t][c];
            if (mVertexTouched[v]) continue;
            mVertexTouched[v] = 1;
            out.push_back(v);
        }
    }
    for (const std::uint32_t v : out)
        mVertexTouched[v] = 0;
    mTouchedTriangles.clear();
    std::sort(out.begin(), out.end());
}

glm::vec3 ImpactCounter::irradiance(std::uint32_t vertex) const {
    if (mRingArea[vertex] <= 0.0) return glm::vec3(0.f);
    glm::dvec3 power(0.0);
    for (std::uint32_t i = mRingStart[vertex]; i < mRingStart[vertex + 1]; ++i)
        power += mTrianglePower[mRingTriangles[i]].value();
    // Additions and subtractions that cancel can leave a rounding error below zero.
    return glm::vec3(glm::max(power / mRingArea[vertex], glm::dvec3(0.0)));
}

} // namespace qgi
