#pragma once

#include "demo/DemoOptions.h"

namespace qgi::demo {

/// Loads the scene, builds the frame schedule and runs the walkthrough. Returns the exit code.
/// Throws qgi::Error on bad input (scene file, camera path, unwritable output).
int runDemo(const DemoOptions& options);

} // namespace qgi::demo
