#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace qgi {

class Registry;
struct PointCache;
struct PointCacheSettings;

/// Version of the cache file layout; a file of another version is stale.
/// 2: the recorded shadow samples (PointCache::reached).
inline constexpr std::uint32_t kPointCacheFileVersion = 2;
/// Revision of the bake and of the shading it stores, part of the key: raised whenever the
/// code changes what a file of the same layout would hold, so files of older code are stale.
/// 2: lamps with a LightStandIn are no area lights of the cache.
/// 3: the soft shadows come from one integration body for traced and replayed samples.
/// 4: points on axis-aligned faces lie on the face's plane exactly.
inline constexpr std::uint32_t kPointCacheBakeRevision = 4;

/** Key of a cache file: FNV-1a 64 over the file version and bake revision, every setting that
 * shapes the point set or its stored shading (resolved values), the scene's static and mobile
 * meshes (world matrix, positions, indices, emission; for emissive static meshes, whether a
 * LightStandIn stands in for them; for mobiles, whether they are out of the world) and every light
 * (kind, pose, colour x intensity, cone). Any change to those gives a different key, so a file made
 * for another scene or other settings is never used. */
std::uint64_t pointCacheKey(const Registry& registry, const PointCacheSettings& resolved);

/** File layout (the writing machine's byte order; an endianness marker rejects others):
 *  "QGIPCACH", u32 version, u32 0x01020304, u64 key, u64 file size in bytes, u64 points,
 *  u32 lights, u32 sample words w, then per array for all points: position (3 f32), normal
 *  (3 f32), radius f32, dart u32, ao f32, direct (3 f32), visibility (lights f32 per point),
 *  reached (lights x w u32 per point); then u64 FNV-1a of every byte
 * before it. Written whole or not at all (writeFileAtomically): a crash or a full disk never
 * leaves half a file under `path`.
 *  Throws qgi::Error when the file cannot be written.                                     */
void writePointCacheFile(const std::string& path, std::uint64_t key, const PointCache& cache);

/// The first bytes of every point cache file.
inline constexpr std::string_view kPointCacheMagic{"QGIPCACH", 8};

/** Reads a file written by writePointCacheFile into `cache` (point set, ao, direct,
 *  visibility, recorded samples; the settings and grid are the caller's). Throws qgi::Error with
 * the reason, and leaves `cache` untouched, when the file is missing, truncated, of another version
 * or machine, made for another key (stale), fails its checksum (corrupt), or holds values out of
 * range (non-finite, normals not unit, AO or visibility outside [0, 1]).              */
void readPointCacheFile(const std::string& path, std::uint64_t key, PointCache& cache);

} // namespace qgi
