#include "systems/sh_probes/ShProbeSystem.h"

#include "components/Avatar.h"
#include "components/DirectionalLight.h"
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/PointLight.h"
#include "components/ShLighting.h"
#include "components/SpotLight.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/core/Finite.h"
#include "runtime/core/Hash.h"
#include "runtime/core/Log.h"
#include "runtime/math/Pose.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneQueries.h"
#include "systems/photon_update/PhotonSampling.h"
#include "systems/photon_update/PhotonStore.h"

#include <glm/common.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/mat3x3.hpp>
#include <glm/vector_relational.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>

namespace qgi {
namespace {

/// A uniformly distributed rotation drawn from (seed, probe) (Shoemake's quaternion method).
glm::mat3 probeRotation(std::uint64_t seed, std::uint32_t probe) {
    const std::uint64_t key =
        photon::mixBits(seed ^ 0x5348'5072'6f62'6573ull) + std::uint64_t(probe) * 3;
    const float u1 = photon::keyUniform(key), u2 = photon::keyUniform(key + 1),
                u3 = photon::keyUniform(key + 2);
    const float a = std::sqrt(1.f - u1), b = std::sqrt(u1);
    const float t2 = glm::two_pi<float>() * u2, t3 = glm::two_pi<float>() * u3;
    const glm::quat q(b * std::cos(t3), a * std::sin(t2), a * std::cos(t2), b * std::sin(t3));
    return glm::mat3_cast(glm::normalize(q));
}

/// Distance ray origins keep from the surface they leave, metres: hundreds of float ulps at
/// the point's magnitude.
float surfaceOffset(const glm::vec3& p) {
    return 1e-4f * (1.f + std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}));
}

Aabb transformBox(const Aabb& box, const glm::mat4& m) {
    Aabb out;
    if (box.empty()) return out;
    for (int k = 0; k < 8; ++k) {
        const glm::vec3 corner(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y,
                               k & 4 ? box.max.z : box.min.z);
        out.extend(glm::vec3(m * glm::vec4(corner, 1.f)));
    }
    return out;
}

/// The punctual lights the probes see (those with a pose), each with its stand-in flag, in
/// registry order: a hash that changes when one is removed, added or (un)tagged.
std::uint64_t lightSetSignature(const Registry& registry) {
    Fnv1aHasher h;
    const auto add = [&](Entity e, std::uint8_t kind) {
        h.add(kind);
        h.add(e);
        h.add(registry.has<LightStandIn>(e));
    };
    registry.view<const PointLight, const WorldTransform>().each(
        [&](Entity e, const PointLight&, const WorldTransform&) { add(e, 0); });
    registry.view<const SpotLight, const WorldTransform>().each(
        [&](Entity e, const SpotLight&, const WorldTransform&) { add(e, 1); });
    registry.view<const DirectionalLight, const WorldTransform>().each(
        [&](Entity e, const DirectionalLight&, const WorldTransform&) { add(e, 2); });
    return h.value();
}

} // namespace

ShProbeSystem::ShProbeSystem(const ShProbeSettings& settings) : mSettings(settings) {
    validate(settings);
}

void ShProbeSystem::build(Registry& registry) {
    const SceneInfo* info = registry.ctx().find<SceneInfo>();
    if (!info) fail("SH probes: the registry has no SceneInfo (load a scene first)");
    if (!registry.ctx().contains<RayScene>())
        fail("SH probes: the registry has no RayScene (build it before the probe volume)");
    Aabb bounds = info->bounds;
    if (!bounds.empty() && !(isFinite(bounds.min) && isFinite(bounds.max)))
        fail("SH probes: the scene bounds are not finite");
    const float spacing = resolveProbeSpacing(mSettings, bounds);
    if (bounds.empty()) bounds.extend(glm::vec3(0.f)); // a spacing was given: a minimal lattice
    const glm::dvec3 counts =
        glm::max(glm::dvec3(2.0), glm::ceil(glm::dvec3(bounds.extent()) / double(spacing)));
    const double probes = counts.x * counts.y * counts.z;
    if (probes > double(mSettings.maxProbes))
        fail("SH probes: spacing ", spacing, " m over bounds of ", bounds.extent().x, " x ",
             bounds.extent().y, " x ", bounds.extent().z, " m needs ", probes,
             " probes, more than ShProbeSettings.maxProbes = ", mSettings.maxProbes);

    mSpacing = spacing;
    mInfluence = mSettings.influenceDistance > 0.f ? mSettings.influenceDistance : 2.f * spacing;
    mVolume = &registry.ctx().emplaceOrReplace<ProbeVolume>(ProbeGrid::over(bounds, spacing),
                                                            mSettings.visibilitySubdivisions);
    mRays = &registry.ctx().get<RayScene>();
    mEnvironment = isFinite(info->environment) ? info->environment : glm::vec3(0.f);
    mStale.assign(mVolume->probeCount(), 0);
    mStaleCount = 0;
    mSweepCursor = 0;
    mSweepOwed = 0; // the first projection sees the scene as it is
    mLightSet = lightSetSignature(registry);
    mCellQueued.assign(mVolume->grid().cellCount(), 0);
    mFineTouched.clear(); // end points counted from the next delta on
    mFramesSinceHalving = 0;
    mMobiles.clear();
    registry.view<const MobileMesh, const Mesh, const WorldTransform>().each(
        [&](Entity e, const MobileMesh&, const Mesh& mesh, const WorldTransform& world) {
            Mobile m;
            for (const glm::vec3& p : mesh.positions)
                m.objectBounds.extend(p);
            m.worldBounds = transformBox(m.objectBounds, world.matrix);
            m.pose = world.matrix;
            m.active = !outOfWorld(registry, e);
            mMobiles.emplace(e, m);
        });
    mBuilt = true;
    mProjected = false;
    const glm::ivec3 n = mVolume->grid().counts;
    logInfo("SH probes: ", n.x, " x ", n.y, " x ", n.z, " = ", mVolume->probeCount(),
            " probes, spacing ", spacing, " m, ", mSettings.raysPerProbe, " rays each",
            mSettings.hybrid ? ", hybrid" : "");
}

// ---- scene snapshot and projection ---------------------------------------------------------

void ShProbeSystem::snapshot(const Registry& registry) {
    std::fill(mSurfaces.begin(), mSurfaces.end(), Surface{});
    registry.view<const Mesh>().each([&](Entity e, const Mesh& mesh) {
        if (e.index >= mSurfaces.size()) mSurfaces.resize(std::size_t(e.index) + 1);
        Surface& s = mSurfaces[e.index];
        const Material* material = registry.tryGet<Material>(e);
        const Material m = material ? *material : Material{};
        s.albedo = isFinite(m.baseColor) ? glm::clamp(m.baseColor, 0.f, 1.f) : glm::vec3(0.f);
        s.emission = isFinite(m.emission) ? glm::max(m.emission, 0.f) : glm::vec3(0.f);
        // Hybrid mode: a lamp with a stand-in reaches avatars through the shader's direct
        // light; seen by the probes too, it would count twice.
        if (mSettings.hybrid && s.emission != glm::vec3(0.f) && hasLightStandIn(registry, e))
            s.emission = glm::vec3(0.f);
        s.indices = mesh.indices.data();
        s.indexCount = mesh.indices.size();
        const VertexIrradiance* irradiance = registry.tryGet<VertexIrradiance>(e);
        if (irradiance && irradiance->irradiance.size() == mesh.positions.size()) {
            s.irradiance = irradiance->irradiance.data();
            s.vertexCount = irradiance->irradiance.size();
        }
    });

    snapshotLights(registry);
}

void ShProbeSystem::snapshotLights(const Registry& registry) {
    mLights.clear();
    registry.view<const PointLight, const WorldTransform>().each(
        [&](Entity e, const PointLight& light, const WorldTransform& world) {
            Light& out = mLights.emplace_back();
            out.kind = Light::Kind::Point;
            out.position = glm::vec3(world.matrix[3]);
            out.radiance = light.color * light.intensity;
            out.standIn = registry.has<LightStandIn>(e);
        });
    registry.view<const SpotLight, const WorldTransform>().each(
        [&](Entity e, const SpotLight& light, const WorldTransform& world) {
            Light& out = mLights.emplace_back();
            out.kind = Light::Kind::Spot;
            out.position = glm::vec3(world.matrix[3]);
            out.direction = lightForward(world.matrix);
            out.radiance = light.color * light.intensity;
            // The renderer's falloff (shaders/common/lighting.glsl): linear in cos between the
            // cones, squared.
            const float cosOuter = std::cos(light.outerConeAngle);
            const float cosInner = std::cos(light.innerConeAngle);
            out.coneScale = 1.f / std::max(1e-3f, cosInner - cosOuter);
            out.coneOffset = -cosOuter * out.coneScale;
            out.standIn = registry.has<LightStandIn>(e);
        });
    registry.view<const DirectionalLight, const WorldTransform>().each(
        [&](Entity e, const DirectionalLight& light, const WorldTransform& world) {
            Light& out = mLights.emplace_back();
            out.kind = Light::Kind::Directional;
            out.direction = lightForward(world.matrix);
            out.radiance = light.color * light.irradiance;
            out.standIn = registry.has<LightStandIn>(e);
        });
    // Lights with non-finite data, or brighter than float lighting can carry, would poison
    // every probe, and one past kMaxPoseReach or with no axis to shine along is dark
    // everywhere (the photons' rules): leave them out.
    std::erase_if(mLights, [](const Light& l) {
        return !isUsableLightPosition(l.position) || !isUsableLightRadiance(l.radiance) ||
               (l.kind != Light::Kind::Point && l.direction == glm::vec3(0.f)) ||
               !isFinite(l.direction) || !std::isfinite(l.coneScale) ||
               !std::isfinite(l.coneOffset);
    });
}

bool ShProbeSystem::lightAt(const Light& light, const glm::vec3& x, glm::vec3& toward,
                            float& distance, glm::vec3& irradiance) {
    if (light.kind == Light::Kind::Directional) {
        toward = -light.direction;
        distance = std::numeric_limits<float>::infinity();
        irradiance = light.radiance;
        return true;
    }
    const glm::vec3 d = light.position - x;
    const float distance2 = glm::dot(d, d);
    if (!(distance2 > 1e-12f)) return false;
    distance = std::sqrt(distance2);
    toward = d / distance;
    irradiance = light.radiance / distance2;
    if (light.kind == Light::Kind::Spot) {
        const float cosAngle = glm::dot(light.direction, -toward);
        const float t = std::clamp(cosAngle * light.coneScale + light.coneOffset, 0.f, 1.f);
        if (t == 0.f) return false;
        irradiance *= t * t;
    }
    return true;
}

std::uint32_t ShProbeSystem::projectProbe(std::uint32_t probe, ProbeVolume& volume) const {
    const std::uint32_t n = mSettings.raysPerProbe;
    const glm::vec3 x = volume.grid().position(probe);
    const glm::mat3 rotation = probeRotation(mSettings.seed, probe);

    std::vector<Ray> rays(n);
    std::vector<std::optional<Hit>> hits(n);
    for (std::uint32_t k = 0; k < n; ++k)
        rays[k] = Ray{x, 0.f, rotation * sh::fibonacciDirection(k, n)};
    mRays->intersect(rays, hits);

    std::vector<glm::vec3> radiance(n, glm::vec3(0.f));
    std::vector<glm::vec3> diffuse(n, glm::vec3(0.f)); // albedo / pi at front hits
    std::uint32_t backFaces = 0, nonFinite = 0;
    for (std::uint32_t k = 0; k < n; ++k) {
        if (!hits[k]) {
            radiance[k] = mEnvironment;
            continue;
        }
        const Hit& hit = *hits[k];
        if (glm::dot(hit.normal, rays[k].direction) >= 0.f) {
            ++backFaces;
            continue;
        }
        if (hit.entity.index >= mSurfaces.size()) continue;
        const Surface& s = mSurfaces[hit.entity.index];
        glm::vec3 e(0.f);
        if (s.irradiance && 3 * std::size_t(hit.primitive) + 2 < s.indexCount) {
            const std::uint32_t* tri = s.indices + 3 * std::size_t(hit.primitive);
            if (tri[0] < s.vertexCount && tri[1] < s.vertexCount && tri[2] < s.vertexCount) {
                const float u = hit.barycentrics.x, v = hit.barycentrics.y;
                e = (1.f - u - v) * s.irradiance[tri[0]] + u * s.irradiance[tri[1]] +
                    v * s.irradiance[tri[2]];
            }
        }
        // A NaN written by some other system would spread to every avatar near this probe.
        if (!isFinite(e)) {
            e = glm::vec3(0.f);
            ++nonFinite;
        }
        diffuse[k] = s.albedo * glm::one_over_pi<float>();
        radiance[k] = s.emission + diffuse[k] * e;
    }

    // Hybrid: the punctual lights' direct light at the surfaces, by one shadow ray per hit to
    // a light picked in proportion to its unshadowed contribution there (weighted by the
    // inverse of that probability: unbiased, one ray instead of one per light).
    if (mSettings.hybrid && !mLights.empty()) {
        std::vector<Ray> shadow;
        std::vector<std::uint32_t> owner;
        std::vector<glm::vec3> contribution;
        std::vector<glm::vec3> candidate(mLights.size());
        std::vector<Ray> candidateRay(mLights.size());
        const std::uint64_t key = photon::mixBits(mSettings.seed ^ 0x4c69'6768'7450'6963ull) ^
                                  (std::uint64_t(probe) << 32);
        for (std::uint32_t k = 0; k < n; ++k) {
            if (!hits[k] || diffuse[k] == glm::vec3(0.f)) continue;
            const Hit& hit = *hits[k];
            if (glm::dot(hit.normal, rays[k].direction) >= 0.f) continue;
            const glm::vec3 p = x + hit.t * rays[k].direction;
            const glm::vec3 origin = p + surfaceOffset(p) * hit.normal;
            float total = 0.f;
            for (std::size_t j = 0; j < mLights.size(); ++j) {
                candidate[j] = glm::vec3(0.f);
                glm::vec3 toward, e0;
                float distance = 0.f;
                if (!lightAt(mLights[j], origin, toward, distance, e0)) continue;
                const float cosine = glm::dot(hit.normal, toward);
                if (cosine <= 0.f) continue;
                candidate[j] = diffuse[k] * e0 * cosine;
                candidateRay[j] = Ray{origin, 0.f, toward,
                                      std::isinf(distance) ? distance : distance * (1.f - 1e-5f)};
                total += candidate[j].r + candidate[j].g + candidate[j].b;
            }
            if (!(total > 0.f)) continue;
            float pick = photon::keyUniform(key + k) * total;
            std::size_t chosen = mLights.size();
            for (std::size_t j = 0; j < mLights.size(); ++j) {
                const float w = candidate[j].r + candidate[j].g + candidate[j].b;
                if (w <= 0.f) continue;
                chosen = j;
                if (pick < w) break;
                pick -= w;
            }
            const float w = candidate[chosen].r + candidate[chosen].g + candidate[chosen].b;
            shadow.push_back(candidateRay[chosen]);
            owner.push_back(k);
            contribution.push_back(candidate[chosen] * (total / w));
        }
        std::vector<std::uint8_t> blocked(shadow.size());
        mRays->occluded(shadow, blocked);
        for (std::size_t i = 0; i < shadow.size(); ++i)
            if (!blocked[i]) radiance[owner[i]] += contribution[i];
    }

    sh::ShRgb coefficients{};
    const float weight = 4.f * glm::pi<float>() / float(n);
    for (std::uint32_t k = 0; k < n; ++k)
        if (radiance[k] != glm::vec3(0.f))
            sh::addSample(coefficients, rays[k].direction, radiance[k], weight);

    // Photon mode: the punctual lights that shoot photons reach the avatar directly too.
    if (!mSettings.hybrid)
        for (const Light& light : mLights) {
            if (light.standIn) continue;
            glm::vec3 toward, e0;
            float distance = 0.f;
            if (!lightAt(light, x, toward, distance, e0) || e0 == glm::vec3(0.f)) continue;
            const Ray ray{x, 0.f, toward,
                          std::isinf(distance) ? distance : distance * (1.f - 1e-5f)};
            if (mRays->occluded(ray)) continue;
            const sh::ShRgb direct = sh::directional(toward, e0);
            for (int i = 0; i < sh::kCoefficientCount; ++i)
                coefficients[i] += direct[i];
        }

    volume.coefficients(probe) = coefficients;
    volume.setEnabled(probe, float(backFaces) <= mSettings.backFaceShare * float(n));
    return nonFinite;
}

void ShProbeSystem::projectProbes(const Registry& registry, std::span<const std::uint32_t> probes) {
    if (!mBuilt || probes.empty()) return;
    snapshot(registry);
    ProbeVolume& volume = *mVolume;
    std::vector<std::uint32_t> nonFinite(probes.size());
    tbb::parallel_for(std::size_t(0), probes.size(),
                      [&](std::size_t i) { nonFinite[i] = projectProbe(probes[i], volume); });
    std::uint64_t hits = 0;
    for (const std::uint32_t k : nonFinite)
        hits += k;
    if (hits > 0 && !mWarnedNonFinite) {
        mWarnedNonFinite = true;
        logWarning("SH probes: ", hits, " probe rays met VertexIrradiance that is not finite ",
                   "(NaN or infinity), read as no light; reported once");
    }
    for (const std::uint32_t p : probes)
        if (mStale[p]) {
            mStale[p] = 0;
            --mStaleCount;
        }
}

void ShProbeSystem::projectAll(const Registry& registry) {
    if (!mBuilt) return;
    mRefresh.resize(mVolume->probeCount());
    for (std::uint32_t p = 0; p < mRefresh.size(); ++p)
        mRefresh[p] = p;
    projectProbes(registry, mRefresh);
    mProjected = true;
}

void ShProbeSystem::markAllStale() {
    if (!mBuilt) return;
    std::fill(mStale.begin(), mStale.end(), 1);
    mStats.markedStale += mStale.size() - mStaleCount;
    mStaleCount = mStale.size();
}

// ---- following the scene ---------------------------------------------------------------------

void ShProbeSystem::markNear(const glm::vec3& point, float radius) {
    // A one-point box: the clamp in markNearBox returns the point itself, so the distances and
    // the probes marked are exactly those of the point.
    markNearBox(Aabb{point, point}, radius);
}

void ShProbeSystem::markNearBox(const Aabb& box, float radius) {
    if (box.empty()) return;
    const ProbeGrid& grid = mVolume->grid();
    const glm::vec3 lo = (box.min - radius - grid.origin) / grid.spacing;
    const glm::vec3 hi = (box.max + radius - grid.origin) / grid.spacing;
    glm::ivec3 a, b;
    for (int k = 0; k < 3; ++k) {
        a[k] = std::max(0, int(std::ceil(lo[k])));
        b[k] = std::min(grid.counts[k] - 1, int(std::floor(hi[k])));
    }
    const float r2 = radius * radius;
    for (int z = a.z; z <= b.z; ++z)
        for (int y = a.y; y <= b.y; ++y)
            for (int x = a.x; x <= b.x; ++x) {
                const std::uint32_t p = grid.probeIndex({x, y, z});
                const glm::vec3 q = grid.position(p);
                const glm::vec3 d = q - glm::clamp(q, box.min, box.max);
                if (glm::dot(d, d) > r2 || mStale[p]) continue;
                mStale[p] = 1;
                ++mStaleCount;
                ++mStats.markedStale;
            }
}

void ShProbeSystem::markShadowed(const Aabb& box) {
    // Photon mode: a probe's own direct light changes where its shadow ray to a light crosses
    // the mobile's bounds.
    if (box.empty()) return;
    const Aabb widened{box.min - 1e-3f * mSpacing, box.max + 1e-3f * mSpacing};
    const ProbeGrid& grid = mVolume->grid();
    for (const Light& light : mLights) {
        if (light.standIn) continue;
        for (std::uint32_t p = 0; p < mStale.size(); ++p) {
            if (mStale[p]) continue;
            const glm::vec3 x = grid.position(p);
            glm::vec3 toward, e0;
            float distance = 0.f;
            if (!lightAt(light, x, toward, distance, e0)) continue;
            if (!segmentMeetsBox(x, toward, std::min(distance, 1e30f), widened)) continue;
            mStale[p] = 1;
            ++mStaleCount;
            ++mStats.markedStale;
        }
    }
}

bool ShProbeSystem::markChanges(const Registry& registry) {
    bool all = false;
    // Lights: any change of a punctual light (its component, or its pose) reaches everywhere.
    if (!registry.changed<PointLight>().empty() || !registry.changed<SpotLight>().empty() ||
        !registry.changed<DirectionalLight>().empty() || !registry.changed<Material>().empty())
        all = true;
    for (const Entity e : registry.changed<WorldTransform>())
        if (registry.has<PointLight>(e) || registry.has<SpotLight>(e) ||
            registry.has<DirectionalLight>(e))
            all = true;
    if (const std::uint64_t lights = lightSetSignature(registry);
        std::exchange(mLightSet, lights) != lights)
        all = true; // one removed, or (un)tagged a stand-in

    // A delta seen before marks nothing; after one missed, what changed is unknown:
    // everything is marked (PhotonDeltaReader).
    const PhotonDelta* delta = registry.ctx().find<PhotonDelta>();
    if (delta) {
        const PhotonDeltaReader::News news = mDeltaReader.read(*delta);
        if (news == PhotonDeltaReader::News::Repeated) delta = nullptr;
        if (news == PhotonDeltaReader::News::AfterGap) all = true;
    }
    if (delta && delta->full) all = true;
    if (all) {
        markAllStale();
        mVolume->invalidateVisibility();
        for (auto& [entity, mobile] : mMobiles) {
            if (const WorldTransform* w = registry.tryGet<WorldTransform>(entity)) {
                mobile.worldBounds = transformBox(mobile.objectBounds, w->matrix);
                mobile.pose = w->matrix;
            }
            mobile.active = !outOfWorld(registry, entity);
        }
        return true;
    }
    bool changed = false;

    // Moved mobiles, and mobiles taken out or put back (MobileMesh::active): their old and new
    // bounds.
    const ProbeGrid& grid = mVolume->grid();
    if (!mSettings.hybrid &&
        (!registry.changed<WorldTransform>().empty() || !registry.changed<MobileMesh>().empty()))
        snapshotLights(registry);
    forEachMovedOrSwitched(registry, [&](Entity e) {
        const auto it = mMobiles.find(e);
        if (it == mMobiles.end()) return;
        const WorldTransform* world = registry.tryGet<WorldTransform>(e);
        if (!world || !isFinite(world->matrix)) return;
        Mobile& mobile = it->second;
        if (mobile.objectBounds.empty()) return; // no vertices: nothing to see or hide
        const Aabb now = transformBox(mobile.objectBounds, world->matrix);
        const bool active = !outOfWorld(registry, e);
        const bool wasActive = std::exchange(mobile.active, active);
        // A turn or a flip can keep the bounds bit for bit, and still show the probes another
        // side of the mobile.
        const bool moved = world->matrix != std::exchange(mobile.pose, world->matrix) ||
                           now.min != mobile.worldBounds.min || now.max != mobile.worldBounds.max;
        // Patched without a change, or moved while out of the world: nothing to see.
        if ((!wasActive && !active) || (wasActive == active && !moved)) {
            mobile.worldBounds = now;
            return;
        }
        changed = true;
        // Reach: the influence distance, or as far as the mobile still covers the given
        // share of a probe's sphere of directions.
        const glm::vec3 extent = glm::max(now.extent(), mobile.worldBounds.extent());
        const float rho = 0.5f * glm::length(extent);
        const float reach =
            std::max(mInfluence, rho / (2.f * std::sqrt(mSettings.mobileSolidAngleShare)));
        for (const Aabb& box : {mobile.worldBounds, now}) {
            markNearBox(box, reach);
            if (!mSettings.hybrid) markShadowed(box);
            // Visibility inside a cell changes only if the mobile overlaps the cell's box.
            glm::ivec3 lo, hi;
            glm::vec3 t;
            grid.locate(box.min - 1e-3f * grid.spacing, lo, t);
            grid.locate(box.max + 1e-3f * grid.spacing, hi, t);
            for (int z = lo.z; z <= hi.z; ++z)
                for (int y = lo.y; y <= hi.y; ++y)
                    for (int x = lo.x; x <= hi.x; ++x)
                        mVolume->setVisibilityReady(grid.cellIndex({x, y, z}), false);
        }
        mobile.worldBounds = now;
    });

    // The delta's end points: where per-vertex irradiance can have changed. They are counted
    // on a lattice of half the probe spacing first (a moving mobile re-traces thousands of
    // paths whose ends crowd into a few places); each half-cell whose count reaches
    // minDeltaEndPoints marks the probes within the influence distance of its centre, widened
    // by its half diagonal so no end point's neighbourhood is missed, and starts counting
    // again. Counts carry over from frame to frame, so changes that trickle in a few end
    // points a frame still mark their probes once they add up.
    // Counts halve every kEndPointHalfLife frames: stray end points that fall rarer than about
    // one in 16 frames never add up to a mark.
    if (!mFineTouched.empty() && ++mFramesSinceHalving >= kEndPointHalfLife) {
        mFramesSinceHalving = 0;
        for (std::uint16_t& count : mFineTouched)
            count = std::uint16_t(count / 2);
    }
    if (delta && !delta->paths.empty()) {
        changed = true; // marked or not: the sweep puts right what the rules let through
        const float fine = 0.5f * grid.spacing;
        const glm::ivec3 fineCounts = 2 * grid.counts + 1;
        const glm::vec3 fineOrigin = grid.origin - 0.5f * fine;
        const std::size_t fineCells = std::size_t(fineCounts.x) * fineCounts.y * fineCounts.z;
        if (mFineTouched.size() != fineCells) mFineTouched.assign(fineCells, 0);
        const glm::vec3 hiBound = glm::vec3(fineCounts - 1);
        const auto touch = [&](const PhotonSegments& s) {
            for (std::size_t i = 0; i < s.size(); ++i) {
                if (!std::isfinite(s.length[i])) continue;
                const glm::vec3 end = s.origin[i] + s.length[i] * s.direction[i];
                if (!isFinite(end)) continue;
                const glm::vec3 f =
                    glm::clamp(glm::floor((end - fineOrigin) / fine), glm::vec3(0.f), hiBound);
                std::uint16_t& count =
                    mFineTouched[std::size_t(f.x) +
                                 fineCounts.x *
                                     (std::size_t(f.y) + fineCounts.y * std::size_t(f.z))];
                if (count < 65535) ++count;
            }
        };
        touch(delta->oldSegments);
        touch(delta->newSegments);
        const float radius = mInfluence + 0.5f * std::sqrt(3.f) * fine;
        for (int z = 0; z < fineCounts.z; ++z)
            for (int y = 0; y < fineCounts.y; ++y)
                for (int x = 0; x < fineCounts.x; ++x) {
                    std::uint16_t& count =
                        mFineTouched[std::size_t(x) +
                                     fineCounts.x *
                                         (std::size_t(y) + fineCounts.y * std::size_t(z))];
                    if (count < mSettings.minDeltaEndPoints) continue;
                    markNear(fineOrigin + fine * (glm::vec3(x, y, z) + 0.5f), radius);
                    count = 0;
                }
    }
    return changed;
}

void ShProbeSystem::chooseRefresh(const Registry& registry) {
    mRefresh.clear();
    if (mStaleCount == 0 || mSettings.updateBudget == 0) return;
    const std::size_t probeCount = mStale.size();
    if (mStaleCount <= mSettings.updateBudget) {
        for (std::uint32_t p = 0; p < probeCount; ++p)
            if (mStale[p]) mRefresh.push_back(p);
        return;
    }
    // Distance in cells (26-neighbour steps) from the nearest avatar: breadth-first search
    // from the probes nearest to the avatars. Without avatars every probe is at distance 0.
    const ProbeGrid& grid = mVolume->grid();
    constexpr std::uint32_t kFar = std::numeric_limits<std::uint32_t>::max();
    mDistance.assign(probeCount, kFar);
    mQueue.clear();
    registry.view<const Avatar, const WorldTransform>().each(
        [&](const Avatar&, const WorldTransform& world) {
            const glm::vec3 p = glm::vec3(world.matrix[3]);
            if (!isFinite(p)) return;
            glm::ivec3 cell;
            glm::vec3 t;
            grid.locate(p, cell, t);
            const glm::ivec3 nearest = cell + glm::ivec3(glm::round(t));
            const std::uint32_t index = grid.probeIndex(nearest);
            if (mDistance[index] == 0) return;
            mDistance[index] = 0;
            mQueue.push_back(index);
        });
    if (mQueue.empty()) std::fill(mDistance.begin(), mDistance.end(), 0u);
    for (std::size_t head = 0; head < mQueue.size(); ++head) {
        const std::uint32_t p = mQueue[head];
        const glm::ivec3 c = grid.probeCoords(p);
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const glm::ivec3 q = c + glm::ivec3(dx, dy, dz);
                    if (glm::any(glm::lessThan(q, glm::ivec3(0))) ||
                        glm::any(glm::greaterThanEqual(q, grid.counts)))
                        continue;
                    const std::uint32_t qi = grid.probeIndex(q);
                    if (mDistance[qi] != kFar) continue;
                    mDistance[qi] = mDistance[p] + 1;
                    mQueue.push_back(qi);
                }
    }
    mCandidates.clear();
    for (std::uint32_t p = 0; p < probeCount; ++p)
        if (mStale[p]) mCandidates.push_back(p);
    const auto nearer = [&](std::uint32_t a, std::uint32_t b) {
        return mDistance[a] != mDistance[b] ? mDistance[a] < mDistance[b] : a < b;
    };
    const auto cut = mCandidates.begin() + std::ptrdiff_t(mSettings.updateBudget);
    std::nth_element(mCandidates.begin(), cut, mCandidates.end(), nearer);
    std::sort(mCandidates.begin(), cut, nearer);
    mRefresh.assign(mCandidates.begin(), cut);
}

void ShProbeSystem::sweep() {
    // The sweep visits sweepPerFrame probes a frame and takes every one the budget did not
    // choose this frame, stale or not: a stale probe far from every avatar would otherwise wait
    // for as long as changes near the avatars fill the budget. None is taken twice: two
    // threads would project it at once.
    const auto count = std::uint32_t(mStale.size());
    const std::uint32_t visits = std::min({mSettings.sweepPerFrame, count, mSweepOwed});
    if (visits == 0) return;
    mSweepOwed -= visits;
    if (mSweepCursor >= count) mSweepCursor = 0; // build() resets it; a smaller volume
    mChosen.assign(mRefresh.begin(), mRefresh.end());
    std::sort(mChosen.begin(), mChosen.end());
    for (std::uint32_t k = 0; k < visits; ++k) {
        const std::uint32_t p = mSweepCursor;
        mSweepCursor = mSweepCursor + 1 == count ? 0 : mSweepCursor + 1;
        if (std::binary_search(mChosen.begin(), mChosen.end(), p)) continue;
        mRefresh.push_back(p);
        ++mStats.swept;
        if (!mStale[p]) ++mStats.sweptFresh;
    }
}

// ---- avatars -----------------------------------------------------------------------------------

void ShProbeSystem::computeVisibility(std::uint32_t cell, ProbeVolume& volume) const {
    const ProbeGrid& grid = volume.grid();
    const glm::ivec3 base = grid.cellCoords(cell);
    glm::vec3 corners[8];
    for (int c = 0; c < 8; ++c)
        corners[c] = grid.position(grid.cornerProbe(base, c));
    const int side = int(volume.visibilitySubdivisions()) + 1;
    std::vector<Ray> rays;
    std::vector<std::uint32_t> slot; // point * 8 + corner
    rays.reserve(std::size_t(volume.latticePointsPerCell()) * 8);
    std::uint8_t* masks = volume.visibilityMasks(cell);
    std::uint32_t point = 0;
    for (int z = 0; z < side; ++z)
        for (int y = 0; y < side; ++y)
            for (int x = 0; x < side; ++x, ++point) {
                const glm::vec3 from = volume.latticePoint(cell, {x, y, z});
                masks[point] = 0xff;
                for (int c = 0; c < 8; ++c) {
                    const glm::vec3 d = corners[c] - from;
                    if (glm::dot(d, d) < 1e-12f) continue; // the point is the probe
                    rays.push_back(Ray{from, 0.f, d, 1.f});
                    slot.push_back(point * 8 + std::uint32_t(c));
                }
            }
    std::vector<std::uint8_t> blocked(rays.size());
    mRays->occluded(rays, blocked);
    for (std::size_t i = 0; i < rays.size(); ++i)
        if (blocked[i]) masks[slot[i] / 8] &= std::uint8_t(~(1u << (slot[i] % 8)));
    volume.setVisibilityReady(cell, true);
}

void ShProbeSystem::lightAvatars(Registry& registry) {
    if (!mBuilt) return;
    ProbeVolume& volume = *mVolume;
    const ProbeGrid& grid = volume.grid();
    // Past the outer probes an avatar takes the nearest ones' light: say so, once per avatar.
    const glm::vec3 low = grid.origin - grid.spacing;
    const glm::vec3 high = grid.origin + grid.spacing * glm::vec3(grid.counts);
    const auto light = [&](Entity e, const glm::vec3& p, ShLighting& lighting) {
        if (!isFinite(p)) {
            ++mStats.unlit; // left as it was
            if (mWarnedNoPosition.insert(e).second)
                logWarning("SH probes: avatar ", entityName(registry, e), " is at (", p.x, ", ",
                           p.y, ", ", p.z,
                           "), no position; it keeps its last lighting (none, "
                           "if it has not been lit yet)");
            return;
        }
        if (glm::any(glm::lessThan(p, low)) || glm::any(glm::greaterThan(p, high))) {
            ++mStats.outside;
            if (mWarnedOutside.insert(e).second) {
                logWarning("SH probes: avatar ", entityName(registry, e),
                           " is outside the probe volume; it takes the light of the nearest "
                           "probes");
            }
        }
        ProbeBlend blend;
        sh::ShRgb blended;
        if (!isFinite(p) || !volume.interpolate(p, blended, &blend)) {
            ++mStats.unlit; // left as it was
            return;
        }
        mStats.fallbacks += blend.fallback;
        if (blend.hidden) {
            // Every probe around it is behind a wall (a closet narrower than the probe
            // spacing): blending them anyway would light it through the walls. It keeps the
            // light it had.
            ++mStats.hidden;
            if (mWarnedHidden.insert(e).second)
                logWarning("SH probes: avatar ", entityName(registry, e),
                           " stands where every probe around it is behind a wall (a space "
                           "narrower than the ",
                           grid.spacing,
                           " m probe spacing); it keeps its last lighting there (none, if it "
                           "has not been lit yet)");
            return;
        }
        lighting.coefficients = blended;
        ++mStats.avatars;
    };

    // One pass lights the avatars that have their ShLighting and stand in a cell whose
    // visibility lattice is ready. The others wait for after the pass: new avatars get their
    // ShLighting then (so the pass changes no pool), and the cells visited for the first time
    // (or since a mobile moved through them) have their lattices computed, in parallel.
    mAvatarEntities.clear();
    mPendingCells.clear();
    registry.view<const Avatar, const WorldTransform>().each(
        [&](Entity e, const Avatar&, const WorldTransform& world) {
            const glm::vec3 p(world.matrix[3]);
            bool ready = true;
            if (isFinite(p)) {
                glm::ivec3 cell;
                glm::vec3 t;
                grid.locate(p, cell, t);
                const std::uint32_t index = grid.cellIndex(cell);
                if (!volume.visibilityReady(index)) {
                    ready = false;
                    if (!mCellQueued[index]) {
                        mCellQueued[index] = 1;
                        mPendingCells.push_back(index);
                    }
                }
            }
            ShLighting* lighting = registry.tryGet<ShLighting>(e);
            if (ready && lighting)
                light(e, p, *lighting);
            else
                mAvatarEntities.push_back(e);
        });
    if (mAvatarEntities.empty()) return;
    for (const Entity e : mAvatarEntities)
        if (!registry.has<ShLighting>(e)) registry.emplace<ShLighting>(e);
    if (!mPendingCells.empty()) {
        tbb::parallel_for(std::size_t(0), mPendingCells.size(),
                          [&](std::size_t i) { computeVisibility(mPendingCells[i], volume); });
        for (const std::uint32_t c : mPendingCells)
            mCellQueued[c] = 0;
    }
    mStats.visibilityCells += mPendingCells.size();
    for (const Entity e : mAvatarEntities)
        light(e, glm::vec3(registry.get<WorldTransform>(e).matrix[3]), registry.get<ShLighting>(e));
}

void ShProbeSystem::update(Registry& registry, const FrameContext&) {
    mStats = FrameStats{};
    if (!mBuilt) return;
    FrameProfiler* profiler = registry.ctx().find<FrameProfiler>();
    {
        FrameProfiler::Scope scope(profiler, "refresh");
        if (!mProjected) {
            // The projection sees what the current delta changed.
            if (const PhotonDelta* delta = registry.ctx().find<PhotonDelta>())
                mDeltaReader.read(*delta);
            projectAll(registry);
            mStats.full = true;
            mStats.refreshed = mVolume->probeCount();
            // The projection saw every mobile where it is now.
            for (auto& [entity, mobile] : mMobiles)
                if (const WorldTransform* w = registry.tryGet<WorldTransform>(entity)) {
                    mobile.worldBounds = transformBox(mobile.objectBounds, w->matrix);
                    mobile.pose = w->matrix;
                }
        } else {
            if (markChanges(registry)) mSweepOwed = std::uint32_t(mStale.size()); // a round
            mStats.staleBefore = mStaleCount;
            chooseRefresh(registry);
            sweep();
            projectProbes(registry, mRefresh);
            mStats.refreshed = mRefresh.size();
        }
        mStats.staleAfter = mStaleCount;
    }
    FrameProfiler::Scope scope(profiler, "avatars");
    lightAvatars(registry);
}

} // namespace qgi
