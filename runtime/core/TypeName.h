#pragma once
// Readable C++ type names for messages ("qgi::RayScene", not "N3qgi8RaySceneE").

#include <cxxabi.h>

#include <cstdlib>
#include <memory>
#include <string>
#include <typeinfo>

namespace qgi {

template <typename T> std::string typeName() {
    const char* mangled = typeid(T).name();
    int status = 0;
    const std::unique_ptr<char, decltype(&std::free)> readable(
        abi::__cxa_demangle(mangled, nullptr, nullptr, &status), &std::free);
    return status == 0 && readable ? std::string(readable.get()) : std::string(mangled);
}

} // namespace qgi
