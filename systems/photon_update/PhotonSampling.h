#pragma once
// The random numbers and the sampling maps of photon emission and reflection. Every random
// choice of a photon is a pure function of (seed, photon index, bounce, dimension), so a path
// re-traced through unchanged geometry reproduces its old segments bit for bit (seed 004
// section 7.3, frame coherence).

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace qgi::photon {

/// The largest float below 1: keeps quasi-random samples in [0, 1).
inline constexpr float kOneMinusEpsilon = 0x1.fffffep-1f;

/// A bijective 64-bit mix (the splitmix64 finaliser): flips about half the output bits for
/// every input bit.
constexpr std::uint64_t mixBits(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/// Uniform number in [0, 1) drawn from a 64-bit key: the top 24 bits of mixBits(key), so
/// distinct keys give independent-looking values and every value is an exact float.
inline float keyUniform(std::uint64_t key) {
    return float(mixBits(key) >> 40) * 0x1p-24f;
}

/// Counter-based uniform number in [0, 1) for one decision of one photon: the key packs
/// (photon, bounce, dimension) without collisions and mixBits is a bijection, so distinct
/// decisions never share a value for a given seed. `seedKey` is mixBits(seed).
inline float hashUniform(std::uint64_t seedKey, std::uint32_t photon, std::uint32_t bounce,
                         std::uint32_t dimension) {
    const std::uint64_t key = (std::uint64_t(photon) << 32) |
                              (std::uint64_t(bounce & 0xffffu) << 16) | (dimension & 0xffffu);
    return keyUniform(key ^ seedKey);
}

/// Radical inverse of `index` in `Base` (a template, so the divisions become multiplications).
template <std::uint32_t Base> double radicalInverse(std::uint32_t index) {
    constexpr double kInverse = 1.0 / Base;
    double value = 0.0, scale = kInverse;
    for (; index > 0; index /= Base) {
        value += double(index % Base) * scale;
        scale *= kInverse;
    }
    return value;
}

/// Coordinate `dimension` (0 to 4: bases 2, 3, 5, 7, 11) of point `index` of the Halton
/// sequence, Cranley-Patterson rotated by an offset drawn from the seed (a rotation keeps the
/// points' low discrepancy and makes each seed a different, equally good point set).
inline float halton(std::uint32_t dimension, std::uint32_t index, std::uint64_t seed) {
    double value = 0.0;
    switch (dimension) {
    case 0:
        value = radicalInverse<2>(index);
        break;
    case 1:
        value = radicalInverse<3>(index);
        break;
    case 2:
        value = radicalInverse<5>(index);
        break;
    case 3:
        value = radicalInverse<7>(index);
        break;
    default:
        value = radicalInverse<11>(index);
        break;
    }
    value += double(mixBits(seed ^ (0x9e3779b97f4a7c15ull * (dimension + 1))) >> 11) * 0x1p-53;
    if (value >= 1.0) value -= 1.0;
    return std::min(float(value), kOneMinusEpsilon);
}

/// Tangent frame (t, b) of unit n, continuous except where n.z changes sign (Duff et al. 2017).
struct Frame {
    glm::vec3 t, b, n;

    explicit Frame(const glm::vec3& normal) : n(normal) {
        const float sign = std::copysign(1.f, n.z);
        const float a = -1.f / (sign + n.z);
        const float c = n.x * n.y * a;
        t = glm::vec3(1.f + sign * n.x * n.x * a, sign * c, -sign * n.x);
        b = glm::vec3(c, sign + n.y * n.y * a, -n.y);
    }
    glm::vec3 toWorld(const glm::vec3& local) const {
        return local.x * t + local.y * b + local.z * n;
    }
};

/// Direction with cos(theta) = cosTheta about the frame's normal, azimuth 2 pi u.
inline glm::vec3 directionAbout(const Frame& frame, float cosTheta, float u) {
    const float sinTheta = std::sqrt(std::max(0.f, 1.f - cosTheta * cosTheta));
    const float phi = glm::two_pi<float>() * u;
    return frame.toWorld({sinTheta * std::cos(phi), sinTheta * std::sin(phi), cosTheta});
}

/// Uniform on the unit sphere (seed 004 Eq 10: cos theta = 1 - 2 u1, phi = 2 pi u2).
inline glm::vec3 sampleSphere(float u1, float u2) {
    const float z = 1.f - 2.f * u1;
    const float r = std::sqrt(std::max(0.f, 1.f - z * z));
    const float phi = glm::two_pi<float>() * u2;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

/// Cosine-weighted about the frame's normal: pdf cos(theta) / pi.
inline glm::vec3 sampleCosine(const Frame& frame, float u1, float u2) {
    return directionAbout(frame, std::sqrt(1.f - u1), u2);
}

/// Barycentric weights (of v1, v2) of a point uniform on a triangle (seed 004 Eq 11):
/// v = v0 + s (v1 - v0) + t (v2 - v0), s = 1 - sqrt(1 - u1), t = (1 - s) u2.
inline glm::vec2 sampleTriangle(float u1, float u2) {
    const float s = 1.f - std::sqrt(1.f - u1);
    return {s, (1.f - s) * u2};
}

/** The spot cone as the renderer shades it (shaders/common/lighting.glsl, glTF
 *  KHR_lights_punctual): intensity I0 * f(c), c = cos(angle to the axis),
 *  f(c) = clamp((c - cosOuter) * scale, 0, 1)^2, scale = 1 / max(1e-3, cosInner - cosOuter).
 *  Photons sample c from f itself (inverse CDF), so every photon carries the same power;
 *  the azimuth is uniform in [0, 2 pi): a true cone, not seed 004's misprinted wedge.       */
class SpotCone {
public:
    SpotCone(float innerAngle, float outerAngle)
        : mCosOuter(std::cos(outerAngle)),
          mScale(1.f / std::max(1e-3f, std::cos(innerAngle) - mCosOuter)),
          mRampEnd(std::min(1.f, mCosOuter + 1.f / mScale)),
          mRampMass(mScale * mScale * cube(mRampEnd - mCosOuter) / 3.f), mCoreMass(1.f - mRampEnd) {
    }

    /// Integral of falloff over the sphere, sr: power = I0 * color * solidAngle().
    float solidAngle() const { return glm::two_pi<float>() * (mRampMass + mCoreMass); }
    /// cos(angle) distributed as falloff, from u in [0, 1).
    float sampleCos(float u) const {
        const float x = u * (mRampMass + mCoreMass);
        const float c = x < mRampMass ? mCosOuter + std::cbrt(3.f * x / (mScale * mScale))
                                      : mRampEnd + (x - mRampMass);
        return std::min(c, 1.f);
    }

private:
    static float cube(float x) { return x * x * x; }

    float mCosOuter;
    float mScale;
    float mRampEnd;  ///< cos(angle) where the ramp reaches 1 (the inner cone, or the axis)
    float mRampMass; ///< integral of falloff over [cosOuter, rampEnd]
    float mCoreMass; ///< integral over [rampEnd, 1], where falloff is 1
};

/// Start of the next segment from a hit at `point`: moved off the surface along `facing` (the
/// normal on the side the photon leaves from), far enough that the ray does not find its own
/// surface again and close enough (0.1 mm at 1 m from the origin) not to matter to lighting.
inline glm::vec3 offsetFromSurface(const glm::vec3& point, const glm::vec3& facing) {
    const float magnitude =
        std::max({1.f, std::abs(point.x), std::abs(point.y), std::abs(point.z)});
    return point + facing * (1e-4f * magnitude);
}

} // namespace qgi::photon
