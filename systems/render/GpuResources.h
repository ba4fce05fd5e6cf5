#pragma once

#include "runtime/ecs/Entity.h"
#include "runtime/render/GlHandle.h"
#include "runtime/render/GpuMesh.h"

#include <unordered_map>
#include <vector>

namespace qgi {

/** World resource: the GPU copies of the scene's meshes and textures, created lazily by the
 *  RenderSystem. Keyed by Entity (never by pointer); entries of destroyed entities, or of
 *  entities that lost their Mesh, are freed on the next frame. Holds GL objects: destroy the
 *  registry while the GL context is still current (create the GlWindow first).           */
struct GpuResources {
    std::unordered_map<Entity, GpuMesh> meshes; ///< an empty GpuMesh marks a rejected Mesh
    std::vector<GlTexture> textures;            ///< by TextureLibrary index, created on use
};

} // namespace qgi
