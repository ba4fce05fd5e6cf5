// libFuzzer harness for the demo's camera path CSV (--camera-path FILE). A path it accepts
// must be one the path follower can play: finite keys at strictly increasing times.

#include "FuzzFile.h"

#include "demo/CameraPath.h"
#include "runtime/core/Finite.h"

#include <glm/gtc/quaternion.hpp>

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto path = qgi::fuzz::writeInput("input.csv", data, size);
    try {
        const qgi::PathFollower follower = qgi::demo::loadCameraPath(path);
        const auto& keys = follower.keys;
        for (std::size_t k = 0; k < keys.size(); ++k) {
            const bool ordered = k == 0 || keys[k].time > keys[k - 1].time;
            const float norm = glm::length(keys[k].rotation);
            if (!std::isfinite(keys[k].time) || !ordered || !qgi::isFinite(keys[k].position) ||
                !(std::abs(norm - 1.f) < 1e-3f)) {
                std::fprintf(stderr, "loadCameraPath accepted key %zu it cannot play\n", k);
                std::abort();
            }
        }
    } catch (const qgi::Error& error) {
        qgi::fuzz::checkMessage(error);
    }
    return 0;
}
