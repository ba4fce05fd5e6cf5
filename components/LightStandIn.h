#pragma once

namespace qgi {

/// Tag on a punctual light that stands in for an emissive surface at the same place (a bulb
/// for a lamp's diffuser): hybrid mode's shader draws its direct light, but it emits no
/// photons and adds nothing in photon mode, where the surface's own photons carry the light.
/// Without it a scene that models a lamp both ways would count the lamp twice.
struct LightStandIn {};

} // namespace qgi
