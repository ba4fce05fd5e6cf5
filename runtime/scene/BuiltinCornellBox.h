#pragma once

#include "runtime/scene/BuiltinSceneBuilder.h"

namespace qgi {

/// Default refinement bound of the Cornell box, metres: 2 cm resolves the blocks' contact
/// shadows in per-vertex lighting at about 29k triangles.
inline constexpr float kCornellBoxMaxEdgeLength = 0.02f;

/// The Cornell box from Cornell University's published measurements (the "Cornell Box data"
/// page), in metres, Y up, right-handed: the data's (x, y, z) mm map to
/// ((278 - x) / 1000, y / 1000, -z / 1000), a half turn about Y that puts the standard camera
/// (278, 273, -800) mm at (0, 0.273, 0.8) m looking along -Z into the open front. The short
/// block is a mobile that slides towards the green wall and back; a small avatar walks a loop
/// in the free floor space in front of the tall block.
void buildCornellBox(BuiltinSceneBuilder& builder);

/// The Cornell box with a glossy floor and a mirror tall block (the specular Cornell box of
/// seed 002, Figs 6.5 and 6.10), for the VLF: the floor keeps 0.4 of its diffuse albedo and
/// gets a modified Phong lobe k_s = 0.5, n_s = 40; the tall block becomes a mirror with
/// k_s = 0.85 and a faint diffuse part (albedo 0.05).
void buildCornellBoxGlossy(BuiltinSceneBuilder& builder);

} // namespace qgi
