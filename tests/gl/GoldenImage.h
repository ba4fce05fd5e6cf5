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

/// Where a golden image of this scene may lie when it was written by another build: the
/// reference is traced in double from float inputs (vertices, matrices, light and camera
/// positions, some from float sin and cos) and stored as float. The double arithmetic rounds
/// differently by ~1e-15 relative, far below a float ulp, but the float inputs come out of
/// chains of float operations (mesh refinement, matrix products) that another compiler, libm
/// or optimisation level rounds differently, or contracts into fused multiply-adds
/// differently: each input may lie several ulps (2^-23 R each, R the largest coordinate in the
/// scene) away. That moves the surfaces, their distances to the lights and the shadow edges
/// against a pixel's ray as moving the point the ray hits does: the range is the reference
/// over camera rays that meet the surface 2^-18 R (32 ulps) away from the pixel centre's hit,
/// each shaded in full (referenceRange, pointOffset, shadeEveryOffsetRay). The sanitizer
/// build (RelWithDebInfo) differs from the Release build that wrote the files by up to 16 ulps'
/// worth. A tripwire for changes to the reference, not a bound derived from first principles.
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
