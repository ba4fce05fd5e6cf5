#pragma once

#include "runtime/scene/SceneInfo.h"

#include <cstdint>

namespace qgi {

/// How the photon update system shoots, keeps and refreshes the photon ray set.
/// `validatePhotonSettings` (called by the system's constructor) rejects absurd values.
struct PhotonSettings {
    /// Photons emitted in all, shared among the lights in proportion to their power (the sum
    /// of the RGB watts) at each full shot. Each photon is one stored path.
    std::uint32_t photonCount = 200'000;
    /// Seeds every random choice: the quasi-random emission's scrambling and the per-bounce
    /// hash. Same seed, same scene: a bit-identical ray set.
    std::uint64_t seed = 1;
    /// Reflections a photon may make; the path ends at the hit after the last one. Russian
    /// roulette ends almost every path long before: with albedo 0.8 only 0.8^32 = 0.08 % of
    /// the power is cut off at 32.
    std::uint32_t maxBounces = 32;
    /// Photons re-shot per frame for lights that moved or changed (progressive refinement,
    /// seed 004 section 7.4), shared among the lights that have photons left to refresh.
    std::uint32_t reshootBudget = 20'000;
    /// Cells of the path index (PhotonPathGrid) along the longest axis of the scene box.
    /// Finer cells give fewer candidate paths per moved mobile but more index entries (memory,
    /// and time to re-index a path). 24: on the atrium (4M photons) 49k candidates a frame in
    /// 226 MiB, against 43k in 300 MiB at 32 and 71k in 175 MiB at 16 (docs/BENCHMARKS.md).
    std::uint32_t gridResolution = 24;
    /// Paths the index re-indexes per frame once re-traced paths pass 1/64 of all (whole
    /// chunks, those with the most re-traced paths first), plus the paths the frame re-shot
    /// for lights that changed; until then a re-traced path is found by its bounding box.
    std::uint32_t gridRefreshBudget = 4096;
    /// A moving mobile keeps the paths near it (those with a segment in a box this share of
    /// its size wider on every side than its old and new bounds, or wider for fast motion:
    /// neighbourhoodBox), updated from each frame's re-traced paths, so that its next moves
    /// inside that box need no path-grid query and read only paths that come near it. 0: the
    /// grid is queried at every move. At most 1.
    float nearPathMargin = 0.125f;
    /// The store is laid out anew (every segment copied once) when its overflow exceeds this
    /// fraction of the live segments: re-traced paths that outgrew their store region's room,
    /// and what they left there. Garbage inside the regions is reclaimed a few regions a frame
    /// (PhotonStoreSpace), so this happens only when paths grow on the whole.
    float compactionFraction = 0.5f;
    /// A segment that hit a mobile which has only translated since (the common case of an
    /// object pushed or sliding) is tested again: when the mobile at its new pose still meets
    /// it first in the same plane at the same distance, to within a millionth of the scene's
    /// diagonal, and no other moved mobile is in the way (static geometry was not before and
    /// still is not), the photon reflects exactly as it did (same point, normal, albedo and
    /// random numbers), so the rest of its path is kept up to its next affected segment
    /// instead of being re-traced. Only the moved mobiles are traced for this, and not at all
    /// when the plane hit slid along the segment (a face moving along its normal). Off: the
    /// seed's rule, every affected path re-traced from its first affected segment
    /// (bit-identical to a fresh shot).
    bool reuseLandedPaths = true;
    /// Re-shoot every photon every frame (PhotonDelta::full): the baseline to compare against.
    bool fullRecompute = false;
    /// Emitters: point, spot and directional lights; triangles whose Material emits.
    /// A scene that models one lamp both ways (the cornell box's luminaire and its punctual
    /// stand-in for hybrid mode) must enable only one of them or the lamp counts twice.
    bool punctualLights = true;
    bool emissiveSurfaces = true;
    /// The box directional lights cover, metres: their photons start on a rectangle across the
    /// light just outside it, so a mobile beyond it gets no directional photons and casts no
    /// photon shadow. Empty (the default): the bounds of every mesh at the first shot, widened
    /// to the scripted path of each mobile with a PathFollower. Set it to the playable area
    /// when game code moves mobiles further; a mobile that leaves it is named in a warning.
    /// Photons spread over a larger box are fewer per square metre. Left as Aabb{} it is unset;
    /// anything else must be a finite range on every axis, flat on one axis at most.
    Aabb directionalBounds{};
};

/// Whether PhotonSettings::directionalBounds was set (anything but Aabb{}).
inline bool directionalBoundsSet(const PhotonSettings& settings) {
    return settings.directionalBounds.min != Aabb{}.min ||
           settings.directionalBounds.max != Aabb{}.max;
}

/// In play the store may hold up to this many times photonCount photons: lights added, and
/// shares dealt anew, take photons while the old ones go dark (PhotonUpdateSystem).
inline constexpr std::uint32_t kMaxPhotonGrowth = 3;
/// The most photons a store may be shot with at `maxBounces` (32-bit segment indices with room
/// for compaction and growth: 2^30 / (kMaxPhotonGrowth (maxBounces + 1))).
std::uint64_t maxPhotonCount(std::uint32_t maxBounces);
/// Throws qgi::Error naming the field when a setting is out of its range.
void validatePhotonSettings(const PhotonSettings& settings);

} // namespace qgi
