#pragma once

#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"

namespace qgi {

struct PathFollower;
struct Transform;

/// The pose of a path at time `t` seconds: linear in position, slerp in rotation; wraps when
/// the path loops, holds the last key otherwise. A path with no keys, or a time that is NaN
/// (or infinite on a looping path), leaves `pose` unchanged.
void samplePath(const PathFollower& path, double t, Transform& pose);

/** Moves scripted entities (cameras, mobiles, avatars, lights) along their paths.
 *  The pose is a function of frame time only, so a run is reproducible frame by frame.
 *  Reads:  const PathFollower, FrameContext::time
 *  Writes: Transform (patched only when the pose changes, so a still path costs nothing
 *          further down the frame)                                                    */
class AnimationSystem {
public:
    void update(Registry& registry, const FrameContext& frame);

private:
    bool mWarnedTime = false;
};

} // namespace qgi
