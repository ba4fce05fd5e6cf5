#pragma once

#include <glm/vec3.hpp>

#include <limits>

namespace qgi {

/// A ray segment in world space: the points origin + t * direction for t in [tnear, tfar].
/// The direction need not be unit length; t is measured in multiples of it (metres when it is
/// unit). Laid out as origin, tnear, direction, tfar to mirror Embree's RTCRay.
struct Ray {
    glm::vec3 origin{0.f};    ///< metres, world space
    float tnear = 0.f;        ///< start of the segment, in units of |direction|
    glm::vec3 direction{0.f}; ///< world space, non-zero
    float tfar = std::numeric_limits<float>::infinity(); ///< end of the segment, >= tnear
};

} // namespace qgi
