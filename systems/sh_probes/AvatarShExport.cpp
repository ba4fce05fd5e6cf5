#include "systems/sh_probes/AvatarShExport.h"

#include "components/Avatar.h"
#include "components/Name.h"
#include "components/ShLighting.h"
#include "components/WorldTransform.h"
#include "runtime/core/Error.h"
#include "runtime/ecs/Registry.h"
#include "runtime/io/AtomicFile.h"

#include <cstdio>
#include <fstream>
#include <sstream>

namespace qgi {
namespace {

std::string csvField(const std::string& text) {
    if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
    std::string quoted = "\"";
    for (const char c : text) {
        if (c == '"') quoted += '"';
        quoted += c;
    }
    return quoted + "\"";
}

std::string number(float value) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.9g", double(value));
    return buffer;
}

} // namespace

std::string avatarShCsvHeader() {
    static constexpr const char* kNames[9] = {"L00",  "L1m1", "L10", "L11", "L2m2",
                                              "L2m1", "L20",  "L21", "L22"};
    std::string header = "avatar,x,y,z";
    for (const char* name : kNames)
        for (const char* channel : {"_r", "_g", "_b"})
            header += std::string(",") + name + channel;
    return header;
}

bool isAvatarShCsv(const std::filesystem::path& path) {
    std::error_code error;
    if (!std::filesystem::is_regular_file(path, error)) return false; // a FIFO would block
    std::ifstream file(path, std::ios::binary);
    const std::string header = avatarShCsvHeader() + '\n';
    std::string head(header.size(), '\0');
    file.read(head.data(), std::streamsize(head.size()));
    return std::size_t(file.gcount()) == head.size() && head == header;
}

void exportAvatarSh(const Registry& registry, const std::filesystem::path& path) {
    std::ostringstream out;
    out << avatarShCsvHeader() << '\n';
    registry.view<const Avatar, const WorldTransform, const ShLighting>().each(
        [&](Entity e, const Avatar&, const WorldTransform& world, const ShLighting& lighting) {
            const Name* name = registry.tryGet<Name>(e);
            out << csvField(name ? name->value : "entity" + std::to_string(e.index));
            for (int k = 0; k < 3; ++k)
                out << ',' << number(world.matrix[3][k]);
            for (const auto& c : lighting.coefficients)
                out << ',' << number(c.r) << ',' << number(c.g) << ',' << number(c.b);
            out << '\n';
        });
    writeFileAtomically(path, out.view(), "the avatar SH export");
}

} // namespace qgi
