#pragma once

#include "runtime/ecs/FrameContext.h"
#include "runtime/ecs/Registry.h"

#include <glm/mat4x4.hpp>

namespace qgi {

struct Transform;

/// Parent links a hierarchy walk follows at most: far deeper than any real scene's, so a
/// loop (which game code can make) ends the walk instead of hanging it.
inline constexpr int kMaxTransformDepth = 256;

/// Local TRS matrix of a Transform.
glm::mat4 localMatrix(const Transform& t);

/** Resolves the node hierarchy into world matrices.
 *  Only entities whose Transform (or an ancestor's) changed this frame are recomputed, and
 *  their WorldTransform is patched only when the matrix actually changes, so
 *  `registry.changed<WorldTransform>()` is exactly the set of entities that moved.
 *  An entity whose parent chain loops is placed as a root (its local matrix), with a warning.
 *  Reads:  const Transform (and its change list), const Name
 *  Writes: WorldTransform (emplaced when missing)                                          */
class TransformSystem {
public:
    void update(Registry& registry, const FrameContext& frame);

private:
    bool mWarnedLoop = false; ///< a parent loop is named once
};

} // namespace qgi
