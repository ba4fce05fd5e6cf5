#pragma once

namespace qgi {

/// Tag: a rigid mesh that moves (door, crate, vehicle). Instanced in the ray scene so a move is
/// a transform update; takes part in photon transport exactly like a static mesh.
struct MobileMesh {};

} // namespace qgi
