#include "runtime/render/ShaderLoader.h"

#include "runtime/core/Error.h"
#include "runtime/core/Log.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace qgi {
namespace {

namespace fs = std::filesystem;

std::string_view trimmed(std::string_view s) {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front())))
        s.remove_prefix(1);
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back())))
        s.remove_suffix(1);
    return s;
}

/// A multi-line log as one line, its lines separated by " | ".
std::string joinLines(std::string_view log) {
    std::string out;
    while (!log.empty()) {
        const std::size_t end = std::min(log.find('\n'), log.size());
        if (const std::string_view line = trimmed(log.substr(0, end)); !line.empty())
            out.append(out.empty() ? "" : " | ").append(line);
        log.remove_prefix(std::min(end + 1, log.size()));
    }
    return out;
}

GLenum stageOf(const fs::path& file) {
    const std::string ext = file.extension().string();
    if (ext == ".vert") return GL_VERTEX_SHADER;
    if (ext == ".frag") return GL_FRAGMENT_SHADER;
    if (ext == ".geom") return GL_GEOMETRY_SHADER;
    if (ext == ".comp") return GL_COMPUTE_SHADER;
    fail("shader '", file.string(), "': unknown stage extension '", ext,
         "' (use .vert .frag .geom .comp)");
}

/// One stage's source with its includes expanded, and where each of its lines came from.
/// No #line directives: drivers disagree on source-string numbers (Mesa reports 0 for many
/// errors), so compiler messages are mapped back through the line table instead.
class StageSource {
public:
    StageSource(const fs::path& root, const std::string& file, std::string_view defines)
        : mRoot(root) {
        const std::string text = readFile(file, "");
        std::string_view rest = text;
        const std::string_view first = nextLine(rest);
        if (!trimmed(first).starts_with("#version"))
            fail("shader '", file, "': the first line must be #version");
        mIncluded.push_back(file);
        appendLine(first, file, 1);
        int defineLine = 1;
        for (std::string_view lines = defines; !lines.empty(); ++defineLine)
            appendLine(nextLine(lines), "<defines>", defineLine);
        expand(rest, file, 2);
    }

    const std::string& text() const { return mText; }

    /// The compiler log on one line, each "<source>:<line>" prefix replaced by "file:line".
    std::string describeLog(std::string_view log) const {
        std::string out;
        while (!log.empty()) {
            std::string_view line = trimmed(nextLine(log));
            if (line.empty()) continue;
            if (!out.empty()) out.append(" | ");
            // Mesa "0:12(5): error", NVIDIA "0(12) : error", AMD "ERROR: 0:12: ..."
            for (const std::string_view prefix : {"ERROR: ", "WARNING: "})
                if (line.starts_with(prefix)) {
                    out.append(prefix);
                    line.remove_prefix(prefix.size());
                }
            if (const std::size_t at = line.find_first_of(":(");
                at != std::string_view::npos && at > 0 && at + 1 < line.size()) {
                std::size_t number = 0;
                const char* begin = line.data() + at + 1;
                const auto [end, ec] = std::from_chars(begin, line.data() + line.size(), number);
                if (ec == std::errc() && number >= 1 && number <= mOrigins.size()) {
                    const Origin& origin = mOrigins[number - 1];
                    out.append(str(origin.file, ":", origin.line));
                    line.remove_prefix(std::size_t(end - line.data()));
                    if (line.starts_with(')')) line.remove_prefix(1); // NVIDIA's "0(12)"
                }
            }
            out.append(line);
        }
        return out;
    }

private:
    struct Origin {
        std::string_view file; ///< points into mIncluded or a literal
        int line;
    };

    static std::string_view nextLine(std::string_view& rest) {
        const std::size_t end = std::min(rest.find('\n'), rest.size());
        const std::string_view line = rest.substr(0, end);
        rest.remove_prefix(std::min(end + 1, rest.size()));
        return line;
    }

    std::string readFile(const std::string& file, const std::string& includedFrom) const {
        std::ifstream in(mRoot / file, std::ios::binary);
        if (!in)
            fail("cannot read shader '", (mRoot / file).string(), "'",
                 includedFrom.empty() ? "" : " included from ", includedFrom);
        return std::string(std::istreambuf_iterator<char>(in), {});
    }

    void appendLine(std::string_view line, std::string_view file, int lineNumber) {
        mText.append(line).append("\n");
        mOrigins.push_back({file, lineNumber});
    }

    void expand(std::string_view rest, std::string_view file, int firstLine) {
        for (int lineNumber = firstLine; !rest.empty(); ++lineNumber) {
            const std::string_view line = nextLine(rest);
            const std::string_view directive = trimmed(line);
            if (directive.starts_with("#version"))
                fail("shader '", file, "' line ", lineNumber, ": #version after the first line");
            if (!directive.starts_with("#include")) {
                appendLine(line, file, lineNumber);
                continue;
            }
            const std::string where = str(file, ":", lineNumber);
            const std::size_t open = directive.find('"');
            const std::size_t close = directive.rfind('"');
            if (open == std::string_view::npos || close <= open)
                fail("shader '", where, "': expected #include \"file\"");
            const std::string name(directive.substr(open + 1, close - open - 1));
            if (std::find(mIncluded.begin(), mIncluded.end(), name) != mIncluded.end()) continue;
            const std::string text = readFile(name, where);
            mIncluded.push_back(name);
            expand(text, mIncluded.back(), 1);
        }
    }

    const fs::path& mRoot;
    std::deque<std::string> mIncluded; ///< a deque: Origin::file points into its elements
    std::vector<Origin> mOrigins;      ///< per line of mText
    std::string mText;
};

std::string shaderLog(GLuint shader) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::string log(std::size_t(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader, GLsizei(log.size()), nullptr, log.data());
    return log.c_str();
}

std::string programLog(GLuint program) {
    GLint length = 0;
    glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
    std::string log(std::size_t(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program, GLsizei(log.size()), nullptr, log.data());
    return log.c_str();
}

GlShader compileStage(const fs::path& root, const std::string& file, std::string_view defines) {
    const GLenum stage = stageOf(file);
    const StageSource source(root, file, defines);
    GlShader shader(glCreateShader(stage));
    const char* text = source.text().c_str();
    glShaderSource(shader.id(), 1, &text, nullptr);
    glCompileShader(shader.id());
    GLint ok = GL_FALSE;
    glGetShaderiv(shader.id(), GL_COMPILE_STATUS, &ok);
    const std::string log = source.describeLog(shaderLog(shader.id()));
    if (!ok) fail("cannot compile shader '", (root / file).string(), "': ", log);
    if (!log.empty()) logWarning("shader '", file, "': ", log);
    return shader;
}

} // namespace

fs::path shaderDirectory() {
    static const fs::path found = [] {
        // A folder holds qgi's shaders when it has this file.
        const auto holdsShaders = [](const fs::path& dir) {
            std::error_code error;
            return fs::is_regular_file(dir / "common" / "lighting.glsl", error);
        };
        std::vector<fs::path> tried;
        if (const char* env = std::getenv("QGI_SHADER_DIR"); env && *env) {
            if (holdsShaders(env)) return fs::path(env);
            fail("QGI_SHADER_DIR='", env, "' holds no qgi shaders (common/lighting.glsl)");
        }
        std::error_code error;
        const fs::path executable = fs::read_symlink("/proc/self/exe", error);
        if (!error) {
            tried.push_back(executable.parent_path() / "shaders");
            tried.push_back(executable.parent_path().parent_path() / "share" / "qgi" / "shaders");
        }
        tried.emplace_back(QGI_SHADER_DIR);
        for (const fs::path& dir : tried)
            if (holdsShaders(dir)) return dir;
        std::string list;
        for (const fs::path& dir : tried)
            list += (list.empty() ? "" : ", ") + dir.string();
        fail("cannot find qgi's shaders (tried ", list, "; set QGI_SHADER_DIR)");
    }();
    return found;
}

GlProgram loadProgram(std::initializer_list<std::string_view> files, std::string_view defines,
                      const fs::path& root) {
    std::vector<GlShader> shaders;
    std::string names;
    for (const std::string_view file : files) {
        shaders.push_back(compileStage(root, std::string(file), defines));
        names.append(names.empty() ? "" : ", ").append(file);
    }
    GlProgram program(glCreateProgram());
    for (const GlShader& shader : shaders)
        glAttachShader(program.id(), shader.id());
    glLinkProgram(program.id());
    for (const GlShader& shader : shaders)
        glDetachShader(program.id(), shader.id());
    GLint ok = GL_FALSE;
    glGetProgramiv(program.id(), GL_LINK_STATUS, &ok);
    if (!ok)
        fail("cannot link shader program (", names, "): ", joinLines(programLog(program.id())));
    return program;
}

} // namespace qgi
