#include "runtime/render/ShaderInterface.h"

#include "runtime/core/Error.h"
#include "runtime/render/GpuMesh.h"
#include "runtime/render/RenderScene.h"

namespace qgi {

std::string shaderInterfaceDefines() {
    using namespace shader;
    std::string out;
    const auto define = [&](const char* name, int value) {
        out.append(str("#define ", name, " ", value, "\n"));
    };
    define("ATTRIBUTE_POSITION", kAttributePosition);
    define("ATTRIBUTE_NORMAL", kAttributeNormal);
    define("ATTRIBUTE_UV", kAttributeUv);
    define("ATTRIBUTE_IRRADIANCE", kAttributeIrradiance);
    define("UNIFORM_MODEL", kModel);
    define("UNIFORM_NORMAL_MATRIX", kNormalMatrix);
    define("UNIFORM_VIEW_PROJECTION", kViewProjection);
    define("UNIFORM_ALBEDO", kAlbedo);
    define("UNIFORM_EMISSION", kEmission);
    define("UNIFORM_LIGHTING", kLighting);
    define("UNIFORM_MIRRORED", kMirrored);
    define("UNIFORM_SH", kSh);
    define("UNIFORM_CAMERA_POSITION", kCameraPosition);
    define("UNIFORM_EXPOSURE", kExposure);
    define("UNIFORM_VLF_FACES", kVlfFaces);
    define("UNIFORM_VLF_PARAMS", kVlfParams);
    define("UNIFORM_VLF_FRAME", kVlfFrame);
    define("UNIFORM_VLF_CELL_SCALE", kVlfCellScale);
    define("VLF_ATLAS_UNIT", kVlfAtlasUnit);
    define("VLF_DIRECTIONS_BINDING", kVlfDirectionsBinding);
    define("VLF_TRIANGLES_BINDING", kVlfTrianglesBinding);
    define("VLF_FACES_BINDING", kVlfFacesBinding);
    define("VLF_BLOCKS_BINDING", kVlfBlocksBinding);
    define("VLF_SLOTS_BINDING", kVlfSlotsBinding);
    define("VLF_ATLAS_TILES", kVlfAtlasTiles);
    define("UNIFORM_POINT_CACHE_GRID", kPointCacheGrid);
    define("UNIFORM_POINT_CACHE_DIMS", kPointCacheDims);
    define("UNIFORM_POINT_CACHE_PARAMS", kPointCacheParams);
    define("POINT_CACHE_POINTS_BINDING", kPointCachePointsBinding);
    define("POINT_CACHE_CELL_START_BINDING", kPointCacheCellStartBinding);
    define("POINT_CACHE_CELL_POINTS_BINDING", kPointCacheCellPointsBinding);
    define("BASE_COLOR_UNIT", kBaseColorUnit);
    define("HDR_UNIT", kHdrUnit);
    define("SHADOW_UNIT", kShadowUnit);
    define("LIGHT_BLOCK_BINDING", kLightBlockBinding);
    define("MAX_LIGHTS", kMaxLights);
    define("MAX_SHADOW_LAYERS", kMaxShadowLayers);
    define("LIGHT_POINT", int(LightType::Point));
    define("LIGHT_SPOT", int(LightType::Spot));
    define("LIGHT_DIRECTIONAL", int(LightType::Directional));
    define("LIGHTING_VERTEX", int(SurfaceLighting::VertexIrradiance));
    define("LIGHTING_SH", int(SurfaceLighting::SphericalHarmonics));
    define("LIGHTING_POINT_CACHE", int(SurfaceLighting::PointCache));
    return out;
}

} // namespace qgi
