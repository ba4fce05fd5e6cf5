#include "systems/photon_update/PhotonStore.h"

#include <algorithm>

namespace qgi {

void PhotonSegments::clear() {
    origin.clear();
    direction.clear();
    length.clear();
    power.clear();
    hitEntity.clear();
    hitPrimitive.clear();
    bounce.clear();
}

void PhotonSegments::reserve(std::size_t n) {
    origin.reserve(n);
    direction.reserve(n);
    length.reserve(n);
    power.reserve(n);
    hitEntity.reserve(n);
    hitPrimitive.reserve(n);
    bounce.reserve(n);
}

void PhotonSegments::resize(std::size_t n) {
    origin.resize(n);
    direction.resize(n);
    length.resize(n);
    power.resize(n);
    hitEntity.resize(n);
    hitPrimitive.resize(n);
    bounce.resize(n);
}

void PhotonSegments::appendFrom(const PhotonSegments& from, std::size_t s) {
    origin.push_back(from.origin[s]);
    direction.push_back(from.direction[s]);
    length.push_back(from.length[s]);
    power.push_back(from.power[s]);
    hitEntity.push_back(from.hitEntity[s]);
    hitPrimitive.push_back(from.hitPrimitive[s]);
    bounce.push_back(from.bounce[s]);
}

void PhotonSegments::copyFrom(std::size_t to, const PhotonSegments& from, std::size_t first,
                              std::size_t count) {
    const auto copy = [&](const auto& src, auto& dst) {
        std::copy_n(src.begin() + std::ptrdiff_t(first), count, dst.begin() + std::ptrdiff_t(to));
    };
    copy(from.origin, origin);
    copy(from.direction, direction);
    copy(from.length, length);
    copy(from.power, power);
    copy(from.hitEntity, hitEntity);
    copy(from.hitPrimitive, hitPrimitive);
    copy(from.bounce, bounce);
}

void PhotonDelta::clear() {
    full = false;
    paths.clear();
    oldSegments.clear();
    newSegments.clear();
    // Always one more entry than paths, so [first[i], first[i + 1]) is valid for every path.
    oldFirst.assign(1, 0);
    newFirst.assign(1, 0);
    movedMobiles.clear();
    relabels.clear();
}

} // namespace qgi
