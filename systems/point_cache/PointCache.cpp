#include "systems/point_cache/PointCache.h"

#include <cmath>

namespace qgi {

float PointCache::weight(float d, float R) const {
    if (!(d < R) || !(R > 0.f)) return 0.f;
    const float w = 1.f - d / R;
    switch (settings.falloffExponent) {
    case 2:
        return w * w;
    case 3:
        return w * w * w;
    default:
        return w;
    }
}

void PointCache::buildGrid() {
    std::vector<float> radii(size());
    double sum = 0.0;
    for (std::size_t p = 0; p < size(); ++p) {
        radii[p] = searchRadius(std::uint32_t(p));
        sum += radii[p];
    }
    PointGrid::Params params;
    params.minNormalCosine = settings.minNormalCosine;
    params.planeTolerance = settings.planeTolerance;
    params.cellSize = settings.gridCellSize > 0.f ? settings.gridCellSize
                      : size() > 0                ? float(sum / double(size()))
                                                  : 1.f;
    grid.build(position, normal, radii, params);
}

PointCacheSample PointCache::sample(const glm::vec3& x, const glm::vec3& n) const {
    PointCacheSample out;
    double wSum = 0.0;
    glm::dvec3 d(0.0), i(0.0);
    double a = 0.0;
    grid.forEachInRange(x, n, [&](std::uint32_t p, float distance) {
        const double w = weight(distance, grid.searchRadius(p));
        if (!(w > 0.0)) return;
        ++out.count;
        wSum += w;
        d += w * glm::dvec3(direct[p]);
        i += w * glm::dvec3(indirect[p]);
        a += w * double(ao[p]);
    });
    if (out.count == 0 || !(wSum > 0.0)) {
        out.count = 0;
        return out;
    }
    out.direct = glm::vec3(d / wSum);
    out.indirect = glm::vec3(i / wSum);
    out.ao = float(a / wSum);
    return out;
}

} // namespace qgi
