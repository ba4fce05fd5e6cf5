#pragma once

#include <cstdint>

namespace qgi {

struct Aabb;

/// How the SH probe volume (ShProbeSystem) is laid out, projected and kept up to date.
/// `validate(const ShProbeSettings&)` (called by the system's constructor) rejects absurd values.
struct ShProbeSettings {
    /// Distance between neighbouring probes, metres, the same on every axis. 0: the scene
    /// default, the longest side of the scene bounds / cellsAlongLongestAxis.
    float spacing = 0.f;
    /// Used when spacing is 0: cells along the longest side of the scene bounds.
    std::uint32_t cellsAlongLongestAxis = 16;
    /// Building a volume of more probes than this throws qgi::Error (a spacing far too fine).
    std::uint32_t maxProbes = 1u << 20;
    /// Rays per probe projection (a spherical Fibonacci set, turned by a seeded random rotation
    /// per probe). The projection's noise falls as 1/sqrt of this.
    std::uint32_t raysPerProbe = 256;
    /// A probe whose rays hit back faces in more than this share is inside geometry: disabled,
    /// it never contributes to an avatar.
    float backFaceShare = 0.25f;
    /// Stale probes re-projected per frame at most, nearest to an avatar first (0: stale probes
    /// wait for the sweep below; with sweepPerFrame 0 too, the probes are never re-projected). The
    /// frame profiler's "sh.probes" entry shows what this costs.
    std::uint32_t updateBudget = 16;
    /// Probes a sweep visits a frame, in index order and round again, re-projecting each one
    /// the budget did not choose, whether or not anything marked it: every probe is projected
    /// afresh within ceil(probeCount / sweepPerFrame) frames of any change. What the marking
    /// rules below let through (a ray that meets a mobile far away, a surface lit anew beyond
    /// influenceDistance) is put right within that time, and so is a stale probe far from the
    /// avatars that the budget, busy nearer them, keeps passing over. The sweep runs while the
    /// scene changes and for one round after its last change, then rests (an unchanged scene
    /// costs the avatar lookups only). A probe's rays are fixed by (seed, probe), so
    /// re-projecting one whose view did not change gives it the same coefficients bit for bit.
    /// 0: marked probes only, chosen by the budget. At 4 on the atrium (1,536 probes, 256
    /// rays): a round in 384 frames (costs in docs/BENCHMARKS.md).
    std::uint32_t sweepPerFrame = 4;
    /// Probes within this distance of a change (a delta segment's end point, the old or new
    /// bounds of a moved mobile) are marked stale, metres. 0: twice the spacing.
    /// This localises the marking; it bounds no error. It is measured from end points, while a
    /// vertex's new irradiance spreads over its triangles (0.5 m legs where this is 1 m in the
    /// test below), so a probe left alone can still see changed surfaces near it. What holds is
    /// exact accounting: along a ray that meets no moved mobile, a stale probe's radiance is off
    /// by albedo / pi x the change of the hit triangle's vertex irradiance, at most its largest
    /// vertex change (tests/unit/test_sh_probes.cpp, ProbesLeftUnmarkedAfterAPhotonDelta...).
    float influenceDistance = 0.f;
    /// A half-spacing cell of the lattice needs this many end points of PhotonDelta segments
    /// (counted over frames until it marks, then from zero again; counts halve every 32
    /// frames) before it marks probes: the
    /// scattered later bounces of re-traced
    /// paths change per-vertex irradiance by a photon or two here and there, far below the
    /// estimate's own noise (DETP's default disc holds about 64 photons), and would otherwise
    /// keep the whole volume stale while anything moves.
    std::uint32_t minDeltaEndPoints = 4;
    /// A moved mobile also marks the probes it can cover at least this share of (the sphere of
    /// directions) by its bounding sphere of radius rho: those within rho / (2 sqrt(share)) of
    /// its old or new bounds (at 0.01, five radii). A mobile in view of a farther probe changes
    /// its projection by less than this share of the radiance difference it makes, on average
    /// over the rays' rotations. One projection counts rays, not solid angle: a mobile however
    /// small can catch one of the raysPerProbe rays (1/64 of the sphere at 64), and a cap of
    /// this share up to N of them (N = 2 of 64), so per probe and pose the bound is
    /// N / raysPerProbe of 4 pi times the largest radiance in view, times the largest |Y_i| for
    /// coefficient i. (In that test one ray of 64 meeting the cube 4 m away moves a dimly lit
    /// probe's irradiance by 16 %.)
    float mobileSolidAngleShare = 0.01f;
    /// Visibility lattice points per cell edge: an avatar's weight for each corner probe is the
    /// trilinear blend of whether the probe is visible from the lattice points around it.
    /// Lattice spacing = spacing / this; keep it below the avatars' radius.
    std::uint32_t visibilitySubdivisions = 4;
    /// Hybrid mode (the renderer draws punctual lights' direct light on avatars and surfaces):
    /// surfaces a probe sees add the punctual lights' direct light by a shadow ray per hit to one
    /// light, picked in proportion to its unshadowed contribution (per-vertex
    /// irradiance carries only the reflected part), and the probes carry no punctual light of
    /// their own. Photon mode (false): per-vertex irradiance carries all light, and each probe
    /// adds the direct light of the punctual lights that shoot photons (not LightStandIn),
    /// shadowed, as directional sources, since the avatar shader adds none.
    bool hybrid = false;
    /// Seeds the per-probe rotations of the ray directions.
    std::uint64_t seed = 1;
};

/// Throws qgi::Error naming the first field out of range.
void validate(const ShProbeSettings& settings);

/// The spacing in use for a scene of `bounds`: settings.spacing, or the default. Throws
/// qgi::Error when the bounds are empty or not finite and no spacing is set.
float resolveProbeSpacing(const ShProbeSettings& settings, const Aabb& bounds);

} // namespace qgi
