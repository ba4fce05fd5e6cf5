#pragma once

#include "components/PathFollower.h"

#include <filesystem>

namespace qgi::demo {

/// Reads a camera path from a CSV file with a header line and rows
/// `time,x,y,z,yaw_deg,pitch_deg` (seconds, metres, degrees; yaw about +Y, 0 looks along -Z,
/// pitch positive looks up). Throws qgi::Error naming the file and line on bad input.
PathFollower loadCameraPath(const std::filesystem::path& path);

} // namespace qgi::demo
