// glTF import, buffer views and accessors: the byte ranges, strides and component types
// tinygltf does not check, and the reads of positions, normals, texture coordinates, indices,
// key times and rotations (strided, sparse, or zeros without a buffer view).

#include "runtime/scene/GltfReader.h"

#include "runtime/core/Finite.h"

#include <algorithm>
#include <cmath>

namespace qgi::gltf_detail {

namespace {

/// Bytes per component of a glTF 2.0 accessor component type; 0 for anything else.
std::size_t componentBytes(int componentType) {
    switch (componentType) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return 4;
    default:
        return 0; // INT and DOUBLE exist in tinygltf, not in glTF 2.0 accessors
    }
}

const char* componentName(int componentType) {
    switch (componentType) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
        return "BYTE";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return "UNSIGNED_BYTE";
    case TINYGLTF_COMPONENT_TYPE_SHORT:
        return "SHORT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return "UNSIGNED_SHORT";
    case TINYGLTF_COMPONENT_TYPE_INT:
        return "INT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
        return "UNSIGNED_INT";
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return "FLOAT";
    case TINYGLTF_COMPONENT_TYPE_DOUBLE:
        return "DOUBLE";
    default:
        return "unknown";
    }
}

const char* typeName(int type) {
    switch (type) {
    case TINYGLTF_TYPE_SCALAR:
        return "SCALAR";
    case TINYGLTF_TYPE_VEC2:
        return "VEC2";
    case TINYGLTF_TYPE_VEC3:
        return "VEC3";
    case TINYGLTF_TYPE_VEC4:
        return "VEC4";
    case TINYGLTF_TYPE_MAT2:
        return "MAT2";
    case TINYGLTF_TYPE_MAT3:
        return "MAT3";
    case TINYGLTF_TYPE_MAT4:
        return "MAT4";
    default:
        return "unknown";
    }
}

/// Bytes of one accessor element, with the column padding the spec requires for small matrices.
std::size_t elementBytes(int componentType, int type) {
    const std::size_t c = componentBytes(componentType);
    switch (type) {
    case TINYGLTF_TYPE_MAT2:
        return c == 1 ? 8 : 4 * c;
    case TINYGLTF_TYPE_MAT3:
        return c == 1 ? 12 : c == 2 ? 24 : 9 * c;
    default:
        return c * std::size_t(tinygltf::GetNumComponentsInType(std::uint32_t(type)));
    }
}

} // namespace

void GltfReader::checkBufferViews() const {
    for (std::size_t i = 0; i < mModel.bufferViews.size(); ++i) {
        const tinygltf::BufferView& view = mModel.bufferViews[i];
        const std::string field = str("bufferViews[", i, "]");
        checkIndex(field + ".buffer", view.buffer, mModel.buffers.size(), "buffers");
        const std::size_t size = mModel.buffers[std::size_t(view.buffer)].data.size();
        if (view.byteLength == 0) fail(field + ".byteLength", "0; must be at least 1");
        if (view.byteOffset > size || view.byteLength > size - view.byteOffset)
            fail(field + ".byteLength", "byteOffset ", view.byteOffset, " + byteLength ",
                 view.byteLength, " run past the end of buffer ", view.buffer, " (", size,
                 " bytes)");
        if (view.byteStride != 0 &&
            (view.byteStride < 4 || view.byteStride > 252 || view.byteStride % 4 != 0))
            fail(field + ".byteStride", view.byteStride, " is not a multiple of 4 in [4, 252]");
    }
}

void GltfReader::checkAccessors() const {
    for (std::size_t i = 0; i < mModel.accessors.size(); ++i) {
        const tinygltf::Accessor& a = mModel.accessors[i];
        const std::string field = str("accessors[", i, "]");
        if (componentBytes(a.componentType) == 0)
            fail(field + ".componentType", a.componentType, " (", componentName(a.componentType),
                 ") is not a glTF 2.0 accessor component type");
        if (a.count == 0) fail(field + ".count", "0; must be at least 1");
        if (a.bufferView < 0) continue; // no data: rejected where it would be read
        checkIndex(field + ".bufferView", a.bufferView, mModel.bufferViews.size(), "buffer views");
        const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(a.bufferView)];
        const std::size_t element = elementBytes(a.componentType, a.type);
        const std::size_t stride = view.byteStride != 0 ? view.byteStride : element;
        if (stride < element)
            fail(str("bufferViews[", a.bufferView, "].byteStride"), stride, " is smaller than the ",
                 element, "-byte elements of ", field);
        const std::size_t length = view.byteLength;
        // byteOffset + stride * (count - 1) + element <= length, without overflow.
        if (a.byteOffset > length || element > length - a.byteOffset ||
            a.count - 1 > (length - a.byteOffset - element) / stride)
            fail(field + ".count", a.count, " elements of ", element, " bytes (stride ", stride,
                 ") from byteOffset ", a.byteOffset, " do not fit in buffer view ", a.bufferView,
                 " (", length, " bytes)");
    }
}

AccessorData GltfReader::useAccessor(const std::string& usage, int index, int type,
                                     std::initializer_list<int> componentTypes,
                                     std::size_t decodedElement) const {
    checkIndex(usage, index, mModel.accessors.size(), "accessors");
    const tinygltf::Accessor& a = mModel.accessors[std::size_t(index)];
    const std::string field = str("accessors[", index, "]");
    if (a.type != type)
        fail(field + ".type", typeName(a.type), " but ", usage, " needs ", typeName(type));
    if (std::find(componentTypes.begin(), componentTypes.end(), a.componentType) ==
        componentTypes.end())
        fail(field + ".componentType", componentName(a.componentType), " is not allowed for ",
             usage);
    const std::size_t element = elementBytes(a.componentType, a.type);
    const bool copied = a.sparse.isSparse || a.bufferView < 0;
    if (copied && a.count > kGltfMaxFileBytes / element)
        fail(field + ".count", a.count, " elements of ", element,
             " bytes would take more than a file may hold (", kGltfMaxFileBytes, " bytes)");
    // What the whole file decodes is bounded too: one accessor within the limit above, or
    // read by many meshes, or many of them, could still ask for more than memory holds.
    const std::uintmax_t decoded =
        std::uintmax_t(a.count) * ((copied ? element : 0) + decodedElement);
    if (decoded > kGltfMaxDecodedBytes - mDecodedBytes)
        fail(field + ".count", a.count, " elements read as ", usage, " decode to ", decoded,
             " bytes, which would bring the file's decoded accessors to ", mDecodedBytes + decoded,
             " bytes, over the limit of ", kGltfMaxDecodedBytes);
    mDecodedBytes += decoded;
    if (!copied) {
        const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(a.bufferView)];
        return {mModel.buffers[std::size_t(view.buffer)].data.data() + view.byteOffset +
                    a.byteOffset,
                view.byteStride != 0 ? view.byteStride : element, a.count, a.componentType};
    }
    // Without a buffer view the elements are zeros; a sparse accessor then replaces some of
    // them (glTF 2.0 section 3.6.2.3). Both are laid out tightly in memory kept for the read.
    std::vector<unsigned char>& dense = mDenseAccessors.emplace_back(a.count * element, 0);
    if (a.bufferView >= 0) {
        const AccessorData base = rawView(index, element);
        for (std::size_t i = 0; i < a.count; ++i)
            std::copy_n(base.data + i * base.stride, element, dense.data() + i * element);
    }
    if (a.sparse.isSparse) applySparse(index, element, dense);
    return {dense.data(), element, a.count, a.componentType};
}

AccessorData GltfReader::rawView(int index, std::size_t element) const {
    const tinygltf::Accessor& a = mModel.accessors[std::size_t(index)];
    const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(a.bufferView)];
    return {mModel.buffers[std::size_t(view.buffer)].data.data() + view.byteOffset + a.byteOffset,
            view.byteStride != 0 ? view.byteStride : element, a.count, a.componentType};
}

void GltfReader::applySparse(int index, std::size_t element,
                             std::vector<unsigned char>& dense) const {
    const tinygltf::Accessor& a = mModel.accessors[std::size_t(index)];
    const std::string field = str("accessors[", index, "].sparse");
    const auto& sparse = a.sparse;
    if (sparse.count < 1 || std::size_t(sparse.count) > a.count)
        fail(field + ".count", sparse.count, " is not in [1, ", a.count, "]");
    const std::size_t count = std::size_t(sparse.count);
    // A view holding `count` tightly packed items of `bytes` each from `offset`, or a failure.
    const auto block = [&](const std::string& where, int viewIndex, int offset,
                           std::size_t bytes) -> const unsigned char* {
        checkIndex(where + ".bufferView", viewIndex, mModel.bufferViews.size(), "buffer views");
        const tinygltf::BufferView& view = mModel.bufferViews[std::size_t(viewIndex)];
        if (offset < 0 || std::size_t(offset) > view.byteLength ||
            count > (view.byteLength - std::size_t(offset)) / bytes)
            fail(where + ".byteOffset", count, " items of ", bytes, " bytes from ", offset,
                 " do not fit in buffer view ", viewIndex, " (", view.byteLength, " bytes)");
        return mModel.buffers[std::size_t(view.buffer)].data.data() + view.byteOffset +
               std::size_t(offset);
    };
    const int indexType = sparse.indices.componentType;
    if (indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        fail(field + ".indices.componentType", componentName(indexType),
             " is not an unsigned integer type");
    const std::size_t indexBytes = componentBytes(indexType);
    const unsigned char* indices =
        block(field + ".indices", sparse.indices.bufferView, sparse.indices.byteOffset, indexBytes);
    const unsigned char* values =
        block(field + ".values", sparse.values.bufferView, sparse.values.byteOffset, element);
    std::size_t previous = 0;
    for (std::size_t i = 0; i < count; ++i) {
        const unsigned char* p = indices + i * indexBytes;
        const std::size_t target = indexBytes == 1   ? p[0]
                                   : indexBytes == 2 ? load<std::uint16_t>(p)
                                                     : load<std::uint32_t>(p);
        if (target >= a.count || (i > 0 && target <= previous))
            fail(field + ".indices", "element ", i, " is ", target,
                 ": indices must increase and stay below the count ", a.count);
        previous = target;
        std::copy_n(values + i * element, element, dense.data() + target * element);
    }
}

std::vector<glm::vec3> GltfReader::readVec3(const std::string& usage, int index) const {
    const AccessorData a = useAccessor(usage, index, TINYGLTF_TYPE_VEC3,
                                       {TINYGLTF_COMPONENT_TYPE_FLOAT}, sizeof(glm::vec3));
    std::vector<glm::vec3> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        out[i] = {load<float>(p), load<float>(p + 4), load<float>(p + 8)};
        if (!isFinite(out[i])) fail(usage, "element ", i, " is not finite");
    }
    return out;
}

std::vector<glm::vec2> GltfReader::readTexcoords(const std::string& usage, int index) const {
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_VEC2,
                    {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT},
                    sizeof(glm::vec2));
    if (a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT &&
        !mModel.accessors[std::size_t(index)].normalized)
        fail(str("accessors[", index, "].normalized"), usage, " stored as ",
             componentName(a.componentType), " must be normalized");
    std::vector<glm::vec2> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
            out[i] = {load<float>(p), load<float>(p + 4)};
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            out[i] = glm::vec2(float(p[0]), float(p[1])) / 255.f;
            break;
        default:
            out[i] = glm::vec2(float(load<std::uint16_t>(p)), float(load<std::uint16_t>(p + 2))) /
                     65535.f;
        }
        if (!std::isfinite(out[i].x) || !std::isfinite(out[i].y))
            fail(usage, "element ", i, " is not finite");
    }
    return out;
}

std::vector<std::uint32_t> GltfReader::readIndices(const std::string& usage, int index,
                                                   std::size_t vertexCount) const {
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_SCALAR,
                    {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT},
                    sizeof(std::uint32_t));
    std::vector<std::uint32_t> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            out[i] = p[0];
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            out[i] = load<std::uint16_t>(p);
            break;
        default:
            out[i] = load<std::uint32_t>(p);
        }
        if (out[i] >= vertexCount)
            fail(usage, "element ", i, " is ", out[i], ", not below the vertex count ",
                 vertexCount);
    }
    return out;
}

std::vector<float> GltfReader::readScalars(const std::string& usage, int index) const {
    const AccessorData a = useAccessor(usage, index, TINYGLTF_TYPE_SCALAR,
                                       {TINYGLTF_COMPONENT_TYPE_FLOAT}, sizeof(float));
    std::vector<float> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        out[i] = load<float>(a.data + i * a.stride);
        if (!std::isfinite(out[i])) fail(usage, "element ", i, " is not finite");
    }
    return out;
}

std::vector<glm::vec4> GltfReader::readRotations(const std::string& usage, int index) const {
    // Floats, or normalized integers of either sign (glTF allows all for rotations). Not
    // normalised here: a cubic spline's tangents are not rotations.
    const AccessorData a =
        useAccessor(usage, index, TINYGLTF_TYPE_VEC4,
                    {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_BYTE,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_SHORT,
                     TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT},
                    sizeof(glm::vec4));
    std::vector<glm::vec4> out(a.count);
    for (std::size_t i = 0; i < a.count; ++i) {
        const unsigned char* p = a.data + i * a.stride;
        for (int c = 0; c < 4; ++c) {
            switch (a.componentType) {
            case TINYGLTF_COMPONENT_TYPE_FLOAT:
                out[i][c] = load<float>(p + 4 * c);
                break;
            case TINYGLTF_COMPONENT_TYPE_BYTE:
                out[i][c] = std::max(float(load<std::int8_t>(p + c)) / 127.f, -1.f);
                break;
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
                out[i][c] = float(p[c]) / 255.f;
                break;
            case TINYGLTF_COMPONENT_TYPE_SHORT:
                out[i][c] = std::max(float(load<std::int16_t>(p + 2 * c)) / 32767.f, -1.f);
                break;
            default:
                out[i][c] = float(load<std::uint16_t>(p + 2 * c)) / 65535.f;
            }
        }
        if (!isFinite(glm::vec3(out[i])) || !std::isfinite(out[i].w))
            fail(usage, "element ", i, " is not finite");
    }
    return out;
}

} // namespace qgi::gltf_detail
