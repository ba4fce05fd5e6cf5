#pragma once

#include "runtime/ecs/Registry.h"
#include "runtime/io/Ply.h"

#include <filesystem>

namespace qgi {

/// Gathers every StaticMesh and MobileMesh vertex in world space with its VertexIrradiance
/// (zero where an entity has none) and mobile flag, and the triangles, entity after entity in
/// registry order. Avatars are not included: they are lit by SH probes, not per vertex; nor
/// are mobiles out of the world (MobileMesh::active false).
PlyMesh gatherVertexIrradiance(const Registry& registry);

/// Writes gatherVertexIrradiance as PLY (header documented in Ply.h), with `note` as a header
/// comment when not empty. Throws qgi::Error.
void exportVertexIrradiance(const Registry& registry, const std::filesystem::path& path,
                            PlyFormat format = PlyFormat::BinaryLittleEndian,
                            std::string_view note = {});

} // namespace qgi
