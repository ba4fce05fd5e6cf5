#include "runtime/render/PassTimer.h"

#include "runtime/core/Log.h"
#include "runtime/profile/FrameProfiler.h"

namespace qgi {

void PassTimer::collect(FrameQueries& frame) {
    if (frame.used == 0) return;
    // Queries complete in submission order: when the last is available, all are.
    GLuint available = GL_FALSE;
    glGetQueryObjectuiv(frame.passes[frame.used - 1].query.id(), GL_QUERY_RESULT_AVAILABLE,
                        &available);
    if (!available) return;
    for (std::size_t i = 0; i < frame.used; ++i) {
        GLuint64 nanoseconds = 0;
        glGetQueryObjectui64v(frame.passes[i].query.id(), GL_QUERY_RESULT, &nanoseconds);
        mProfiler->recordSample(frame.passes[i].name, frame.frameIndex, -1.0,
                                double(nanoseconds) * 1e-6, FrameProfiler::Track::Gpu);
    }
    frame.used = 0;
}

void PassTimer::beginFrame(FrameProfiler* profiler, std::uint64_t frameIndex) {
    mProfiler = profiler;
    mFrameIndex = frameIndex;
    if (!mProfiler || mCpuTimed) return;
    for (FrameQueries& frame : mRing)
        collect(frame);
    FrameQueries& current = mRing[frameIndex % kFramesInFlight];
    if (current.used != 0)
        logDebug("GPU pass times of frame ", current.frameIndex, " were not ready in time");
    current.frameIndex = frameIndex;
    current.used = 0;
}

void PassTimer::beginPass(std::string_view name) {
    if (!mProfiler) return;
    if (mCpuTimed) {
        glFinish(); // the previous pass's work is not this pass's
        mPassName = name;
        mPassStartMs = mProfiler->nowMs();
        return;
    }
    FrameQueries& frame = mRing[mFrameIndex % kFramesInFlight];
    if (frame.used == frame.passes.size())
        frame.passes.push_back({name, createQuery(GL_TIME_ELAPSED)});
    PendingPass& pass = frame.passes[frame.used];
    pass.name = name;
    glBeginQuery(GL_TIME_ELAPSED, pass.query.id());
}

void PassTimer::endPass() {
    if (!mProfiler) return;
    if (mCpuTimed) {
        glFinish();
        mProfiler->recordSample(mPassName, mFrameIndex, mPassStartMs,
                                mProfiler->nowMs() - mPassStartMs, FrameProfiler::Track::Cpu);
        return;
    }
    glEndQuery(GL_TIME_ELAPSED);
    ++mRing[mFrameIndex % kFramesInFlight].used;
}

} // namespace qgi
