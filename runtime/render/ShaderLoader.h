#pragma once

#include "runtime/render/GlHandle.h"

#include <filesystem>
#include <initializer_list>
#include <string_view>

namespace qgi {

/// qgi's GLSL folder, looked up once: the QGI_SHADER_DIR environment variable when set;
/// else `shaders/` next to the executable, then `../share/qgi/shaders` from it (the layout
/// `cmake --install` makes); else the source tree the program was built from. Throws
/// qgi::Error listing the places tried when none holds the shaders.
std::filesystem::path shaderDirectory();

/** Compiles and links a program from GLSL 4.50 files, one per stage; the stage follows from the
 *  extension (.vert .frag .geom .comp). Paths are relative to `root`.
 *  - `#include "common/x.glsl"` is replaced by that file (relative to `root`). Like #pragma
 *    once, a file is included at most once per stage, so repeats and cycles are harmless.
 *  - `defines` (e.g. "#define MAX_LIGHTS 64\n") goes right after the #version line, so the
 *    C++ side owns constants such as binding points.
 *  - Compiler messages ("0:12(5): error ...") are rewritten to name the file and line the
 *    text came from ("common/lighting.glsl:7(5): error ...").
 *  Throws qgi::Error (one line: file, line, compiler message) on any failure.              */
GlProgram loadProgram(std::initializer_list<std::string_view> files, std::string_view defines = {},
                      const std::filesystem::path& root = shaderDirectory());

} // namespace qgi
