// libFuzzer harness for the irradiance PLY reader (readPly); start it from files writePly
// wrote (a demo run's --export-irradiance, in both formats).

#include "FuzzFile.h"

#include "runtime/io/Ply.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto path = qgi::fuzz::writeInput("input.ply", data, size);
    try {
        const qgi::PlyMesh mesh = qgi::readPly(path);
        const std::size_t n = mesh.positions.size();
        if (mesh.normals.size() != n || mesh.irradiance.size() != n || mesh.mobile.size() != n ||
            mesh.triangles.size() % 3 != 0) {
            std::fprintf(stderr, "readPly returned arrays of different sizes\n");
            std::abort();
        }
        for (const std::uint32_t index : mesh.triangles)
            if (index >= n) {
                std::fprintf(stderr, "readPly returned index %u of %zu vertices\n", index, n);
                std::abort();
            }
    } catch (const qgi::Error& error) {
        qgi::fuzz::checkMessage(error);
    }
    return 0;
}
