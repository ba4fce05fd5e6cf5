#pragma once

#include <string>

namespace qgi {

/// A human-readable name (from the glTF node or the built-in scene). Used in logs and exports.
struct Name {
    std::string value;
};

} // namespace qgi
