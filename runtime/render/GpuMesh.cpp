#include "runtime/render/GpuMesh.h"

#include "components/Mesh.h"

#include <algorithm>
#include <vector>

namespace qgi {
namespace {

template <typename T> GlBuffer createStaticBuffer(std::span<const T> data) {
    GlBuffer buffer = createBuffer();
    glNamedBufferStorage(buffer.id(), GLsizeiptr(std::max<std::size_t>(data.size_bytes(), 1)),
                         data.empty() ? nullptr : data.data(), 0);
    return buffer;
}

void attach(GLuint vertexArray, GpuMeshAttribute attribute, const GlBuffer& buffer,
            GLint components) {
    glVertexArrayVertexBuffer(vertexArray, attribute, buffer.id(), 0,
                              GLsizei(components * sizeof(float)));
    glVertexArrayAttribFormat(vertexArray, attribute, components, GL_FLOAT, GL_FALSE, 0);
    glVertexArrayAttribBinding(vertexArray, attribute, attribute);
    glEnableVertexArrayAttrib(vertexArray, attribute);
}

} // namespace

GpuMesh createGpuMesh(const Mesh& mesh) {
    GpuMesh gpu;
    gpu.vertexCount = std::uint32_t(mesh.positions.size());
    gpu.indexCount = std::uint32_t(mesh.indices.size());
    for (const glm::vec3& p : mesh.positions)
        gpu.bounds.extend(p);

    gpu.positions = createStaticBuffer<glm::vec3>(mesh.positions);
    gpu.normals = createStaticBuffer<glm::vec3>(mesh.normals);
    gpu.indices = createStaticBuffer<std::uint32_t>(mesh.indices);
    const std::vector<glm::vec2> noUvs(mesh.uvs.empty() ? mesh.positions.size() : 0);
    gpu.uvs = createStaticBuffer<glm::vec2>(mesh.uvs.empty() ? noUvs : mesh.uvs);

    // Zero irradiance until the first upload. The zeros come with the storage rather than from
    // glClearNamedBufferData: NVIDIA's driver (580) let such a clear land after the first
    // glNamedBufferSubData of a large buffer, and every vertex stayed black until it next
    // changed.
    gpu.irradiance = createBuffer();
    const std::vector<glm::vec3> zeros(std::max<std::size_t>(mesh.positions.size(), 1));
    glNamedBufferStorage(gpu.irradiance.id(), GLsizeiptr(zeros.size() * sizeof(glm::vec3)),
                         zeros.data(), GL_DYNAMIC_STORAGE_BIT);

    gpu.vertexArray = createVertexArray();
    const GLuint vao = gpu.vertexArray.id();
    attach(vao, kAttributePosition, gpu.positions, 3);
    attach(vao, kAttributeNormal, gpu.normals, 3);
    attach(vao, kAttributeUv, gpu.uvs, 2);
    attach(vao, kAttributeIrradiance, gpu.irradiance, 3);
    glVertexArrayElementBuffer(vao, gpu.indices.id());
    return gpu;
}

void drawGpuMesh(const GpuMesh& mesh) {
    glBindVertexArray(mesh.vertexArray.id());
    glDrawElements(GL_TRIANGLES, GLsizei(mesh.indexCount), GL_UNSIGNED_INT, nullptr);
}

void mergeDirtyRanges(std::vector<DirtyRange>& ranges) {
    std::erase_if(ranges, [](const DirtyRange& r) { return r.end <= r.begin; });
    std::sort(ranges.begin(), ranges.end(),
              [](const DirtyRange& a, const DirtyRange& b) { return a.begin < b.begin; });
    std::size_t out = 0;
    for (const DirtyRange& r : ranges) {
        if (out > 0 && r.begin <= ranges[out - 1].end)
            ranges[out - 1].end = std::max(ranges[out - 1].end, r.end);
        else
            ranges[out++] = r;
    }
    ranges.resize(out);
}

void uploadIrradiance(GpuMesh& mesh, std::span<const glm::vec3> irradiance,
                      std::vector<DirtyRange>& dirty) {
    mergeDirtyRanges(dirty);
    const std::uint32_t limit =
        std::min<std::uint32_t>(mesh.vertexCount, std::uint32_t(irradiance.size()));
    for (const DirtyRange& r : dirty) {
        const std::uint32_t end = std::min(r.end, limit);
        if (r.begin >= end) continue;
        glNamedBufferSubData(mesh.irradiance.id(), GLintptr(r.begin * sizeof(glm::vec3)),
                             GLsizeiptr((end - r.begin) * sizeof(glm::vec3)),
                             irradiance.data() + r.begin);
    }
    dirty.clear();
}

} // namespace qgi
