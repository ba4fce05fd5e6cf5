#pragma once

namespace qgi {

/// A character lit by the SH probe volume. It does not block or reflect photons.
/// Its Mesh is only drawn; its lighting arrives in ShLighting.
struct Avatar {
    float radius = 0.3f; ///< metres: bounding radius used for probe lookups
};

} // namespace qgi
