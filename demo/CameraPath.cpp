#include "demo/CameraPath.h"

#include "runtime/core/Error.h"
#include "runtime/math/Pose.h"

#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

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
    constexpr std::array<const char*, 6> kFields{"time", "x", "y", "z", "yaw_deg", "pitch_deg"};
    while (std::getline(in, line)) {
        ++lineNumber;
        // A byte-order mark (spreadsheets write one) and Windows line ends are no content.
        if (lineNumber == 1 && line.starts_with("\xEF\xBB\xBF")) line.erase(0, 3);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.empty() || line[0] == '#') continue;
        if (lineNumber == 1 && line.starts_with("time")) continue; // the header
        const auto where = [&] { return str(path.string(), ":", lineNumber, ": "); };
        std::replace(line.begin(), line.end(), ',', ' ');
        std::istringstream words(line);
        std::vector<std::string> tokens;
        for (std::string word; words >> word;)
            tokens.push_back(word);
        if (tokens.size() != kFields.size())
            fail(where(), "expected six numbers time,x,y,z,yaw_deg,pitch_deg, found ",
                 tokens.size(), " fields (a first line starting with 'time' is a header)");
        std::array<float, 6> v{};
        for (std::size_t i = 0; i < kFields.size(); ++i) {
            const std::string& token = tokens[i];
            const char* begin = token.data() + (token.starts_with('+') ? 1 : 0);
            const char* end = token.data() + token.size();
            const auto [stop, code] = std::from_chars(begin, end, v[i]);
            if (code == std::errc::result_out_of_range)
                fail(where(), kFields[i], " '", token, "' is out of a 32-bit float's range");
            if (code != std::errc() || stop != end)
                fail(where(), kFields[i], " '", token, "' is not a number");
            if (!std::isfinite(v[i])) fail(where(), kFields[i], " '", token, "' is not finite");
        }
        const auto [t, x, y, z, yaw, pitch] = v;
        // Where rays and poses still mean something (runtime/math/Pose.h), as for meshes.
        for (std::size_t a = 1; a <= 3; ++a)
            if (std::abs(v[a]) > kMaxPoseReach)
                fail(where(), kFields[a], " ", v[a], " m is farther from the origin than ",
                     kMaxPoseReach, " m");
        if (std::abs(pitch) > 90.f)
            fail(where(), "pitch ", pitch, " degrees is past straight up or down (at most 90)");
        if (!follower.keys.empty() && t <= follower.keys.back().time)
            fail(where(), "times must increase");
        const glm::quat rotation = glm::angleAxis(glm::radians(yaw), glm::vec3(0, 1, 0)) *
                                   glm::angleAxis(glm::radians(pitch), glm::vec3(1, 0, 0));
        follower.keys.push_back(PathKey{t, glm::vec3(x, y, z), rotation});
    }
    if (follower.keys.empty()) fail(path.string(), ": camera path has no keys");
    return follower;
}

} // namespace qgi::demo
