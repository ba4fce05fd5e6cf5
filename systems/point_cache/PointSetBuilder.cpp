#include "systems/point_cache/PointSetBuilder.h"

#include "components/Mesh.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/photon_update/PhotonEmitter.h"
#include "systems/photon_update/PhotonSampling.h"
#include "systems/point_cache/PointCache.h"
#include "systems/point_cache/PointShading.h"

#include <glm/geometric.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace qgi {
namespace {

constexpr std::uint64_t kParticleStream = 0x9a87c1ull;
constexpr std::uint64_t kDartStream = 0xd4a27ull;
constexpr std::size_t kBatch = 4096;

/// Hash grid of accepted points with cells of rMax: a point within rMax of x lies in one of the
/// 27 cells around x's.
class SpacingGrid {
public:
    explicit SpacingGrid(float cell) : mCell(cell) {}

    void insert(const glm::vec3& p, std::uint32_t index) {
        mCells[key(cellOf(p))].push_back(index);
    }
    /// Distance from x to the nearest point closer than the cell size; +inf when there is none.
    float nearest(const glm::vec3& x, const std::vector<glm::vec3>& points) const {
        const glm::ivec3 c = cellOf(x);
        float best = std::numeric_limits<float>::infinity();
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const auto it = mCells.find(key(c + glm::ivec3(dx, dy, dz)));
                    if (it == mCells.end()) continue;
                    for (const std::uint32_t p : it->second)
                        best = std::min(best, glm::length(points[p] - x));
                }
        return best < mCell ? best : std::numeric_limits<float>::infinity();
    }

private:
    glm::ivec3 cellOf(const glm::vec3& p) const { return glm::ivec3(glm::floor(p / mCell)); }
    static std::uint64_t key(const glm::ivec3& c) {
        const auto part = [](int v) {
            return std::uint64_t(std::uint32_t(v + (1 << 20)) & 0x1fffffu);
        };
        return part(c.x) | (part(c.y) << 21) | (part(c.z) << 42);
    }
    float mCell;
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> mCells;
};

struct Landing {
    bool valid = false;
    glm::vec3 position{0.f};
    glm::vec3 normal{0.f};
};

/// A landing on a static triangle that lies in a plane of constant x, y or z (its world
/// corners share that coordinate bit for bit, as the ray scene holds them) is put on the plane
/// exactly, with the axis as its normal: origin + t * direction lands within rounding of the
/// plane and a normalised normal can miss 1 by an ulp, and the point cache's DETP discs group
/// into exact planes only when their normals and their centres' coordinate agree bit for bit
/// (DiscIndex: one plane crossing per segment instead of a walk through overlapping discs).
void ontoAxisPlane(const Registry& registry, const Hit& hit, Landing& landing) {
    int axis = -1;
    for (int a = 0; a < 3; ++a)
        if (landing.normal[(a + 1) % 3] == 0.f && landing.normal[(a + 2) % 3] == 0.f) axis = a;
    if (axis < 0) return;
    const Mesh* mesh = registry.tryGet<Mesh>(hit.entity);
    const WorldTransform* world = registry.tryGet<WorldTransform>(hit.entity);
    if (!mesh || !world || 3 * std::size_t(hit.primitive) + 2 >= mesh->indices.size()) return;
    float coordinate = 0.f;
    for (int k = 0; k < 3; ++k) {
        const std::uint32_t index = mesh->indices[3 * std::size_t(hit.primitive) + k];
        if (index >= mesh->positions.size()) return;
        // The ray scene's expression for a static vertex in the world, so the same bits.
        const float c = glm::vec3(world->matrix * glm::vec4(mesh->positions[index], 1.f))[axis];
        if (k > 0 && c != coordinate) return;
        coordinate = c;
    }
    // The landing lies within rounding of the plane; one farther off came from another
    // triangle than the ray scene's (the registry changed since it was built): left alone.
    if (!(std::abs(landing.position[axis] - coordinate) <=
          1e-4f * std::max(1.f, std::abs(coordinate))))
        return;
    landing.position[axis] = coordinate;
    landing.normal = glm::vec3(0.f);
    landing.normal[axis] = hit.normal[axis] > 0.f ? 1.f : -1.f;
}

} // namespace

Aabb staticBounds(const Registry& registry) {
    Aabb box;
    registry.view<const StaticMesh, const Mesh, const WorldTransform>().each(
        [&](Entity, const StaticMesh&, const Mesh& mesh, const WorldTransform& world) {
            for (const glm::vec3& p : mesh.positions)
                box.extend(glm::vec3(world.matrix * glm::vec4(p, 1.f)));
        });
    return box;
}

std::vector<DartSource> makeDartSources(const Registry& registry, const RayScene& scene,
                                        const PointCacheSettings& s, const Aabb& bounds,
                                        std::uint32_t* particlesShot) {
    PhotonSettings every;
    std::vector<PhotonEmitter> emitters;
    findEmitterSources(registry, every, emitters);
    double total = 0.0;
    for (PhotonEmitter& e : emitters) {
        prepareEmitter(registry, bounds, e);
        total += double(e.power.x) + e.power.y + e.power.z;
    }
    std::uint32_t first = 0;
    if (total > 0.0)
        for (PhotonEmitter& e : emitters) {
            const double share = (double(e.power.x) + e.power.y + e.power.z) / total;
            e.firstPhoton = first;
            e.photonCount = std::uint32_t(std::floor(share * s.particleCount + 0.5));
            first += e.photonCount;
        }
    if (particlesShot) *particlesShot = first;

    // Each particle writes its sources into its own slot; concatenated in particle order.
    std::vector<std::vector<DartSource>> perParticle(first);
    std::vector<const PhotonEmitter*> owner(first);
    for (const PhotonEmitter& e : emitters)
        for (std::uint32_t i = 0; i < e.photonCount; ++i)
            owner[e.firstPhoton + i] = &e;
    const std::uint64_t seedKey = photon::mixBits(s.seed ^ kParticleStream);
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, first, 64),
                      [&](const tbb::blocked_range<std::uint32_t>& range) {
                          for (std::uint32_t i = range.begin(); i != range.end(); ++i) {
                              const PhotonHead head = emitPhoton(*owner[i], i, s.seed);
                              Ray ray;
                              ray.origin = head.origin;
                              ray.direction = head.direction;
                              for (std::uint32_t b = 0; b <= s.particleBounces; ++b) {
                                  const std::optional<Hit> hit = scene.intersect(ray);
                                  if (!hit) break;
                                  const glm::vec3 at = ray.origin + hit->t * ray.direction;
                                  const glm::vec3 facing =
                                      glm::dot(hit->normal, ray.direction) < 0.f ? hit->normal
                                                                                 : -hit->normal;
                                  if (!scene.isMobile(hit->entity))
                                      perParticle[i].push_back({at, facing});
                                  if (b == s.particleBounces) break;
                                  ray.origin = photon::offsetFromSurface(at, facing);
                                  ray.direction = photon::sampleCosine(
                                      photon::Frame(facing), photon::hashUniform(seedKey, i, b, 0),
                                      photon::hashUniform(seedKey, i, b, 1));
                                  ray.tnear = 0.f;
                                  ray.tfar = std::numeric_limits<float>::infinity();
                              }
                          }
                      });
    std::vector<DartSource> sources;
    for (const auto& list : perParticle)
        sources.insert(sources.end(), list.begin(), list.end());
    return sources;
}

PointSetStats buildPointSet(const Registry& registry, const RayScene& scene,
                            const PointCacheSettings& s, const Aabb& bounds, PointCache& cache) {
    QGI_ASSERT(s.rMin > 0.f && s.rMin <= s.rMax && s.aoDistance > 0.f, "settings not resolved");
    cache.position.clear();
    cache.normal.clear();
    cache.dart.clear();
    PointSetStats stats;
    const std::vector<DartSource> sources =
        makeDartSources(registry, scene, s, bounds, &stats.particles);
    stats.sources = std::uint32_t(sources.size());
    if (sources.empty()) {
        stats.stop = PointSetStop::NoSources;
        logWarning("point cache: no light reaches a static surface; the point set is empty");
    }
    logInfo("point cache: ", stats.particles, " particles left ", stats.sources,
            " dart sources; throwing darts (r ", s.rMin, " .. ", s.rMax, " m, AO ", s.aoRays,
            " rays over ", s.aoDistance, " m)");

    const std::uint64_t dartKey = photon::mixBits(s.seed ^ kDartStream);
    const auto aoOf = [&](const Landing& l, std::uint64_t dart) {
        return ambientOcclusion(scene, l.position, l.normal, s.aoRays, s.aoDistance, s.seed,
                                std::uint32_t(dart));
    };
    SpacingGrid grid(s.rMax);
    std::vector<Landing> landings(kBatch);
    std::vector<float> aoAhead(kBatch);
    std::vector<std::uint8_t> hasAo(kBatch);
    std::uint32_t rejections = 0;
    std::uint64_t nextReport = 1'000'000;
    const auto start = std::chrono::steady_clock::now();
    bool done = sources.empty();
    for (std::uint64_t base = 0; !done; base += kBatch) {
        const std::size_t count = std::size_t(std::min<std::uint64_t>(kBatch, s.maxDarts - base));
        // Trace the batch and, for darts in the grey zone of the points known before the
        // batch, compute AO ahead (pure function: the same value the decision would compute).
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 64),
                          [&](const tbb::blocked_range<std::size_t>& range) {
                              for (std::size_t k = range.begin(); k != range.end(); ++k) {
                                  const std::uint64_t d = base + k;
                                  const DartSource& src = sources[std::size_t(d % sources.size())];
                                  Ray ray;
                                  ray.origin = photon::offsetFromSurface(src.position, src.normal);
                                  ray.direction = photon::sampleCosine(
                                      photon::Frame(src.normal),
                                      photon::hashUniform(dartKey, std::uint32_t(d), 0, 0),
                                      photon::hashUniform(dartKey, std::uint32_t(d), 0, 1));
                                  const std::optional<Hit> hit = scene.intersect(ray);
                                  Landing& l = landings[k];
                                  l.valid = hit && !scene.isMobile(hit->entity);
                                  hasAo[k] = 0;
                                  if (!l.valid) continue;
                                  l.position = ray.origin + hit->t * ray.direction;
                                  l.normal = hit->normal;
                                  ontoAxisPlane(registry, *hit, l);
                                  if (glm::dot(l.normal, ray.direction) >= 0.f)
                                      l.normal = -l.normal;
                                  const float e = grid.nearest(l.position, cache.position);
                                  if (!s.trivialTests || (e >= s.rMin && e < s.rMax)) {
                                      aoAhead[k] = aoOf(l, d);
                                      hasAo[k] = 1;
                                  }
                              }
                          });
        for (std::size_t k = 0; k < count && !done; ++k) {
            const std::uint64_t d = base + k;
            ++stats.darts;
            const Landing& l = landings[k];
            bool accept = false;
            if (!l.valid) {
                ++stats.misses;
            } else {
                const float e = grid.nearest(l.position, cache.position);
                if (s.trivialTests && e >= s.rMax) {
                    ++stats.trivialAccepts;
                    accept = true;
                } else if (s.trivialTests && e < s.rMin) {
                    ++stats.trivialRejects;
                } else {
                    ++stats.aoCalls;
                    const float ao = hasAo[k] ? aoAhead[k] : aoOf(l, d);
                    accept = e >= spacingRadius(ao, s.rMin, s.rMax);
                }
            }
            if (accept) {
                grid.insert(l.position, std::uint32_t(cache.position.size()));
                cache.position.push_back(l.position);
                cache.normal.push_back(l.normal);
                cache.dart.push_back(std::uint32_t(d));
                rejections = 0;
                if (cache.position.size() >= s.maxPoints) {
                    stats.stop = PointSetStop::PointBudget;
                    done = true;
                }
            } else if (++rejections >= s.stopAfterRejections) {
                stats.stop = PointSetStop::Rejections;
                done = true;
            }
        }
        if (!done && base + count >= s.maxDarts) {
            stats.stop = PointSetStop::DartBudget;
            done = true;
        }
        if (stats.darts >= nextReport) {
            // It stops at whichever budget comes first, or after a run of rejections.
            const double seconds =
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
            logInfo("point cache: ", stats.darts, " of at most ", s.maxDarts, " darts, ",
                    cache.position.size(), " of at most ", s.maxPoints, " points, ", stats.aoCalls,
                    " AO calls, ", std::lround(seconds), " s");
            nextReport += 1'000'000;
        }
    }
    stats.points = std::uint32_t(cache.position.size());

    // AO and spacing radius of every point (the same values the decisions used).
    cache.ao.assign(cache.position.size(), 0.f);
    cache.radius.assign(cache.position.size(), s.rMax);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cache.position.size(), 64),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t p = range.begin(); p != range.end(); ++p) {
                              cache.ao[p] =
                                  ambientOcclusion(scene, cache.position[p], cache.normal[p],
                                                   s.aoRays, s.aoDistance, s.seed, cache.dart[p]);
                              cache.radius[p] = spacingRadius(cache.ao[p], s.rMin, s.rMax);
                          }
                      });
    static constexpr const char* kStop[] = {"consecutive rejections", "dart budget", "point budget",
                                            "no dart sources"};
    logInfo("point cache: ", stats.points, " points from ", stats.darts, " darts (",
            stats.trivialAccepts, " trivial accepts, ", stats.trivialRejects, " trivial rejects, ",
            stats.aoCalls, " AO calls, ", stats.misses, " misses); stopped by ",
            kStop[int(stats.stop)]);
    return stats;
}

} // namespace qgi
