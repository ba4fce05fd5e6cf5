#pragma once

namespace qgi {

/// A character lit by the SH probe volume. It does not block or reflect photons.
/// Its Mesh is only drawn; its lighting arrives in ShLighting.
struct Avatar {
    /// Metres: the character's bounding radius, for tools and game code. The probes light the
    /// avatar from its centre (its WorldTransform's origin) and do not read it.
    float radius = 0.3f;
};

} // namespace qgi
