#include "systems/animation/AnimationSystem.h"

#include "components/PathFollower.h"
#include "components/Transform.h"
#include "runtime/core/Log.h"

#include <algorithm>
#include <cmath>

namespace qgi {

void samplePath(const PathFollower& path, double t, Transform& pose) {
    const auto& keys = path.keys;
    if (keys.empty()) return;
    const double first = keys.front().time;
    const double last = keys.back().time;
    t += path.timeOffset;
    if (path.loop && last > first) {
        t = first + std::fmod(t - first, last - first);
        if (t < first) t += last - first;
    }
    if (std::isnan(t)) return; // no time (or an endless one on a loop): the pose stays
    if (t <= first) {
        pose.translation = keys.front().position;
        pose.rotation = keys.front().rotation;
        return;
    }
    if (t >= last) {
        pose.translation = keys.back().position;
        pose.rotation = keys.back().rotation;
        return;
    }
    // First key strictly after t; keys are sorted by time.
    // (Clamped: keys a game wrote out of order or with NaN times must not send it past them.)
    const auto next =
        std::clamp(std::upper_bound(keys.begin(), keys.end(), t,
                                    [](double value, const PathKey& k) { return value < k.time; }),
                   keys.begin() + 1, keys.end() - 1);
    const PathKey& b = *next;
    const PathKey& a = *(next - 1);
    const float span = b.time - a.time;
    const float u = span > 0.f ? float((t - a.time) / span) : 1.f;
    pose.translation = glm::mix(a.position, b.position, u);
    pose.rotation = glm::normalize(glm::slerp(a.rotation, b.rotation, u));
}

void AnimationSystem::update(Registry& registry, const FrameContext& frame) {
    if (!std::isfinite(frame.time) && !mWarnedTime) {
        logWarning("animation: frame time ", frame.time,
                   " is not finite; scripted paths hold their poses until it is");
        mWarnedTime = true;
    }
    registry.view<const PathFollower, Transform>().each(
        [&](Entity e, const PathFollower& path, Transform& transform) {
            Transform next = transform;
            samplePath(path, frame.time, next);
            if (next.translation != transform.translation || next.rotation != transform.rotation) {
                transform = next;
                registry.markChanged<Transform>(e);
            }
        });
}

} // namespace qgi
