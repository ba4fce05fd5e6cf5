// The CPU reference tracer the GL image tests compare the renderer with, itself checked
// against closed forms: a camera looking straight down at a large grey floor, each pixel's
// floor point found from the pinhole model written out here (a non-square image, so a
// swapped aspect shows), and its radiance albedo / pi x E from each light's definition. No GL.
#include "ReferenceTracer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace qgi::test {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kAlbedo = 0.6;

/// A 100 m floor at y = 0 facing up, as two triangles of one surface.
std::vector<RefTriangle> floorTriangles() {
    const double h = 50.0;
    const glm::dvec3 a(-h, 0.0, -h), b(-h, 0.0, h), c(h, 0.0, h), d(h, 0.0, -h);
    const glm::dvec3 up(0.0, 1.0, 0.0), grey(kAlbedo);
    return {RefTriangle{a, b, c, up, grey, 0}, RefTriangle{a, c, d, up, grey, 0}};
}

/// 40 x 30 pixels, 3 m above (0.3, 0, 0.1), looking down with image up along -z.
RefCamera downwardCamera() {
    RefCamera camera;
    camera.position = {0.3, 3.0, 0.1};
    camera.yfov = 1.0;
    camera.width = 40;
    camera.height = 30;
    // Columns: the camera's x (right), y (up) and z (back) in the world.
    camera.orientation = glm::dmat3(glm::dvec3(1.0, 0.0, 0.0), glm::dvec3(0.0, 0.0, -1.0),
                                    glm::dvec3(0.0, 1.0, 0.0));
    return camera;
}

/// Where pixel (x, y)'s centre sees the floor: the pinhole model (vertical field of view,
/// rows from the top) met with y = 0.
glm::dvec3 floorPoint(const RefCamera& camera, int x, int y) {
    const double tanHalf = std::tan(0.5 * camera.yfov);
    const double right = (2.0 * (x + 0.5) / camera.width - 1.0) * tanHalf * camera.width /
                         camera.height; // metres per metre of depth
    const double up = (1.0 - 2.0 * (y + 0.5) / camera.height) * tanHalf;
    const double depth = camera.position.y; // straight down
    return camera.position + depth * glm::dvec3(right, -1.0, -up);
}

/// Checks every pixel of the traced floor against albedo / pi x irradiance(point).
template <typename Irradiance>
void expectFloor(const std::vector<RefTriangle>& triangles, const std::vector<RefLight>& lights,
                 Irradiance irradiance) {
    const RefCamera camera = downwardCamera();
    const RefImage image = traceReference(triangles, lights, camera);
    ASSERT_EQ(image.radiance.width, camera.width);
    ASSERT_EQ(image.radiance.height, camera.height);
    int wrong = 0, lit = 0;
    for (int y = 0; y < camera.height; ++y)
        for (int x = 0; x < camera.width; ++x) {
            const double expected = kAlbedo / kPi * irradiance(floorPoint(camera, x, y));
            const double got = image.radiance.pixel(x, y)[0];
            // The image is float: half an ulp of the value, and double rounding far below it.
            if (!(std::abs(got - expected) <= 1e-6 * expected + 1e-12) && ++wrong <= 5)
                ADD_FAILURE() << "pixel " << x << "," << y << ": " << got << " against "
                              << expected;
            lit += expected > 0.0;
        }
    EXPECT_EQ(wrong, 0);
    EXPECT_GT(lit, 0);
}

TEST(ReferenceTracer, PointLightOverAFloorIsInverseSquareTimesCosine) {
    RefLight light;
    light.position = {-0.4, 1.2, 0.5};
    light.radiance = glm::dvec3(5.0); // W/sr
    expectFloor(floorTriangles(), {light}, [&](const glm::dvec3& p) {
        const glm::dvec3 d = light.position - p;
        const double r = glm::length(d);
        return 5.0 * d.y / (r * r * r);
    });
}

TEST(ReferenceTracer, SpotLightFollowsTheGltfConeRamp) {
    // Straight down from 1.5 m, cones of 15 and 35 degrees: the floor holds the full beam,
    // the ramp and the dark outside.
    RefLight light;
    light.type = RefLightType::Spot;
    light.position = {0.3, 1.5, 0.1};
    light.direction = {0.0, -1.0, 0.0};
    light.radiance = glm::dvec3(4.0);
    light.innerCone = 15.0 * kPi / 180.0;
    light.outerCone = 35.0 * kPi / 180.0;
    expectFloor(floorTriangles(), {light}, [&](const glm::dvec3& p) {
        const glm::dvec3 d = light.position - p;
        const double r = glm::length(d);
        const double angle = std::acos(d.y / r); // off the axis
        const double ramp = std::clamp((std::cos(angle) - std::cos(light.outerCone)) /
                                           (std::cos(light.innerCone) - std::cos(light.outerCone)),
                                       0.0, 1.0);
        return 4.0 * ramp * ramp * d.y / (r * r * r);
    });
}

TEST(ReferenceTracer, DirectionalLightIsItsIrradianceTimesCosine) {
    // 10 W/m^2 across the beam, travelling 50 degrees off the vertical.
    RefLight sun;
    sun.type = RefLightType::Directional;
    const double tilt = 50.0 * kPi / 180.0;
    sun.direction = {std::sin(tilt), -std::cos(tilt), 0.0};
    sun.radiance = glm::dvec3(10.0);
    expectFloor(floorTriangles(), {sun}, [&](const glm::dvec3&) { return 10.0 * std::cos(tilt); });
}

TEST(ReferenceTracer, ASquareOccluderCastsItsProjectedShadow) {
    // A point light 1.5 m up and a 0.4 m square 1 m up between it and the floor: the shadow
    // is the square scaled by 3 about the light's foot, |x - lx| < 0.6 and |z - lz| < 0.6. Pixels
    // within 1 cm of its rim are left out (the tracer's hit there is a rounding decision).
    RefLight light;
    light.position = {0.3, 1.5, 0.1};
    light.radiance = glm::dvec3(5.0);
    std::vector<RefTriangle> triangles = floorTriangles();
    const double s = 0.2, y = 1.0;
    const glm::dvec3 a(0.3 - s, y, 0.1 - s), b(0.3 - s, y, 0.1 + s), c(0.3 + s, y, 0.1 + s),
        d(0.3 + s, y, 0.1 - s);
    const glm::dvec3 down(0.0, -1.0, 0.0), black(0.0);
    triangles.push_back(RefTriangle{a, c, b, down, black, 1});
    triangles.push_back(RefTriangle{a, d, c, down, black, 1});
    // The camera sees the floor past the square only where the square does not hide it: from
    // 3 m, the square hides |x - 0.3| < 0.3 around the same foot; the shadow reaches 0.6.
    const RefCamera camera = downwardCamera();
    const RefImage image = traceReference(triangles, {light}, camera);
    int shadowed = 0, open = 0, wrong = 0;
    for (int py = 0; py < camera.height; ++py)
        for (int px = 0; px < camera.width; ++px) {
            const glm::dvec3 p = floorPoint(camera, px, py);
            const double ex = std::abs(p.x - 0.3), ez = std::abs(p.z - 0.1);
            const double hidden = 3.0 * s / (3.0 - y); // the square's image on the floor
            if (ex < hidden + 0.01 && ez < hidden + 0.01) continue; // the square itself
            const double rim = std::max(ex, ez);
            const double shadow = 1.5 * s / (1.5 - y);
            if (std::abs(rim - shadow) < 0.01) continue;
            const glm::dvec3 toLight = light.position - p;
            const double r = glm::length(toLight);
            const double expected =
                rim < shadow ? 0.0 : kAlbedo / kPi * 5.0 * toLight.y / (r * r * r);
            const double got = image.radiance.pixel(px, py)[0];
            if (!(std::abs(got - expected) <= 1e-6 * expected + 1e-12) && ++wrong <= 5)
                ADD_FAILURE() << "pixel " << px << "," << py << ": " << got << " against "
                              << expected;
            (expected == 0.0 ? shadowed : open) += 1;
        }
    EXPECT_EQ(wrong, 0);
    EXPECT_GT(shadowed, 10); // the shadow's ring around the square is seen
    EXPECT_GT(open, 100);
}

} // namespace
} // namespace qgi::test
