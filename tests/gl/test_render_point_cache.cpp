// The fragment shader's point-cache blend (shaders/common/pointcache.glsl) against the CPU
// query (PointCache::sample) it mirrors, pixel by pixel (runs under `xvfb-run -a`).
#include "GlTestWindow.h"
#include "components/Camera.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/PointCacheShaded.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/ecs/Registry.h"
#include "runtime/render/GlWindow.h"
#include "systems/point_cache/PointCache.h"
#include "systems/render/RenderSystem.h"

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <random>

namespace qgi {
namespace {

constexpr int kSize = 96;
constexpr float kAlbedo = 0.5f, kHeight = 3.f, kFov = 0.9f;

TEST(RenderPointCache, FragmentBlendMatchesTheCpuQuery) {
    QGI_SKIP_WITHOUT_GL();
    GlWindow context(test::testWindow(kSize, kSize, "qgi test_render_point_cache"));
    // Each falloff exponent the settings allow (the shader has a branch for each).
    for (const std::uint32_t falloff : {1u, 2u, 3u}) {
        SCOPED_TRACE(::testing::Message() << "falloff exponent " << falloff);
        Registry world;
        // A 4 x 4 m floor at y = 0 facing up, no lights: the cache lights it where its points
        // reach, its per-vertex irradiance elsewhere. Its mesh is given in an object space
        // turned about y and moved, so the shader must query with world positions.
        const glm::mat4 model = glm::rotate(glm::translate(glm::mat4(1.f), {0.3f, 0.f, -0.2f}),
                                            0.7f, glm::vec3(0.f, 1.f, 0.f));
        const Entity floor = world.create();
        Mesh& mesh = world.emplace<Mesh>(floor);
        for (const glm::vec3& corner : {glm::vec3(-2.f, 0.f, 2.f), glm::vec3(2.f, 0.f, 2.f),
                                        glm::vec3(2.f, 0.f, -2.f), glm::vec3(-2.f, 0.f, -2.f)})
            mesh.positions.push_back(glm::vec3(glm::inverse(model) * glm::vec4(corner, 1.f)));
        mesh.normals.assign(4, glm::vec3(0.f, 1.f, 0.f));
        mesh.indices = {0, 1, 2, 0, 2, 3};
        world.emplace<WorldTransform>(floor, WorldTransform{model});
        Material material;
        material.baseColor = glm::vec3(kAlbedo);
        world.emplace<Material>(floor, material);
        // Where no point reaches, the shader falls back to this per-vertex irradiance.
        const glm::vec3 vertexIrradiance(0.37f, 0.21f, 0.11f);
        VertexIrradiance& vi = world.emplace<VertexIrradiance>(floor);
        vi.irradiance.assign(4, vertexIrradiance);
        vi.dirty.push_back({0, 4});
        world.emplace<PointCacheShaded>(floor);

        // The camera kHeight above the origin looking straight down (local -Z to world -Y).
        const Entity camera = world.create();
        Camera& cam = world.emplace<Camera>(camera);
        cam.yfov = kFov;
        cam.active = true;
        const glm::mat4 pose = glm::rotate(glm::translate(glm::mat4(1.f), {0.f, kHeight, 0.f}),
                                           -glm::half_pi<float>(), glm::vec3(1.f, 0.f, 0.f));
        world.emplace<WorldTransform>(camera, WorldTransform{pose});

        // Random points on the floor (a gap on the left half-plane x < -1.2 shows the fallback).
        // A fifth of them turned off the floor's normal, and a fifth lifted off its plane, by
        // amounts on both sides of the rules that leave such points out of a query.
        PointCache& cache = world.ctx().emplace<PointCache>();
        cache.settings.falloffExponent = falloff;
        std::mt19937 rng(3);
        std::uniform_real_distribution<float> u(0.f, 1.f);
        for (int i = 0; i < 400; ++i) {
            glm::vec3 p(-1.0f + 3.f * u(rng), 0.f, -2.f + 4.f * u(rng));
            glm::vec3 n(0.f, 1.f, 0.f);
            if (i % 5 == 1) {
                const float tilt = 1.4f * u(rng); // up to 80 degrees: the rule's limit is 60
                n = glm::vec3(std::sin(tilt), std::cos(tilt), 0.f);
            } else if (i % 5 == 2) {
                p.y = 0.5f * (u(rng) - 0.5f); // up to 25 cm off: past half R for most
            }
            cache.position.push_back(p);
            cache.normal.push_back(n);
            cache.radius.push_back(0.08f + 0.12f * u(rng));
            cache.dart.push_back(std::uint32_t(i));
            cache.ao.push_back(u(rng));
            cache.direct.push_back({2.f * u(rng), 2.f * u(rng), 2.f * u(rng)});
            cache.indirect.push_back(glm::vec3(0.5f * u(rng)));
        }
        cache.buildGrid();

        RenderSettings settings;
        settings.width = kSize;
        settings.height = kSize;
        settings.mode = ShadingMode::Hybrid;
        RenderSystem renderer(settings);
        renderer.update(world, FrameContext{});
        const ImageF hdr = renderer.readHdr();

        const float tanHalf = std::tan(0.5f * kFov);
        int cached = 0, fallback = 0;
        for (int y = 0; y < kSize; ++y)
            for (int x = 0; x < kSize; ++x) {
                // Pixel centre -> camera ray -> floor (image rows top first).
                const float ndcX = 2.f * (float(x) + 0.5f) / kSize - 1.f;
                const float ndcY = 1.f - 2.f * (float(y) + 0.5f) / kSize;
                const glm::vec3 dir(pose * glm::vec4(ndcX * tanHalf, ndcY * tanHalf, -1.f, 0.f));
                const glm::vec3 at = glm::vec3(pose[3]) + (kHeight / -dir.y) * dir;
                if (std::abs(at.x) > 1.98f || std::abs(at.z) > 1.98f) continue;
                const PointCacheSample s = cache.sample(at, {0.f, 1.f, 0.f});
                const glm::vec3 expected =
                    kAlbedo / glm::pi<float>() * (s.count > 0 ? s.irradiance() : vertexIrradiance);
                (s.count > 0 ? cached : fallback) += 1;
                const float* actual = hdr.pixel(x, y);
                for (int c = 0; c < 3; ++c)
                    // float on the GPU against double on the CPU, and a pixel centre that may
                    // differ from the rasterizer's by float rounding: the blend is continuous
                    // (weights vanish at R_p), so 1e-3 of the brightest value bounds both.
                    ASSERT_NEAR(actual[c], expected[c], 1e-3f * 2.5f * kAlbedo / glm::pi<float>())
                        << "pixel " << x << ", " << y << " channel " << c << " points " << s.count;
            }
        EXPECT_GT(cached, 3000);
        EXPECT_GT(fallback, 100);
    }
}

} // namespace
} // namespace qgi
