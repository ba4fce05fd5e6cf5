// The demo's SH probe integration, run as a user would: the `sh.probes` schedule entry shows
// in the profile, and --export-avatars writes the documented CSV, one row per avatar.
#include "systems/sh_probes/AvatarShExport.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace qgi {
namespace {

namespace fs = std::filesystem;

int runDemo(const std::string& arguments, std::string& output) {
    const std::string command = std::string(QGI_DEMO_PATH) + " " + arguments + " 2>&1";
    FILE* pipe = popen(command.c_str(), "r");
    if (!pipe) return -1;
    char buffer[4096];
    while (std::fgets(buffer, sizeof buffer, pipe))
        output += buffer;
    const int status = pclose(pipe);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(ShProbesDemo, ExportsEveryAvatarsShAndProfilesThePhase) {
    const fs::path dir = fs::temp_directory_path() / "qgi_sh_probes_demo";
    fs::create_directories(dir);
    const std::string csvPath = (dir / "avatars.csv").string(), profile = (dir / "run").string();
    std::string output;
    // Photon mode: the avatar's whole lighting comes from the probes.
    const int code = runDemo("--scene cornell --headless --frames 4 --width 64 --height 48 "
                             "--mode photon --photons 20000 --export-avatars " +
                                 csvPath + " --profile " + profile,
                             output);
    ASSERT_EQ(code, 0) << output;

    std::ifstream csv(csvPath);
    std::string header;
    ASSERT_TRUE(std::getline(csv, header));
    EXPECT_EQ(header, avatarShCsvHeader());
    std::vector<std::string> rows;
    for (std::string line; std::getline(csv, line);)
        rows.push_back(line);
    ASSERT_EQ(rows.size(), 1u); // the cornell scene has one avatar
    std::stringstream fields(rows[0]);
    std::vector<std::string> cells;
    for (std::string f; std::getline(fields, f, ',');)
        cells.push_back(f);
    ASSERT_EQ(cells.size(), 31u);
    EXPECT_EQ(cells[0], "avatar");
    for (std::size_t i = 1; i < cells.size(); ++i)
        EXPECT_TRUE(std::isfinite(std::stod(cells[i])));
    EXPECT_GT(std::stod(cells[4]), 0.0) << "L00_r: the avatar inside the lit box is unlit";

    std::ifstream trace(profile + ".csv");
    std::string traceHeader;
    ASSERT_TRUE(std::getline(trace, traceHeader));
    // The phase and its two stages, each a column of the profile.
    for (const char* column : {",sh.probes_ms", ",sh.probes/refresh_ms", ",sh.probes/avatars_ms"})
        EXPECT_NE(traceHeader.find(column), std::string::npos) << column << ": " << traceHeader;
}

} // namespace
} // namespace qgi
