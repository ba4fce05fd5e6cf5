#pragma once

namespace qgi {

/// Tag: a mesh of the static world. Never moves after load; its triangles sit in the static
/// Embree scene; it blocks and reflects photons and receives per-vertex irradiance.
struct StaticMesh {};

} // namespace qgi
