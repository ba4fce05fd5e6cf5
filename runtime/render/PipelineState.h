#pragma once

#include <epoxy/gl.h>

namespace qgi {

/** Everything a pass depends on, set in full by applyState() at the start of every pass, so
 *  no pass inherits state from the one before it (or from an overlay drawn in between).
 *  Blending, stencil, scissor, sRGB conversion, face culling, logic ops, rasterizer discard
 *  and primitive restart are always off in this renderer (both sides of thin, single-sided
 *  walls are drawn); front faces wind counter-clockwise and clip depth runs from -1 to 1.  */
struct PipelineState {
    GLuint framebuffer = 0; ///< 0: the window's framebuffer
    GLint viewportWidth = 0;
    GLint viewportHeight = 0;
    bool depthTest = true;
    bool depthWrite = true;
    /// Slope-scaled depth bias (glPolygonOffset factor, units); 0, 0: none.
    float depthBiasSlope = 0.f;
    float depthBiasConstant = 0.f;
};

void applyState(const PipelineState& state);

} // namespace qgi
