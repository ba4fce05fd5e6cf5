#include "runtime/render/PipelineState.h"

namespace qgi {
namespace {

void setEnabled(GLenum capability, bool enabled) {
    if (enabled)
        glEnable(capability);
    else
        glDisable(capability);
}

} // namespace

void applyState(const PipelineState& state) {
    glBindFramebuffer(GL_FRAMEBUFFER, state.framebuffer);
    glViewport(0, 0, state.viewportWidth, state.viewportHeight);
    glDisable(GL_SCISSOR_TEST);
    glDisable(GL_STENCIL_TEST);
    glDisable(GL_BLEND);
    glDisable(GL_FRAMEBUFFER_SRGB);
    glDisable(GL_MULTISAMPLE);
    setEnabled(GL_DEPTH_TEST, state.depthTest);
    glDepthFunc(GL_LESS);
    glDepthMask(state.depthWrite ? GL_TRUE : GL_FALSE);
    glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    glDisable(GL_CULL_FACE);
    glDisable(GL_DEPTH_CLAMP);
    glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    // Shaders tell faces apart by gl_FrontFacing, and depth runs from -1 to 1 in clip space.
    glFrontFace(GL_CCW);
    glClipControl(GL_LOWER_LEFT, GL_NEGATIVE_ONE_TO_ONE);
    glDisable(GL_RASTERIZER_DISCARD);
    glDisable(GL_COLOR_LOGIC_OP);
    glDisable(GL_SAMPLE_ALPHA_TO_COVERAGE);
    glDisable(GL_PRIMITIVE_RESTART);
    const bool bias = state.depthBiasSlope != 0.f || state.depthBiasConstant != 0.f;
    setEnabled(GL_POLYGON_OFFSET_FILL, bias);
    glPolygonOffset(state.depthBiasSlope, state.depthBiasConstant);
}

} // namespace qgi
