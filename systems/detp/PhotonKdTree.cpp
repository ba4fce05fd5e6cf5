#include "systems/detp/PhotonKdTree.h"

#include "runtime/scene/SceneInfo.h"

#include <glm/gtc/constants.hpp>
#include <oneapi/tbb/parallel_invoke.h>

namespace qgi {
namespace {

/// Ranges at least this long build their two halves in parallel.
constexpr std::size_t kParallelBuild = std::size_t(1) << 15;

} // namespace

void PhotonKdTree::build(std::vector<Photon> photons) {
    mPhotons = std::move(photons);
    mAxes.assign(mPhotons.size(), 0);
    buildRange(0, mPhotons.size());
}

void PhotonKdTree::buildRange(std::size_t lo, std::size_t end) {
    if (end <= lo) return;
    Aabb box;
    for (std::size_t i = lo; i < end; ++i)
        box.extend(mPhotons[i].position);
    const glm::vec3 extent = box.extent();
    const int axis =
        extent.x >= extent.y ? (extent.x >= extent.z ? 0 : 2) : (extent.y >= extent.z ? 1 : 2);
    // The median of the inclusive range [lo, end - 1], as the search computes it.
    const std::size_t median = lo + (end - 1 - lo) / 2;
    const auto first = mPhotons.begin();
    std::nth_element(
        first + std::ptrdiff_t(lo), first + std::ptrdiff_t(median), first + std::ptrdiff_t(end),
        [axis](const Photon& a, const Photon& b) { return a.position[axis] < b.position[axis]; });
    mAxes[median] = std::uint8_t(axis);
    if (end - lo >= kParallelBuild)
        tbb::parallel_invoke([&] { buildRange(lo, median); }, [&] { buildRange(median + 1, end); });
    else {
        buildRange(lo, median);
        buildRange(median + 1, end);
    }
}

glm::vec3 PhotonKdTree::estimateIrradiance(const glm::vec3& center, const glm::vec3& normal,
                                           std::uint32_t k, float maxRadius,
                                           std::vector<Neighbour>& scratch) const {
    const float radius2 = nearest(
        center, k, maxRadius * maxRadius,
        [&normal](const Photon& p) { return glm::dot(p.direction, normal) < 0.f; }, scratch);
    // k photons at exactly the query point leave no area to divide by: no estimate.
    if (!(radius2 > 0.f)) return glm::vec3(0.f);
    glm::vec3 power(0.f);
    for (const Neighbour& n : scratch)
        power += mPhotons[n.index].power;
    return power / (glm::pi<float>() * radius2);
}

} // namespace qgi
