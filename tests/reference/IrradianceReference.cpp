#include "tests/reference/IrradianceReference.h"

#include "components/DirectionalLight.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/LightStandIn.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/SceneInfo.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/matrix.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>

namespace qgi::reference {
namespace {

constexpr float kPi = glm::pi<float>();
constexpr float kInfinity = std::numeric_limits<float>::infinity();
/// Surface offset for rays, metres per metre of coordinate magnitude (see the class comment).
constexpr float kOffset = 1e-5f;
/// Russian roulette starts at this reflection: earlier bounces carry most of the light, and
/// always tracing them keeps the variance of the common short paths low.
constexpr std::uint32_t kRouletteStart = 3;
/// Bound on ReferenceSettings::maxBounces: it caps a path's length when roulette cannot end
/// it (albedo 1 everywhere in a closed scene); an albedo of 0.99 leaves 4e-5 of the light
/// beyond 1000 bounces.
constexpr std::uint32_t kMaxBouncesLimit = 1000;
/// Samples per parallel task: large enough to amortise scheduling, small enough that one
/// point with many samples spreads over every core.
constexpr std::uint32_t kBlockSamples = 256;

std::string describe(const Registry& registry, Entity e, const char* kind) {
    std::string out = str("reference: ", kind, " entity ", e.index);
    if (const Name* name = registry.tryGet<Name>(e)) out += str(" '", name->value, "'");
    return out;
}

bool isFinite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

/// A colour must be finite, at least 0 and (when `maxValue` is finite) at most maxValue.
void checkColor(const glm::vec3& c, float maxValue, const std::string& who, const char* field) {
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(c[i]) || c[i] < 0.f || c[i] > maxValue)
            fail(who, ": ", field, " = (", c.x, ", ", c.y, ", ", c.z,
                 ") must be finite and in [0, ", maxValue, "]");
}

void checkScalar(float value, float maxValue, const std::string& who, const char* field) {
    if (!std::isfinite(value) || value < 0.f || value > maxValue)
        fail(who, ": ", field, " = ", value, " must be finite and in [0, ", maxValue, "]");
}

const glm::mat4& worldOf(const Registry& registry, Entity e, const char* kind) {
    const WorldTransform* world = registry.tryGet<WorldTransform>(e);
    if (!world)
        fail(describe(registry, e, kind), ": has no WorldTransform (run the transform system)");
    for (int c = 0; c < 4; ++c)
        if (!isFinite(glm::vec3(world->matrix[c])) || !std::isfinite(world->matrix[c][3]))
            fail(describe(registry, e, kind), ": WorldTransform.matrix is not finite");
    return world->matrix;
}

float average(const glm::vec3& c) {
    return (c.x + c.y + c.z) / 3.f;
}

float maxComponent(const glm::vec3& c) {
    return std::max({c.x, c.y, c.z});
}

/// `p` moved off its surface to the side of unit normal n.
glm::vec3 offsetAlong(const glm::vec3& p, const glm::vec3& n) {
    const float magnitude = maxComponent(glm::abs(p));
    return p + n * (kOffset * (1.f + magnitude));
}

/// A direction about unit n with density cos(theta) / pi, from two uniform numbers: a uniform
/// point on the unit disc lifted onto the hemisphere (Malley's method). The tangent frame is
/// built without branches from the sign of n.z, so it stays orthonormal near both poles.
glm::vec3 cosineDirection(const glm::vec3& n, float u1, float u2) {
    const float sign = std::copysign(1.f, n.z);
    const float a = -1.f / (sign + n.z);
    const float b = n.x * n.y * a;
    const glm::vec3 tangent(1.f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    const glm::vec3 bitangent(b, sign + n.y * n.y * a, -n.y);
    const float r = std::sqrt(u1);
    const float phi = 2.f * kPi * u2;
    return r * std::cos(phi) * tangent + r * std::sin(phi) * bitangent +
           std::sqrt(std::max(0.f, 1.f - u1)) * n;
}

/// Power-heuristic weight (exponent 2) of a strategy with density `pdf` against one with
/// density `other`, in double: grazing emitter samples have densities whose squares overflow
/// a float.
double powerHeuristic(double pdf, double other) {
    return pdf * pdf / (pdf * pdf + other * other);
}

struct Moments {
    glm::dvec3 sum{0.0};
    glm::dvec3 sumSquares{0.0};
};

} // namespace

/// Counter-based stream: a sample's numbers depend on (seed, point, sample) alone, so results
/// do not depend on how samples are spread over threads. SplitMix64 (a Weyl sequence through
/// a 64-bit finaliser) passes BigCrush and needs one word of state.
class IrradianceReference::Random {
public:
    Random(std::uint64_t seed, std::uint64_t point, std::uint64_t sample)
        : mState(mix(mix(mix(seed) + point) + sample)) {}

    /// Uniform in [0, 1): the top 24 bits, so every value is an exact float below 1.
    float uniform() { return float(next() >> 40) * 0x1p-24f; }

private:
    static std::uint64_t mix(std::uint64_t z) {
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
        return z ^ (z >> 31);
    }
    std::uint64_t next() {
        mState += 0x9e3779b97f4a7c15ull;
        return mix(mState);
    }

    std::uint64_t mState;
};

IrradianceReference::IrradianceReference(const Registry& registry, const RayScene& scene,
                                         const ReferenceSettings& settings)
    : mRays(scene), mSettings(settings) {
    if (settings.samplesPerPoint < 2)
        fail("reference: ReferenceSettings.samplesPerPoint = ", settings.samplesPerPoint,
             " must be at least 2 (the standard error needs a sample variance)");
    if (settings.maxBounces > kMaxBouncesLimit)
        fail("reference: ReferenceSettings.maxBounces = ", settings.maxBounces,
             " exceeds the limit of ", kMaxBouncesLimit);
    addSurfaces(registry);
    addLights(registry);
    if (const SceneInfo* info = registry.ctx().find<SceneInfo>();
        info && settings.includeEnvironment) {
        checkColor(info->environment, kInfinity, "reference: SceneInfo", "environment");
        mEnvironment = info->environment;
    }
}

void IrradianceReference::addSurfaces(const Registry& registry) {
    struct Triangle {
        EmitterTriangle triangle;
        Entity entity;
        float power; // average over channels of emission * area, W/sr
    };
    std::vector<Triangle> emitters;
    double totalPower = 0.0;

    const auto addMesh = [&](Entity e, const char* kind) {
        const std::string who = describe(registry, e, kind);
        const Material* material = registry.tryGet<Material>(e);
        if (!material) fail(who, ": has no Material");
        checkColor(material->baseColor, 1.f, who, "Material.baseColor");
        checkColor(material->emission, kInfinity, who, "Material.emission");
        if (mSurfaces.size() <= e.index) mSurfaces.resize(std::size_t(e.index) + 1);
        mSurfaces[e.index] = Surface{material->baseColor, material->emission, 0.f, true};
        if (maxComponent(material->emission) == 0.f) return;

        const Mesh* mesh = registry.tryGet<Mesh>(e);
        if (!mesh) fail(who, ": has no Mesh");
        const glm::mat4& world = worldOf(registry, e, kind);
        // A mirroring matrix reverses the winding; the front side stays the object's.
        const float sign = glm::determinant(glm::mat3(world)) < 0.f ? -1.f : 1.f;
        const float radiance = average(material->emission);
        for (std::size_t i = 0; i + 2 < mesh->indices.size(); i += 3) {
            glm::vec3 p[3];
            for (std::size_t k = 0; k < 3; ++k) {
                const std::uint32_t index = mesh->indices[i + k];
                if (index >= mesh->positions.size())
                    fail(who, ": Mesh.indices[", i + k, "] = ", index, " is out of range");
                p[k] = glm::vec3(world * glm::vec4(mesh->positions[index], 1.f));
            }
            const glm::vec3 cross = glm::cross(p[1] - p[0], p[2] - p[0]);
            const float twiceArea = glm::length(cross);
            if (!(twiceArea > 0.f)) continue; // degenerate: never hit, emits nothing
            const EmitterTriangle triangle{
                p[0], p[1] - p[0], p[2] - p[0], sign * cross / twiceArea, material->emission, 0.f};
            emitters.push_back({triangle, e, radiance * 0.5f * twiceArea});
            totalPower += double(emitters.back().power);
        }
    };
    registry.view<const StaticMesh>().each(
        [&](Entity e, const StaticMesh&) { addMesh(e, "StaticMesh"); });
    registry.view<const MobileMesh>().each(
        [&](Entity e, const MobileMesh&) { addMesh(e, "MobileMesh"); });

    // Triangles are picked with probability power / totalPower and a point on one uniformly,
    // so the density per m^2 is the surface's radiance / totalPower on every triangle of it.
    double running = 0.0;
    for (Triangle& t : emitters) {
        Surface& surface = mSurfaces[t.entity.index];
        surface.emitterDensity = float(double(average(surface.emission)) / totalPower);
        t.triangle.density = surface.emitterDensity;
        mEmitters.push_back(t.triangle);
        running += double(t.power);
        mEmitterCdf.push_back(running / totalPower);
    }
    if (!mEmitterCdf.empty()) mEmitterCdf.back() = 1.0;
}

void IrradianceReference::addLights(const Registry& registry) {
    registry.view<const PointLight>().each([&](Entity e, const PointLight& light) {
        if (registry.has<LightStandIn>(e)) return; // adds no light of its own
        const std::string who = describe(registry, e, "PointLight");
        checkColor(light.color, kInfinity, who, "PointLight.color");
        checkScalar(light.intensity, kInfinity, who, "PointLight.intensity");
        PunctualLight& out = mLights.emplace_back();
        out.kind = LightKind::Point;
        out.position = glm::vec3(worldOf(registry, e, "PointLight")[3]);
        out.radiance = light.color * light.intensity;
    });
    registry.view<const SpotLight>().each([&](Entity e, const SpotLight& light) {
        if (registry.has<LightStandIn>(e)) return; // adds no light of its own
        const std::string who = describe(registry, e, "SpotLight");
        checkColor(light.color, kInfinity, who, "SpotLight.color");
        checkScalar(light.intensity, kInfinity, who, "SpotLight.intensity");
        checkScalar(light.outerConeAngle, 0.5f * kPi, who, "SpotLight.outerConeAngle");
        checkScalar(light.innerConeAngle, light.outerConeAngle, who, "SpotLight.innerConeAngle");
        const glm::mat4& world = worldOf(registry, e, "SpotLight");
        const glm::vec3 axis = -glm::vec3(world[2]);
        if (!(glm::length(axis) > 0.f)) fail(who, ": WorldTransform.matrix has no -Z axis");
        // The renderer's falloff (SceneRenderer::uploadLights and lighting.glsl), in float
        // like the renderer.
        const float cosInner = std::cos(light.innerConeAngle);
        const float cosOuter = std::cos(light.outerConeAngle);
        const float scale = 1.f / std::max(1e-3f, cosInner - cosOuter);
        PunctualLight& out = mLights.emplace_back();
        out.kind = LightKind::Spot;
        out.position = glm::vec3(world[3]);
        out.direction = glm::normalize(axis);
        out.radiance = light.color * light.intensity;
        out.coneScale = scale;
        out.coneOffset = -cosOuter * scale;
    });
    registry.view<const DirectionalLight>().each([&](Entity e, const DirectionalLight& light) {
        if (registry.has<LightStandIn>(e)) return; // adds no light of its own
        const std::string who = describe(registry, e, "DirectionalLight");
        checkColor(light.color, kInfinity, who, "DirectionalLight.color");
        checkScalar(light.irradiance, kInfinity, who, "DirectionalLight.irradiance");
        const glm::vec3 axis = -glm::vec3(worldOf(registry, e, "DirectionalLight")[2]);
        if (!(glm::length(axis) > 0.f)) fail(who, ": WorldTransform.matrix has no -Z axis");
        PunctualLight& out = mLights.emplace_back();
        out.kind = LightKind::Directional;
        out.direction = glm::normalize(axis);
        out.radiance = light.color * light.irradiance;
    });
}

glm::vec3 IrradianceReference::punctualIrradiance(const glm::vec3& z, const glm::vec3& n) const {
    glm::vec3 sum(0.f);
    const glm::vec3 origin = offsetAlong(z, n);
    for (const PunctualLight& light : mLights) {
        if (light.kind == LightKind::Directional) {
            const float cosTheta = -glm::dot(n, light.direction);
            if (cosTheta <= 0.f) continue;
            if (!mRays.occluded(Ray{origin, 0.f, -light.direction, kInfinity}))
                sum += light.radiance * cosTheta;
            continue;
        }
        const glm::vec3 d = light.position - z;
        const float distance2 = glm::dot(d, d);
        if (!(distance2 > 0.f)) continue;
        const glm::vec3 toLight = d / std::sqrt(distance2);
        const float cosTheta = glm::dot(n, toLight);
        if (cosTheta <= 0.f) continue;
        float falloff = 1.f;
        if (light.kind == LightKind::Spot) {
            const float cosAngle = -glm::dot(light.direction, toLight);
            const float t = std::clamp(cosAngle * light.coneScale + light.coneOffset, 0.f, 1.f);
            falloff = t * t;
            if (falloff == 0.f) continue;
        }
        // The segment ends at the light itself: tfar = 1 in units of the unnormalised direction.
        if (!mRays.occluded(Ray{origin, 0.f, light.position - origin, 1.f}))
            sum += light.radiance * (falloff * cosTheta / distance2);
    }
    return sum;
}

glm::vec3 IrradianceReference::sampleEmitters(const glm::vec3& z, const glm::vec3& n,
                                              Random& random) const {
    if (mEmitters.empty()) return glm::vec3(0.f);
    const double pick = double(random.uniform());
    const auto chosen = std::upper_bound(mEmitterCdf.begin(), mEmitterCdf.end(), pick);
    const EmitterTriangle& triangle =
        mEmitters[std::min(std::size_t(chosen - mEmitterCdf.begin()), mEmitters.size() - 1)];
    // Uniform on the triangle: barycentrics (1 - s, s (1 - v), s v) with s = sqrt(u).
    const float s = std::sqrt(random.uniform());
    const float v = random.uniform();
    const glm::vec3 y =
        triangle.corner + (s * (1.f - v)) * triangle.edge1 + (s * v) * triangle.edge2;

    const glm::vec3 d = y - z;
    const float distance2 = glm::dot(d, d);
    if (!(distance2 > 0.f)) return glm::vec3(0.f);
    const glm::vec3 w = d / std::sqrt(distance2);
    const float cosTheta = glm::dot(n, w);
    const float cosLight = -glm::dot(triangle.normal, w); // emission leaves the front only
    if (cosTheta <= 0.f || cosLight <= 0.f) return glm::vec3(0.f);

    const glm::vec3 origin = offsetAlong(z, n);
    const glm::vec3 target = offsetAlong(y, triangle.normal);
    if (mRays.occluded(Ray{origin, 0.f, target - origin, 1.f})) return glm::vec3(0.f);
    // Solid-angle densities of this direction under both strategies.
    const double lightPdf = double(triangle.density) * double(distance2) / double(cosLight);
    const double bsdfPdf = double(cosTheta) / glm::pi<double>();
    return triangle.emission *
           float(double(cosTheta) / lightPdf * powerHeuristic(lightPdf, bsdfPdf));
}

glm::dvec3 IrradianceReference::tracePath(const glm::vec3& x, const glm::vec3& n,
                                          Random& random) const {
    glm::dvec3 sum(0.0);
    glm::vec3 beta(1.f); // product of the albedos so far, over roulette survival
    glm::vec3 z = x;
    glm::vec3 normal = n;
    for (std::uint32_t bounce = 0;; ++bounce) {
        const bool counts = bounce > 0 || mSettings.includeDirect;
        if (counts) {
            glm::vec3 direct = sampleEmitters(z, normal, random);
            if (bounce > 0) direct += punctualIrradiance(z, normal); // at x: once per point
            sum += glm::dvec3(beta * direct);
        }
        const float u1 = random.uniform();
        const float u2 = random.uniform();
        const glm::vec3 w = cosineDirection(normal, u1, u2);
        const Ray ray{offsetAlong(z, normal), 0.f, w, kInfinity};
        const std::optional<Hit> hit = mRays.intersect(ray);
        if (!hit) {
            if (counts) sum += glm::dvec3(kPi * beta * mEnvironment);
            break;
        }
        QGI_ASSERT(hit->entity.index < mSurfaces.size() && mSurfaces[hit->entity.index].inScene,
                   "the ray scene holds entity ", hit->entity.index,
                   " that the reference did not see: build both from the same registry");
        const Surface& surface = mSurfaces[hit->entity.index];
        const float cosLight = -glm::dot(hit->normal, w);
        if (counts && cosLight > 0.f && surface.emitterDensity > 0.f) {
            const double lightPdf =
                double(surface.emitterDensity) * double(hit->t) * double(hit->t) / double(cosLight);
            const double bsdfPdf = double(glm::dot(normal, w)) / glm::pi<double>();
            sum += glm::dvec3(kPi * beta * surface.emission) * powerHeuristic(bsdfPdf, lightPdf);
        }
        if (bounce == mSettings.maxBounces) break;
        beta *= surface.albedo;
        const float survival = maxComponent(beta);
        if (survival <= 0.f) break;
        if (bounce + 1 >= kRouletteStart) {
            if (random.uniform() >= survival) break;
            beta /= survival;
        }
        z = ray.origin + hit->t * w;
        normal = cosLight > 0.f ? hit->normal : -hit->normal; // the side the light arrived on
    }
    return sum;
}

IrradianceEstimate IrradianceReference::estimate(const glm::vec3& x, const glm::vec3& n) const {
    return estimate(std::span(&x, 1), std::span(&n, 1)).front();
}

std::vector<IrradianceEstimate> IrradianceReference::estimate(std::span<const glm::vec3> x,
                                                              std::span<const glm::vec3> n) const {
    if (x.size() != n.size()) fail("reference: ", x.size(), " points but ", n.size(), " normals");
    std::vector<glm::vec3> normals(n.size());
    for (std::size_t i = 0; i < x.size(); ++i) {
        if (!isFinite(x[i])) fail("reference: point ", i, " is not finite");
        const float length = glm::length(n[i]);
        if (!std::isfinite(length) || !(length > 0.f))
            fail("reference: normal ", i, " is zero or not finite");
        normals[i] = n[i] / length;
    }

    const std::uint32_t samples = mSettings.samplesPerPoint;
    const std::size_t blocks = (samples + kBlockSamples - 1) / kBlockSamples;
    std::vector<Moments> partial(x.size() * blocks);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, partial.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& tasks) {
                          for (std::size_t task = tasks.begin(); task != tasks.end(); ++task) {
                              const std::size_t point = task / blocks;
                              const std::uint32_t first =
                                  std::uint32_t(task % blocks) * kBlockSamples;
                              const std::uint32_t last = std::min(samples, first + kBlockSamples);
                              Moments moments;
                              for (std::uint32_t s = first; s < last; ++s) {
                                  Random random(mSettings.seed, point, s);
                                  const glm::dvec3 value =
                                      tracePath(x[point], normals[point], random);
                                  moments.sum += value;
                                  moments.sumSquares += value * value;
                              }
                              partial[task] = moments;
                          }
                      });

    // Blocks are summed in a fixed order, so the result is the same on any number of threads.
    std::vector<IrradianceEstimate> out(x.size());
    const double count = double(samples);
    for (std::size_t point = 0; point < x.size(); ++point) {
        Moments total;
        for (std::size_t block = 0; block < blocks; ++block) {
            total.sum += partial[point * blocks + block].sum;
            total.sumSquares += partial[point * blocks + block].sumSquares;
        }
        const glm::dvec3 mean = total.sum / count;
        const glm::dvec3 variance =
            glm::max(glm::dvec3(0.0), (total.sumSquares - count * mean * mean) / (count - 1.0));
        out[point].mean = mean;
        out[point].standardError = glm::sqrt(variance / count);
        if (mSettings.includeDirect)
            out[point].mean += glm::dvec3(punctualIrradiance(x[point], normals[point]));
    }
    return out;
}

IrradianceEstimate estimateIrradiance(const Registry& registry, const RayScene& scene,
                                      const glm::vec3& x, const glm::vec3& n,
                                      const ReferenceSettings& settings) {
    return IrradianceReference(registry, scene, settings).estimate(x, n);
}

std::vector<IrradianceEstimate> estimateIrradiance(const Registry& registry, const RayScene& scene,
                                                   std::span<const glm::vec3> x,
                                                   std::span<const glm::vec3> n,
                                                   const ReferenceSettings& settings) {
    return IrradianceReference(registry, scene, settings).estimate(x, n);
}

} // namespace qgi::reference
