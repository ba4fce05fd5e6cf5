#pragma once

namespace qgi {

/// Tag on a StaticMesh whose surface is shaded from the point cache (seed 003) rather than its
/// per-vertex irradiance: large, coarsely tessellated surfaces, where per-vertex lighting
/// cannot resolve soft shadows. Used in hybrid mode when a PointCache resource exists; the
/// per-vertex irradiance remains the fallback where no cache point is in range.
struct PointCacheShaded {};

} // namespace qgi
