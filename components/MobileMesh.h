#pragma once

namespace qgi {

/// A rigid mesh that moves (door, crate, vehicle). Instanced in the ray scene so a move is a
/// transform update; takes part in photon transport exactly like a static mesh.
///
/// `active` takes it out of the world and puts it back without rebuilding anything: for pooled
/// objects spawned and despawned during play. An inactive mobile neither blocks nor reflects
/// light, receives none (its VertexIrradiance is zero) and is not drawn. Change it through
/// `registry.patch<MobileMesh>(e).active = ...`: the systems follow the change from that frame
/// like a move, re-tracing only the photon paths the mobile touched or now touches. The set of
/// mobiles itself is fixed when the frame schedule is built, so create the pool up front.
struct MobileMesh {
    bool active = true;
};

} // namespace qgi
