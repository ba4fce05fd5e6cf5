#pragma once

#include <glm/vec3.hpp>

#include <cstdint>
#include <filesystem>
#include <span>
#include <string_view>
#include <vector>

namespace qgi {

enum class PlyFormat { Ascii, BinaryLittleEndian };

/// Per-vertex irradiance as stored in a PLY file (see writePly for the layout).
struct PlyMesh {
    std::vector<glm::vec3> positions;     ///< metres, world space
    std::vector<glm::vec3> normals;       ///< unit, world space
    std::vector<glm::vec3> irradiance;    ///< W/m^2, linear RGB
    std::vector<std::uint8_t> mobile;     ///< 1: the vertex belongs to a mobile mesh, else 0
    std::vector<std::uint32_t> triangles; ///< three vertex indices per face; may be empty
};

/** Writes per-vertex irradiance as a PLY file any tool can read. The header is exactly:
 *
 *      ply
 *      format binary_little_endian 1.0          (or: format ascii 1.0)
 *      comment qgi vertex irradiance: x y z metres, nx ny nz unit normal, er eg eb W/m^2
 *      comment <note>                            (only when `note` is not empty)
 *      element vertex <N>
 *      property float x
 *      property float y
 *      property float z
 *      property float nx
 *      property float ny
 *      property float nz
 *      property float er
 *      property float eg
 *      property float eb
 *      property uchar mobile
 *      element face <M>                          (only when `triangles` is not empty)
 *      property list uchar uint vertex_indices
 *      end_header
 *
 *  Binary vertices are 37 packed bytes each (nine float32, one uint8), faces 13 bytes (count 3,
 *  three uint32). ASCII floats are written with the shortest text that reads back bit-exactly.
 *  A nonzero mobile flag is written as 1. Every span must have one entry per position; `triangles`
 * holds 3 indices per face. `note` (one line) says what the irradiance holds, for whoever opens
 * the file. Throws qgi::Error naming the path when sizes disagree, an index is out of range, the
 * note spans lines, or the file cannot be written. */
void writePly(const std::filesystem::path& path, std::span<const glm::vec3> positions,
              std::span<const glm::vec3> normals, std::span<const glm::vec3> irradiance,
              std::span<const std::uint8_t> mobile, std::span<const std::uint32_t> triangles = {},
              PlyFormat format = PlyFormat::BinaryLittleEndian, std::string_view note = {});

inline void writePly(const std::filesystem::path& path, const PlyMesh& mesh,
                     PlyFormat format = PlyFormat::BinaryLittleEndian, std::string_view note = {}) {
    writePly(path, mesh.positions, mesh.normals, mesh.irradiance, mesh.mobile, mesh.triangles,
             format, note);
}

/// Whether `path` is a regular file that begins as writePly's do (the "ply" line, a format
/// line and qgi's comment): an earlier export, which may be rewritten.
bool isIrradiancePly(const std::filesystem::path& path);

/// Reads a file written by writePly (either format). Other PLY layouts are rejected.
/// Throws qgi::Error naming the path and the offending header line or element.
PlyMesh readPly(const std::filesystem::path& path);

} // namespace qgi
