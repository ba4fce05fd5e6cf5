// qgi-demo: a walkthrough of a quasi-static scene. All lighting lives in systems/; this
// program only parses the command line, loads the scene and runs the frame schedule.
#include "demo/DemoApp.h"
#include "demo/DemoOptions.h"

#include "runtime/core/Error.h"
#include "runtime/core/Log.h"

#include <cstdio>
#include <exception>
#include <filesystem>
#include <new>

int main(int argc, char** argv) {
    const auto parsed = qgi::demo::parseDemoOptions(argc, argv);
    if (parsed.exitCode) return *parsed.exitCode;
    try {
        return qgi::demo::runDemo(parsed.options);
    } catch (const qgi::Error& e) {
        std::fprintf(stderr, "qgi-demo: error: %s\n", qgi::printable(e.what()).c_str());
        return 1;
    } catch (const std::filesystem::filesystem_error& e) { // the user's disk, not our bug
        std::fprintf(stderr, "qgi-demo: error: %s\n", qgi::printable(e.what()).c_str());
        return 1;
    } catch (const std::bad_alloc&) { // the machine's memory, not our bug
        std::fprintf(stderr, "qgi-demo: error: out of memory: lower --photons (about 400 bytes "
                             "each on the Cornell box), --vlf-level or --vlf-lines, or load a "
                             "smaller scene\n");
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "qgi-demo: internal error: %s\n", qgi::printable(e.what()).c_str());
        return 3;
    }
}
