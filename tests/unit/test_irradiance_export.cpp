#include "runtime/io/IrradianceExport.h"

#include "components/Avatar.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/StaticMesh.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"

#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <filesystem>

namespace qgi {
namespace {

Mesh triangle() {
    Mesh m;
    m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    m.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
    m.indices = {0, 1, 2};
    return m;
}

TEST(IrradianceExport, WritesWorldSpaceVerticesWithIrradianceAndMobileFlag) {
    Registry r;
    const Entity fixed = r.create();
    r.emplace<Mesh>(fixed, triangle());
    r.emplace<StaticMesh>(fixed);
    r.emplace<WorldTransform>(fixed);
    r.emplace<VertexIrradiance>(fixed, VertexIrradiance{{{1, 2, 3}, {4, 5, 6}, {7, 8, 9}}, {}});

    // A mobile turned 90 degrees about +Y and moved: its normal (0,0,1) becomes (1,0,0).
    const Entity mover = r.create();
    r.emplace<Mesh>(mover, triangle());
    r.emplace<MobileMesh>(mover);
    const glm::mat4 pose = glm::rotate(glm::translate(glm::mat4(1.f), glm::vec3(0, 0, 5)),
                                       glm::half_pi<float>(), glm::vec3(0, 1, 0));
    r.emplace<WorldTransform>(mover, WorldTransform{pose});

    const Entity pooled = r.create(); // out of the world (MobileMesh::active): not exported
    r.emplace<Mesh>(pooled, triangle());
    r.emplace<MobileMesh>(pooled, MobileMesh{false});
    r.emplace<WorldTransform>(pooled);

    const Entity avatar = r.create(); // lit by probes: not exported
    r.emplace<Mesh>(avatar, triangle());
    r.emplace<Avatar>(avatar);
    r.emplace<WorldTransform>(avatar);

    const auto path = std::filesystem::temp_directory_path() / "qgi_irradiance_export.ply";
    exportVertexIrradiance(r, path);
    const PlyMesh ply = readPly(path);

    ASSERT_EQ(ply.positions.size(), 6u);
    ASSERT_EQ(ply.triangles, (std::vector<std::uint32_t>{0, 1, 2, 3, 4, 5}));
    EXPECT_EQ(ply.irradiance[1], glm::vec3(4, 5, 6));
    EXPECT_EQ(ply.mobile, (std::vector<std::uint8_t>{0, 0, 0, 1, 1, 1}));
    // Vertex (1,0,0) of the mobile: rotated to (0,0,-1), then moved to (0,0,4).
    EXPECT_NEAR(ply.positions[4].x, 0.f, 1e-6f);
    EXPECT_NEAR(ply.positions[4].z, 4.f, 1e-6f);
    EXPECT_NEAR(ply.normals[3].x, 1.f, 1e-6f);
    EXPECT_NEAR(ply.normals[3].z, 0.f, 1e-6f);
    // No VertexIrradiance yet: exported as zero rather than skipped.
    EXPECT_EQ(ply.irradiance[3], glm::vec3(0.f));
}

TEST(IrradianceExport, UnwritablePathThrows) {
    Registry r;
    EXPECT_THROW(exportVertexIrradiance(r, "/nonexistent-dir/x.ply"), Error);
}

} // namespace
} // namespace qgi
