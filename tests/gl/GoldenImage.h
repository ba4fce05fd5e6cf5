#pragma once
// Golden reference images for the GL tests. A golden EXR stores what the independent CPU
// reference computes, so the file is backed by that math rather than by the renderer.

#include "runtime/io/ImageF.h"

#include <filesystem>
#include <string>

namespace qgi::test {

enum class GoldenCheck { Compared, Written };

/// With QGI_WRITE_REFERENCE=1 in the environment, writes `fresh` (colour only, float) to
/// `golden` and returns Written: the caller skips the test, and a person looks at the image
/// before committing it. Otherwise checks, with gtest expectations, that the stored image
/// equals `fresh`: float32 EXR stores values exactly, and another compiler may round the double
/// ray arithmetic (or the float mesh processing) differently in the last bits, which moves
/// smooth values by ~1e-7 and can only flip pixels whose rays graze an edge within ~1e-12 m,
/// so 0.1 % of the values may differ and the rest must agree to 1e-5 relative.
GoldenCheck checkGolden(const std::filesystem::path& golden, const ImageF& fresh);

/// For a failed comparison: writes <name>_actual.exr, <name>_reference.exr and
/// <name>_diff.exr (|actual - expected|) into `dir` and records a test failure naming them.
void writeFailureImages(const std::filesystem::path& dir, const std::string& name,
                        const ImageF& actual, const ImageF& expected);

} // namespace qgi::test
