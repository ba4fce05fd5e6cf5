#pragma once
// Golden reference images for the GL tests. A golden EXR stores what the CPU reference
// (ReferenceTracer) computed when it was written, so comparing it with a fresh trace is a
// regression tripwire for the reference code itself, not a test of the renderer: the renderer
// tests compare with a fresh reference.

#include "ReferenceTracer.h"

#include "runtime/io/ImageF.h"

#include <filesystem>
#include <string>
#include <vector>

namespace qgi::test {

enum class GoldenCheck { Compared, Written };

/// Where a golden image of this scene may lie when it was written on another platform: the
/// reference is traced in double from float inputs (vertices, matrices, light and camera
/// positions, some from float sin and cos) and stored as float. A compiler or libm may put each
/// float input one ulp (<= 2^-23 R, R the largest coordinate in the scene) away, and round
/// the double arithmetic differently by ~1e-15 relative, far below a float ulp. The inputs
/// move the surfaces, their distances to the lights and the shadow edges against a pixel's
/// ray by a few such ulps, as moving the point the ray hits does: the range is the reference
/// over camera rays that meet the surface 2^-21 R (four ulps) away from the pixel centre's
/// hit, each shaded in full (referenceRange, pointOffset, shadeEveryOffsetRay).
RefRange roundingRange(const std::vector<RefTriangle>& triangles,
                       const std::vector<RefLight>& lights, const RefCamera& camera);

/// With QGI_WRITE_REFERENCE=1 in the environment, writes `fresh` (colour only, float) to
/// `golden` and returns Written: the caller skips the test, and a person looks at the image
/// before committing it. Otherwise checks, with gtest expectations, that every stored value
/// differs from the fresh one by no more than the width of `range` (roundingRange of the scene
/// `fresh` was traced from: both lie in it) plus one float ulp of the larger, for the rounding
/// of the double result to float. float32 EXR stores values exactly. On the platform that
/// wrote the file the two are equal.
GoldenCheck checkGolden(const std::filesystem::path& golden, const ImageF& fresh,
                        const RefRange& range);

/// For a failed comparison: writes <name>_actual.exr, <name>_reference.exr and
/// <name>_diff.exr (|actual - expected|) into `dir` and records a test failure naming them.
void writeFailureImages(const std::filesystem::path& dir, const std::string& name,
                        const ImageF& actual, const ImageF& expected);

} // namespace qgi::test
