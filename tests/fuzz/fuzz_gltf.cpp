// libFuzzer harness for the glTF importer: the input is a .glb when it starts with the GLB
// magic, a .gltf otherwise. A file the importer refuses must leave the registry empty.
// README.md, "Fuzzing the loaders", runs it with tests/data/gltf as the seed corpus.

#include "FuzzFile.h"

#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/scene/SceneLoader.h"

#include <cstring>

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    qgi::setLogLevel(qgi::LogLevel::Error); // warnings about odd files are expected
    // The corpus's external buffer, for inputs that keep its URI.
    std::filesystem::copy_file(QGI_FUZZ_GLTF_DIR "/good/triangle.bin",
                               qgi::fuzz::folder() / "triangle.bin",
                               std::filesystem::copy_options::overwrite_existing);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const bool glb = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
    const auto path = qgi::fuzz::writeInput(glb ? "input.glb" : "input.gltf", data, size);
    qgi::Registry registry;
    try {
        qgi::importGltf(registry, path, qgi::SceneOptions{});
    } catch (const qgi::Error& error) {
        qgi::fuzz::checkMessage(error);
        if (registry.aliveCount() != 0) {
            std::fprintf(stderr, "refused file left %zu entities\n", registry.aliveCount());
            std::abort();
        }
    }
    return 0;
}
