// Point cache query (seed 003 sections 1.6-1.7), the fragment shader's copy of
// PointCache::sample / PointGrid (systems/point_cache): a uniform grid of cells, each listing
// the points whose thickened oriented disc overlaps it (CSR: uCellStart, uCellPoints), and the
// blend w_p = (1 - d / R_p)^k over the points in range:
//   |x - p| < R_p,  n_p . n >= minNormalCosine,  |n_p . (x - p)| <= planeTolerance R_p.
// Layouts: SceneRenderer.cpp (bindings and uniforms); every macro comes from the C++ side.

struct CachePoint {
    vec4 position;   // xyz: metres; w: search radius R_p
    vec4 normal;     // xyz: unit; w: ambient occlusion
    vec4 irradiance; // rgb: W/m^2, area lights with soft shadows + indirect; w: spacing radius
};

layout(std430, binding = POINT_CACHE_POINTS_BINDING) readonly buffer PointCachePoints {
    CachePoint uCachePoints[];
};
layout(std430, binding = POINT_CACHE_CELL_START_BINDING) readonly buffer PointCacheCellStart {
    uint uCellStart[];
};
layout(std430, binding = POINT_CACHE_CELL_POINTS_BINDING) readonly buffer PointCacheCellPoints {
    uint uCellPoints[];
};

layout(location = UNIFORM_POINT_CACHE_GRID) uniform vec4 uPointGrid;     // origin, cell size
layout(location = UNIFORM_POINT_CACHE_DIMS) uniform ivec4 uPointDims;    // cells, falloff k
layout(location = UNIFORM_POINT_CACHE_PARAMS) uniform vec4 uPointParams; // minCos, planeTol,
                                                                         // enabled, show points

// Blended irradiance at x (unit normal n); w = 0 when no point is in range (the caller falls
// back). `nearest` returns the distance to the closest point in range over its spacing radius
// (for the point-set view), large when none.
vec4 pointCacheIrradiance(vec3 x, vec3 n, out float nearest) {
    nearest = 1e9;
    if (uPointParams.z < 0.5) return vec4(0.0);
    vec3 cell = floor((x - uPointGrid.xyz) / uPointGrid.w);
    if (any(lessThan(cell, vec3(0.0))) || any(greaterThanEqual(cell, vec3(uPointDims.xyz))))
        return vec4(0.0);
    ivec3 c = ivec3(cell);
    uint index = uint((c.z * uPointDims.y + c.y) * uPointDims.x + c.x);
    uint begin = uCellStart[index], end = uCellStart[index + 1u];
    vec3 sum = vec3(0.0);
    float weightSum = 0.0;
    for (uint k = begin; k < end; ++k) {
        CachePoint p = uCachePoints[uCellPoints[k]];
        vec3 offset = x - p.position.xyz;
        float R = p.position.w;
        float d2 = dot(offset, offset);
        if (d2 >= R * R) continue;
        if (dot(p.normal.xyz, n) < uPointParams.x) continue;
        if (abs(dot(p.normal.xyz, offset)) > uPointParams.y * R) continue;
        float d = sqrt(d2);
        float w = 1.0 - d / R;
        if (uPointDims.w >= 2) w *= 1.0 - d / R;
        if (uPointDims.w >= 3) w *= 1.0 - d / R;
        if (w <= 0.0) continue;
        sum += w * p.irradiance.rgb;
        weightSum += w;
        nearest = min(nearest, d / p.irradiance.w);
    }
    return weightSum > 0.0 ? vec4(sum / weightSum, 1.0) : vec4(0.0);
}
