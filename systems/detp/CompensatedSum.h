#pragma once

#include <glm/vec3.hpp>

namespace qgi {

/** A running sum of RGB powers in double that carries its own rounding error: each addition's
 *  error is found exactly (Knuth's TwoSum, branch-free) and summed apart, and value() adds the
 *  two (Ogita, Rump and Oishi's Sum2). After n additions of terms x_i, value() is within
 *      2^-53 |S| + (n 2^-53)^2 sum |x_i|
 *  of the exact sum S, per channel, in any order (plain summation: (n - 1) 2^-53 sum |x_i|).
 *  With n additions of at most p each that is 2^-53 |S| + n^3 2^-106 p: at n = 2^30, 2^-53 |S|
 *  plus a sixty-five-thousandth of the largest term, under the rounding of the float the sum is
 *  published in (2^-24 |S|) wherever |S| is at least 256 p. Large terms that came and went (a
 *  mobile parked in the light, then moved away) no longer swamp the small ones that stayed.
 *  Needs IEEE double arithmetic as written (no -ffast-math, which would fold the error away). */
struct CompensatedSum {
    glm::dvec3 sum{0.0};
    glm::dvec3 carry{0.0}; ///< the summed rounding errors of `sum`

    void add(const glm::dvec3& x) {
        const glm::dvec3 total = sum + x;
        const glm::dvec3 xPart = total - sum;
        carry += (sum - (total - xPart)) + (x - xPart);
        sum = total;
    }
    glm::dvec3 value() const { return sum + carry; }
};

} // namespace qgi
