#pragma once

#include "runtime/scene/BuiltinSceneBuilder.h"

namespace qgi {

/// Default refinement bound of the atrium, metres: per-vertex lighting resolves ~35 cm
/// features (column shadows, light pools under the galleries) at about 310k triangles.
inline constexpr float kAtriumMaxEdgeLength = 0.35f;

/// A procedural two-storey courtyard, about 25 x 8 x 25 m, centred on the origin: an open
/// court with a fountain, ringed by arcades (columns and semicircular arches) carrying an
/// upper gallery with a parapet, a roof over the galleries, and outer walls with a door and
/// windows on each side. Lit by a sun, a sky, four lanterns, a spot on the fountain's bronze
/// sphere and emissive panels under the gallery ceilings. Four mobiles (a sliding door, a
/// cart, a crate pushed around the court, a crate hoisted to the upper floor) and seven
/// characters walk scripted loops through sun and shade; the camera walks a ~29 s loop
/// through both long galleries and across the court. No randomness: the scene is the same
/// on every build.
void buildAtrium(BuiltinSceneBuilder& builder);

} // namespace qgi
