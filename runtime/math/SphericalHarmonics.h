#pragma once
// Order-2 (9 coefficient) real spherical harmonics for irradiance (Ramamoorthi and Hanrahan
// 2001, "An efficient representation for irradiance environment maps").
//
// Convention (the same as components/ShLighting.h and shaders/common/sh.glsl): the real basis
// of Ramamoorthi and Hanrahan applied to world (x, y, z), Y up, coefficients in the order
//   0 L00, 1 L1-1, 2 L10, 3 L11, 4 L2-2, 5 L2-1, 6 L20, 7 L21, 8 L22
// with, for a unit direction (x, y, z):
//   Y00 = 0.282095, Y1-1 = 0.488603 y, Y10 = 0.488603 z, Y11 = 0.488603 x,
//   Y2-2 = 1.092548 xy, Y2-1 = 1.092548 yz, Y20 = 0.315392 (3z^2 - 1), Y21 = 1.092548 xz,
//   Y22 = 0.546274 (x^2 - y^2).
// The basis is orthonormal over the unit sphere (integral of Y_i Y_j over solid angle =
// delta_ij), so the coefficients of a radiance function L(w), W/(m^2 sr), are
// L_i = integral of L(w) Y_i(w) dw, in the same units.
//
// Irradiance, W/m^2, on a surface of unit normal n is the convolution of L with the clamped
// cosine max(0, n.w). By the Funk-Hecke theorem each band l scales by
//   A0 = pi, A1 = 2 pi / 3, A2 = pi / 4,
// giving E(n) = sum_i A_l(i) L_i Y_i(n), which Ramamoorthi and Hanrahan write (their eq. 13)
// with the five constants c1..c5 below. A constant radiance L gives E = pi L.
//
// Truncation error. For a single directional source of irradiance E0 (W/m^2 on a surface
// facing it) the order-2 reconstruction is E0 (1/4 + c/2 + (15 c^2 - 5)/32), c = cos(angle);
// the exact value is E0 max(0, c). The error is largest at grazing incidence (c = 0), where
// it is 3/32 = 9.375% of E0, and averages 3.07% of E0 over the sphere of normals. Any
// non-negative radiance is a sum of such sources, so |E_sh(n) - E(n)| <= 3/32 times the sum
// of their E0, which is integral of L dw = L00 / Y00 (kDirectionalMaxError).
//
// Everything here is plain inline math over glm; no allocation, no state.

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

namespace qgi::sh {

inline constexpr int kCoefficientCount = 9;

/// Nine RGB coefficients, ShLighting order.
using ShRgb = std::array<glm::vec3, kCoefficientCount>;

// ---- basis constants: the normalisation of each function ------------------------------------
inline constexpr float kY00 = 0.282095f; ///< 1 / (2 sqrt(pi))
inline constexpr float kY1 = 0.488603f;  ///< sqrt(3 / (4 pi)): Y1-1, Y10, Y11
inline constexpr float kY2 = 1.092548f;  ///< sqrt(15 / (4 pi)): Y2-2, Y2-1, Y21
inline constexpr float kY20 = 0.315392f; ///< sqrt(5 / (16 pi))
inline constexpr float kY22 = 0.546274f; ///< sqrt(15 / (16 pi))

// ---- convolution constants of eq. 13 ---------------------------------------------------------
inline constexpr float kC1 = 0.429043f; ///< A2 Y22 = (pi/4) 0.546274: x^2-y^2, and 2 c1 xy, xz, yz
inline constexpr float kC2 = 0.511664f; ///< A1 Y1 / 2 = (pi/3) 0.488603: 2 c2 (x, y, z)
inline constexpr float kC3 = 0.743125f; ///< 3 A2 Y20 = (3 pi/4) 0.315392: z^2 term of L20
inline constexpr float kC4 = 0.886227f; ///< A0 Y00 = pi 0.282095: L00
inline constexpr float kC5 = 0.247708f; ///< A2 Y20 = (pi/4) 0.315392: constant term of L20

/// Largest order-2 irradiance error for one directional source, as a fraction of its
/// irradiance at normal incidence (at grazing incidence): 3/32.
inline constexpr float kDirectionalMaxError = 3.f / 32.f;
/// Mean of that error over the sphere of normals, as the same fraction (1/2 the integral of
/// |E_sh - E| over c in [-1, 1]).
inline constexpr float kDirectionalMeanError = 0.030674f;

/// The nine basis functions at unit direction d.
inline std::array<float, kCoefficientCount> basis(const glm::vec3& d) {
    const float x = d.x, y = d.y, z = d.z;
    return {kY00,
            kY1 * y,
            kY1 * z,
            kY1 * x,
            kY2 * x * y,
            kY2 * y * z,
            kY20 * (3.f * z * z - 1.f),
            kY2 * x * z,
            kY22 * (x * x - y * y)};
}

/// Adds `weight` x radiance arriving from unit direction d to the projection: a Monte Carlo
/// projection over N uniform directions uses weight 4 pi / N.
inline void addSample(ShRgb& coefficients, const glm::vec3& d, const glm::vec3& radiance,
                      float weight) {
    const auto y = basis(d);
    const glm::vec3 r = radiance * weight;
    for (int i = 0; i < kCoefficientCount; ++i)
        coefficients[i] += r * y[i];
}

/// Coefficients of a directional source (a delta in direction `towardSource`, unit) that
/// delivers `irradiance` W/m^2 to a surface facing it.
inline ShRgb directional(const glm::vec3& towardSource, const glm::vec3& irradiance) {
    ShRgb c{};
    addSample(c, towardSource, irradiance, 1.f);
    return c;
}

/// The order-2 radiance reconstruction sum_i L_i Y_i(d), W/(m^2 sr).
inline glm::vec3 radiance(const ShRgb& L, const glm::vec3& d) {
    const auto y = basis(d);
    glm::vec3 sum(0.f);
    for (int i = 0; i < kCoefficientCount; ++i)
        sum += L[i] * y[i];
    return sum;
}

/// Irradiance, W/m^2, on a surface of unit normal n under radiance L (eq. 13). Not clamped:
/// order-2 ringing may make it slightly negative (the shader clamps at zero).
inline glm::vec3 irradiance(const ShRgb& L, const glm::vec3& n) {
    const float x = n.x, y = n.y, z = n.z;
    return kC1 * L[8] * (x * x - y * y) + kC3 * L[6] * z * z + kC4 * L[0] - kC5 * L[6] +
           2.f * kC1 * (L[4] * x * y + L[7] * x * z + L[5] * y * z) +
           2.f * kC2 * (L[3] * x + L[1] * y + L[2] * z);
}

/// Point i of N (i < N) of the spherical Fibonacci set: N unit directions of nearly equal
/// solid angle 4 pi / N each, spread without clumps. Projecting with them (weight 4 pi / N)
/// integrates smooth functions far more accurately than independent random directions.
inline glm::vec3 fibonacciDirection(std::uint32_t i, std::uint32_t n) {
    constexpr double kGoldenAngle = 2.399963229728653; // pi (3 - sqrt 5), radians
    const double z = 1.0 - (2.0 * double(i) + 1.0) / double(n);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = kGoldenAngle * double(i);
    return glm::vec3(float(r * std::cos(phi)), float(r * std::sin(phi)), float(z));
}

/// Integral of L over the sphere, W/m^2 per channel: L00 / Y00. For non-negative radiance it
/// bounds the order-2 irradiance error: |E_sh - E| <= kDirectionalMaxError x this.
inline glm::vec3 integral(const ShRgb& L) {
    return L[0] / kY00;
}

} // namespace qgi::sh
