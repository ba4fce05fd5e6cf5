#pragma once

namespace qgi {

/// Perspective camera looking along the entity's local -Z axis, Y up (glTF).
struct Camera {
    float yfov = 0.9f;    ///< vertical field of view, radians
    float znear = 0.05f;  ///< metres
    float zfar = 500.f;   ///< metres; +inf: no far plane (glTF's camera without zfar)
    bool active = false;  ///< the camera the renderer draws from
};

} // namespace qgi
