#include "demo/Overlay.h"

#include "runtime/core/Error.h"
#include "runtime/profile/FrameProfiler.h"

#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>
#include <imgui.h>

#include <algorithm>
#include <string_view>
#include <utility>
#include <vector>

namespace qgi::demo {

Overlay::Overlay(GLFWwindow* window) : mWindow(window) {
    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGuiIO& io = ImGui::GetIO();
    io.IniFilename = nullptr; // nothing written beside the game
    ImGui::StyleColorsDark();
    // The backends chain to the callbacks GLFW already has; the fly camera polls.
    if (!ImGui_ImplGlfw_InitForOpenGL(window, true)) {
        ImGui::DestroyContext();
        fail("overlay: Dear ImGui could not start on this window");
    }
    if (!ImGui_ImplOpenGL3_Init("#version 450")) { // its GL loader found no libGL
        ImGui_ImplGlfw_Shutdown();
        ImGui::DestroyContext();
        fail("overlay: Dear ImGui could not load OpenGL for its drawing");
    }
}

Overlay::~Overlay() {
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
}

bool Overlay::wantsMouse() const {
    return mVisible && ImGui::GetIO().WantCaptureMouse;
}

void Overlay::draw(const FrameProfiler& profiler, const OverlayInfo& info) {
    const bool f1 = glfwGetKey(mWindow, GLFW_KEY_F1) == GLFW_PRESS;
    if (f1 && !mF1Down) mVisible = !mVisible;
    mF1Down = f1;
    const auto now = std::chrono::steady_clock::now();
    const auto smooth = [](double& smoothed, double value) {
        if (value > 0.0) smoothed = smoothed > 0.0 ? 0.9 * smoothed + 0.1 * value : value;
    };
    if (mLastDraw != std::chrono::steady_clock::time_point{})
        smooth(mFrameMs, std::chrono::duration<double, std::milli>(now - mLastDraw).count());
    mLastDraw = now;
    if (!mVisible || profiler.frameCount() == 0) return;

    // The newest frame whose render passes have reported: on a GPU their timer queries are
    // read a few frames late (PassTimer); elsewhere the frame just run.
    std::size_t last = profiler.frameCount() - 1;
    for (std::size_t back = 0; back <= 6 && back < profiler.frameCount(); ++back)
        if (profiler.sampleMs(profiler.frameCount() - 1 - back, "render/scene") >= 0.0) {
            last = profiler.frameCount() - 1 - back;
            break;
        }
    smooth(mScheduleMs, profiler.frameMs(profiler.frameCount() - 1));

    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    ImGui::SetNextWindowPos(ImVec2(10.f, 10.f), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowBgAlpha(0.75f);
    ImGui::Begin("qgi", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
    ImGui::Text("%s", info.scene.c_str());
    ImGui::TextUnformatted(info.lighting.c_str());
    ImGui::Text("frame %.1f ms (%.0f fps), systems %.1f ms", mFrameMs,
                mFrameMs > 0.0 ? 1000.0 / mFrameMs : 0.0, mScheduleMs);
    ImGui::Separator();
    // The last frame's entries: systems, each followed by its stages, indented (a stage is
    // recorded when it closes, before its system).
    const auto recorded = profiler.frameSamples(last);
    std::vector<std::pair<std::string_view, double>> samples;
    const auto isStageOf = [](std::string_view stage, std::string_view system) {
        return stage.size() > system.size() && stage.starts_with(system) &&
               stage[system.size()] == '/';
    };
    for (const auto& entry : recorded) {
        if (entry.first.find('/') != std::string_view::npos) continue;
        samples.push_back(entry);
        for (const auto& stage : recorded)
            if (isStageOf(stage.first, entry.first)) samples.push_back(stage);
    }
    for (const auto& entry : recorded) // stages whose system did not run
        if (entry.first.find('/') != std::string_view::npos &&
            std::find(samples.begin(), samples.end(), entry) == samples.end())
            samples.push_back(entry);
    double longest = 0.0;
    for (const auto& [name, ms] : samples)
        longest = std::max(longest, ms);
    if (ImGui::BeginTable("profile", 3, ImGuiTableFlags_SizingFixedFit)) {
        for (const auto& [name, ms] : samples) {
            const std::size_t slash = name.rfind('/');
            const std::string_view shown =
                slash == std::string_view::npos ? name : name.substr(slash + 1);
            ImGui::TableNextRow();
            ImGui::TableNextColumn();
            if (slash != std::string_view::npos) ImGui::Indent();
            ImGui::TextUnformatted(shown.data(), shown.data() + shown.size());
            if (slash != std::string_view::npos) ImGui::Unindent();
            ImGui::TableNextColumn();
            ImGui::Text("%7.2f ms", ms);
            ImGui::TableNextColumn();
            ImGui::ProgressBar(longest > 0.0 ? float(ms / longest) : 0.f, ImVec2(80.f, 0.f), "");
        }
        ImGui::EndTable();
    }
    ImGui::Separator();
    ImGui::Text("mobile: %s%s", info.selected.empty() ? "none (Tab)" : info.selected.c_str(),
                info.lampsOff ? "   lamps off" : "");
    if (ImGui::CollapsingHeader("keys")) {
        ImGui::TextUnformatted("WASD, Q/E, right drag: fly (Shift: faster); C: back to the path");
        ImGui::TextUnformatted("Tab: next mobile; arrows, PgUp/PgDn: move it; H: out / back");
        ImGui::TextUnformatted("L: lamps off / on; P: point-cache points");
        ImGui::TextUnformatted("F12: screenshot; F1: this overlay; Esc: quit");
    }
    if (info.pointsShown) ImGui::TextUnformatted("showing the point cache's points");
    ImGui::End();
    ImGui::Render();
    glBindFramebuffer(GL_FRAMEBUFFER, 0); // over the window's image, whatever the frame bound
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
}

} // namespace qgi::demo
