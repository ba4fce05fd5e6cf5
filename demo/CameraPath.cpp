#include "demo/CameraPath.h"

#include "runtime/core/Error.h"

#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>

namespace qgi::demo {

PathFollower loadCameraPath(const std::filesystem::path& path) {
    std::error_code error;
    if (path.empty()) fail("--camera-path: the path is empty");
    if (!std::filesystem::exists(path, error)) fail(path.string(), ": no such camera path file");
    if (!std::filesystem::is_regular_file(path, error))
        fail(path.string(), ": the camera path is not a file");
    std::ifstream in(path);
    if (!in) fail(path.string(), ": cannot open camera path");
    PathFollower follower;
    follower.loop = true;
    std::string line;
    int lineNumber = 0;
    while (std::getline(in, line)) {
        ++lineNumber;
        if (line.empty() || line[0] == '#') continue;
        if (lineNumber == 1 && line.starts_with("time")) continue; // the header
        std::replace(line.begin(), line.end(), ',', ' ');
        std::istringstream fields(line);
        float t, x, y, z, yaw, pitch;
        std::string extra;
        if (!(fields >> t >> x >> y >> z >> yaw >> pitch) || (fields >> extra))
            fail(path.string(), ":", lineNumber,
                 ": expected six numbers time,x,y,z,yaw_deg,pitch_deg (a first line starting "
                 "with 'time' is a header)");
        for (float v : {t, x, y, z, yaw, pitch})
            if (!std::isfinite(v)) fail(path.string(), ":", lineNumber, ": value is not finite");
        if (std::abs(pitch) > 90.f)
            fail(path.string(), ":", lineNumber, ": pitch ", pitch,
                 " degrees is past straight up or down (at most 90)");
        if (!follower.keys.empty() && t <= follower.keys.back().time)
            fail(path.string(), ":", lineNumber, ": times must increase");
        const glm::quat rotation = glm::angleAxis(glm::radians(yaw), glm::vec3(0, 1, 0)) *
                                   glm::angleAxis(glm::radians(pitch), glm::vec3(1, 0, 0));
        follower.keys.push_back(PathKey{t, glm::vec3(x, y, z), rotation});
    }
    if (follower.keys.empty()) fail(path.string(), ": camera path has no keys");
    return follower;
}

} // namespace qgi::demo
