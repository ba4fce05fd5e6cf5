// The avatar shader (shaders/scene.frag with common/sh.glsl) against the CPU's order-2
// irradiance (runtime/math/SphericalHarmonics.h, itself checked against the textbook
// harmonics in test_sh_math): each of the nine coefficients on its own, over six normals,
// per pixel. A swapped coefficient or a misplaced convolution constant in the shader fails the
// coefficient it touches.
#include "GlTestWindow.h"
#include "components/Avatar.h"
#include "components/Camera.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/ShLighting.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/math/SphericalHarmonics.h"
#include "runtime/render/GlWindow.h"
#include "systems/render/RenderSystem.h"

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <utility>

namespace qgi {
namespace {

constexpr int kSize = 64;
constexpr float kFov = 0.8f; // radians, vertical

/// A 0.3 m square centred at c facing n (counter-clockwise seen from n).
Mesh squareFacing(const glm::vec3& c, const glm::vec3& n) {
    const glm::vec3 t = glm::normalize(glm::cross(glm::vec3(0.f, 1.f, 0.f), n));
    const glm::vec3 b = glm::cross(n, t);
    Mesh mesh;
    for (const glm::vec2 s :
         {glm::vec2(-1, -1), glm::vec2(1, -1), glm::vec2(1, 1), glm::vec2(-1, 1)}) {
        mesh.positions.push_back(c + 0.15f * (s.x * t + s.y * b));
        mesh.normals.push_back(n);
    }
    mesh.indices = {0, 1, 2, 0, 2, 3};
    return mesh;
}

TEST(ShShader, EachCoefficientShadesAsTheCpuIrradiance) {
    QGI_SKIP_WITHOUT_GL();
    GlWindow window(test::testWindow(kSize, kSize, "qgi test_sh_shader"));
    // Twice: as laid out below, and with the camera and every square moved and turned by one
    // rigid motion G, each square's mesh given in its own turned object space. The image is
    // the same but for the world normals, which the SH is read with: a shader that read it
    // with the view-space or the object-space normal fails the second.
    const glm::mat4 moved = glm::rotate(glm::translate(glm::mat4(1.f), {0.7f, -0.3f, 1.2f}), 0.8f,
                                        glm::normalize(glm::vec3(1.f, 2.f, 0.5f)));
    for (const glm::mat4& g : {glm::mat4(1.f), moved}) {
        SCOPED_TRACE(g == glm::mat4(1.f) ? "in place" : "moved and turned");
        Registry world; // destroyed while the context is current
        const Entity camera = world.create();
        world.emplace<Camera>(camera, Camera{kFov, 0.05f, 20.f, true});
        world.emplace<WorldTransform>(camera, WorldTransform{g}); // looking along g's -Z

        // Six squares 3 m ahead, each with its own normal (all turned towards the camera).
        const glm::vec3 normals[6] = {glm::vec3(0.f, 0.f, 1.f),
                                      glm::normalize(glm::vec3(1.f, 0.f, 1.f)),
                                      glm::normalize(glm::vec3(0.f, 1.f, 1.f)),
                                      glm::normalize(glm::vec3(-1.f, -1.f, 1.f)),
                                      glm::normalize(glm::vec3(1.f, -1.f, 0.6f)),
                                      glm::normalize(glm::vec3(-0.7f, 0.5f, 0.5f))};
        const glm::vec2 centres[6] = {{-0.6f, -0.4f}, {0.f, -0.4f}, {0.6f, -0.4f},
                                      {-0.6f, 0.4f},  {0.f, 0.4f},  {0.6f, 0.4f}};
        const glm::vec3 albedo(0.5f, 0.7f, 0.9f);
        Entity squares[6];
        glm::vec3 worldNormals[6];
        for (int k = 0; k < 6; ++k) {
            squares[k] = world.create();
            // Object space turned by r: the mesh as laid out, taken back through r.
            const glm::mat4 r = glm::rotate(glm::mat4(1.f), 0.2f + 0.3f * float(k),
                                            glm::normalize(glm::vec3(0.3f, 1.f, 0.2f)));
            const glm::mat3 back = glm::transpose(glm::mat3(r));
            Mesh mesh = squareFacing({centres[k], -3.f}, normals[k]);
            for (glm::vec3& p : mesh.positions)
                p = back * p;
            for (glm::vec3& n : mesh.normals)
                n = back * n;
            world.emplace<Mesh>(squares[k], std::move(mesh));
            world.emplace<WorldTransform>(squares[k], WorldTransform{g * r});
            worldNormals[k] = glm::mat3(g) * normals[k];
            world.emplace<Material>(squares[k]).baseColor = albedo;
            world.emplace<Avatar>(squares[k]);
            world.emplace<ShLighting>(squares[k]);
        }

        RenderSettings settings;
        settings.width = kSize;
        settings.height = kSize;
        settings.mode = ShadingMode::Photon; // the SH is the avatars' only light
        RenderSystem renderer(settings);
        const float toNdc = 1.f / (3.f * std::tan(0.5f * kFov));
        for (int i = 0; i < 9; ++i) {
            // L00 keeps the irradiance positive (the shader clamps at zero); coefficient i
            // alone on top of it, a different value per channel.
            sh::ShRgb L{};
            L[0] = glm::vec3(3.f);
            L[i] += glm::vec3(1.f, -0.6f, 0.35f);
            for (const Entity e : squares)
                world.get<ShLighting>(e).coefficients = L;
            renderer.update(world, FrameContext{std::uint64_t(i), 0.0, 0.f, 0});
            world.clearChanges();
            const ImageF hdr = renderer.readHdr();
            for (int k = 0; k < 6; ++k) {
                const int px = int((centres[k].x * toNdc + 1.f) * 0.5f * kSize);
                const int py = int((1.f - centres[k].y * toNdc) * 0.5f * kSize); // top row first
                const glm::vec3 e = sh::irradiance(L, worldNormals[k]);
                for (int c = 0; c < 3; ++c) {
                    const float expected = albedo[c] * glm::one_over_pi<float>() * e[c];
                    EXPECT_NEAR(hdr.pixel(px, py)[c], expected, 1e-4f * expected + 1e-6f)
                        << "coefficient " << i << ", normal " << k << ", channel " << c;
                }
            }
        }
    }
}

} // namespace
} // namespace qgi
