// The VLF structure: direction set, triangle lookup, cells, subfield frames, tiling, memory.
#include "components/Material.h"
#include "runtime/core/Error.h"
#include "runtime/render/RenderScene.h"
#include "runtime/render/ShaderInterface.h"
#include "systems/vlf/DirectionSet.h"
#include "systems/vlf/Vlf.h"
#include "systems/vlf/VlfBake.h"
#include "test_vlf_scenes.h"

#include <glm/gtc/constants.hpp>
#include <glm/gtc/packing.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

using namespace qgi;
using namespace qgi::vlf;

namespace {

glm::vec3 randomDirection(std::mt19937& rng) {
    std::normal_distribution<float> g;
    glm::vec3 d;
    do
        d = glm::vec3(g(rng), g(rng), g(rng));
    while (glm::length(d) < 1e-3f);
    return glm::normalize(d);
}

/// Whether d lies in the (positively oriented) spherical triangle with corner vectors c.
bool contains(const std::array<glm::vec3, 3>& c, const glm::vec3& d, float eps) {
    return glm::dot(d, glm::cross(c[0], c[1])) >= -eps &&
           glm::dot(d, glm::cross(c[1], c[2])) >= -eps &&
           glm::dot(d, glm::cross(c[2], c[0])) >= -eps;
}

std::array<glm::vec3, 3> corners(const DirectionSet& set, std::uint32_t t) {
    std::array<glm::vec3, 3> c;
    for (int k = 0; k < 3; ++k)
        c[k] = set.triangle(t)[k].sign * set.direction(set.triangle(t)[k].index);
    return c;
}

} // namespace

TEST(VlfDirections, CountIsTwoFourToTheLPlusOne) {
    const int expected[] = {3, 9, 33, 129, 513, 2049};
    for (int level = 0; level <= 5; ++level) {
        const DirectionSet set(level);
        EXPECT_EQ(set.size(), std::size_t(expected[level])) << "level " << level;
        EXPECT_EQ(set.triangleCount(), std::size_t(4) << (2 * level));
    }
    EXPECT_THROW(DirectionSet(-1), Error);
    EXPECT_THROW(DirectionSet(8), Error);
}

TEST(VlfDirections, UnitUpperHemisphereEquatorOnce) {
    const DirectionSet set(4);
    for (std::size_t i = 0; i < set.size(); ++i) {
        const glm::vec3& d = set.direction(i);
        EXPECT_NEAR(glm::length(d), 1.f, 1e-6f);
        EXPECT_GE(d.z, 0.f);
        if (d.z == 0.f) { // equator: azimuth in [0, pi), so no antipode is also stored
            EXPECT_TRUE(d.y > 0.f || (d.y == 0.f && d.x > 0.f)) << i;
        }
        for (std::size_t j = i + 1; j < set.size(); ++j)
            EXPECT_GT(glm::length(d + set.direction(j)), 1e-4f) << i << " antipode of " << j;
    }
}

TEST(VlfDirections, CellSolidAnglesSumToTwoPi) {
    // Exactly, the pieces of the cells tile the hemisphere: neighbouring triangles share their
    // float corners and chord midpoints bit for bit, and the equator is a great circle, so the
    // exact areas of the pieces (two spherical triangles at each corner of each triangle) sum to
    // 2 pi. Rounding (u = 2^-24): a piece's area in double (normalised corners, triple product,
    // atan2, its addition into the cell's double sum) is within 2^-48 sr; each cell is rounded
    // to float once, within u of itself, so within 2 pi u summed over the cells; the double sum
    // here adds at most size * 2^-53 * 2 pi.
    // The weight of cell i is fl(area_i / fl(fl(2 pi) / size)): the rounding of pi to float, the
    // division, the quotient and the cell's own float rounding, each u relative, so the mean
    // weight is within 4u of 1, plus the double terms above over 2 pi and second-order terms
    // (below 2^-44).
    const double twoPi = 2.0 * glm::pi<double>();
    for (int level = 0; level <= 7; ++level) {
        const DirectionSet set(level);
        double sum = 0.0, weights = 0.0;
        for (std::size_t i = 0; i < set.size(); ++i) {
            EXPECT_GT(set.cellSolidAngle(i), 0.f);
            sum += set.cellSolidAngle(i);
            weights += set.solidAngleWeight(i);
        }
        const double pieces = 6.0 * double(set.triangleCount());
        const double doubleTerms = pieces * 0x1p-48 + double(set.size()) * 0x1p-53 * twoPi;
        EXPECT_NEAR(sum, twoPi, twoPi * 0x1p-24 + doubleTerms) << "level " << level;
        EXPECT_NEAR(weights / double(set.size()), 1.0,
                    4.0 * 0x1p-24 + doubleTerms / twoPi + 0x1p-44)
            << "level " << level;
    }
}

TEST(VlfDirections, LookupMatchesBruteForce) {
    std::mt19937 rng(7);
    for (int level : {2, 3, 5}) {
        const DirectionSet set(level);
        const int queries = level == 5 ? 3000 : 100000;
        for (int q = 0; q < queries; ++q) {
            const glm::vec3 d = randomDirection(rng);
            const glm::vec3 up = d.z < 0.f ? -d : d;
            const std::uint32_t found = set.locateTriangle(d);
            // Brute force: every triangle that contains the direction (shared edges allow
            // several); the constant-time lookup must return one of them.
            bool anyContains = false;
            for (std::uint32_t t = 0; t < set.triangleCount(); ++t)
                anyContains |= contains(corners(set, t), up, 1e-6f);
            ASSERT_TRUE(anyContains);
            ASSERT_TRUE(contains(corners(set, found), up, 1e-6f))
                << "level " << level << " query " << q;
            const DirectionTriangle tri = set.locate(d);
            float sum = 0.f;
            glm::vec3 chord(0.f);
            for (int k = 0; k < 3; ++k) {
                EXPECT_GE(tri.weights[k], 0.f);
                sum += tri.weights[k];
                chord += tri.weights[k] * tri.corners[k].sign * set.direction(tri.corners[k].index);
            }
            EXPECT_NEAR(sum, 1.f, 1e-6f);
            // The weights are the barycentrics of d on the chord: their point lies along d.
            EXPECT_GT(glm::dot(glm::normalize(chord), d), 1.f - 1e-5f);
        }
    }
}

TEST(VlfDirections, StoredDirectionHasWeightOne) {
    const DirectionSet set(4);
    for (std::size_t i = 0; i < set.size(); ++i)
        for (float sign : {1.f, -1.f}) {
            const DirectionTriangle tri = set.locate(sign * set.direction(i));
            int hits = 0;
            for (int k = 0; k < 3; ++k)
                if (tri.weights[k] == 1.f) {
                    ++hits;
                    EXPECT_EQ(tri.corners[k].index, i);
                    EXPECT_EQ(tri.corners[k].sign, sign);
                } else {
                    EXPECT_EQ(tri.weights[k], 0.f);
                }
            EXPECT_EQ(hits, 1) << i;
        }
}

TEST(VlfDirections, JitteredSamplesAreUnbiasedForTheCellArea) {
    const DirectionSet set(3);
    std::mt19937 rng(11);
    for (std::size_t i : {std::size_t(0), std::size_t(5), set.size() - 1}) {
        const int n = 20000;
        double sum = 0.0, sum2 = 0.0;
        for (int s = 0; s < n; ++s) {
            const DirectionSample x = set.sampleCell(i, -1.f, rng);
            EXPECT_NEAR(glm::length(x.direction), 1.f, 1e-5f);
            // On the requested side, and inside one of the cell's triangles (near direction i).
            EXPECT_GT(glm::dot(x.direction, -set.direction(i)), 0.5f);
            sum += x.solidAngle;
            sum2 += double(x.solidAngle) * x.solidAngle;
        }
        const double mean = sum / n, se = std::sqrt((sum2 / n - mean * mean) / n);
        EXPECT_NEAR(mean, set.cellSolidAngle(i), 5.0 * se + 1e-7) << i;
    }
}

TEST(VlfFrames, OrthonormalRightHanded) {
    const DirectionSet set(4);
    std::mt19937 rng(3);
    std::vector<glm::vec3> dirs = set.directions();
    for (int k = 0; k < 1000; ++k)
        dirs.push_back(randomDirection(rng));
    for (const glm::vec3& d : dirs) {
        const SubfieldFrame f = makeSubfieldFrame(d);
        EXPECT_NEAR(glm::length(f.u), 1.f, 1e-5f);
        EXPECT_NEAR(glm::length(f.v), 1.f, 1e-5f);
        EXPECT_NEAR(glm::dot(f.u, f.v), 0.f, 1e-5f);
        EXPECT_NEAR(glm::dot(f.u, f.n), 0.f, 1e-5f);
        EXPECT_NEAR(glm::dot(f.v, f.n), 0.f, 1e-5f);
        EXPECT_LT(glm::length(glm::cross(f.u, f.v) - f.n), 1e-5f);
        EXPECT_LT(glm::length(f.n - d), 1e-6f);
    }
}

TEST(VlfTiling, IndexRoundTrips) {
    for (int m : {1, 4, 8, 64}) {
        const int N = 64;
        for (int i = 0; i < N; ++i)
            for (int j = 0; j < N; ++j) {
                const TiledIndex t = toTiled(i, j, m);
                EXPECT_GE(t.u, 0);
                EXPECT_LT(t.u, m);
                EXPECT_GE(t.v, 0);
                EXPECT_LT(t.v, m);
                EXPECT_EQ(toGlobal(t, m), glm::ivec2(i, j));
            }
        // The cells of one tile (here tile (1, 2) of the subfield, in slot 3) fill exactly
        // that slot's m x m places of the cell array.
        std::vector<int> seen(std::size_t(m) * m, 0);
        for (int i = m; i < 2 * m; ++i)
            for (int j = 2 * m; j < 3 * m; ++j) {
                const std::size_t c = cellOffset(3, i, j, m);
                ASSERT_GE(c, std::size_t(3 * m * m));
                ASSERT_LT(c, std::size_t(4 * m * m));
                ++seen[c - std::size_t(3 * m * m)];
            }
        EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), m * m);
    }
}

namespace {

/// A room with a glossy floor and a tilted glossy quad in it.
std::unique_ptr<VlfScene> glossyRoom() {
    test::VlfSceneBuilder b;
    const std::uint32_t wall = b.material(glm::vec3(0.5f));
    const std::uint32_t glossy = b.material(glm::vec3(0.2f), glm::vec3(0.f), glm::vec3(0.5f), 20.f);
    b.box({-1.f, 0.f, -1.f}, {1.f, 2.f, 1.f}, true,
          [&](int axis, int side) { return axis == 1 && side == 0 ? glossy : wall; });
    b.quad({-0.3f, 0.5f, -0.2f}, {0.4f, 0.7f, -0.3f}, {0.3f, 0.9f, 0.4f}, {-0.4f, 0.7f, 0.5f},
           glossy);
    return b.build();
}

/// Level-2 directions, 32 x 32 lines, 4 x 4 tiles: small, yet several tiles per face.
VlfSettings tiledSettings() {
    VlfSettings s;
    s.directionLevel = 2;
    s.linesPerSide = 32;
    s.tileSize = 4;
    return s;
}

/// A 2 m mirror floor in 20 x 20 quads: one face of 800 triangles, as the demo's mesh
/// refinement makes of a one-quad floor.
std::unique_ptr<VlfScene> dividedMirrorFloor() {
    test::VlfSceneBuilder b;
    const std::uint32_t mirror = b.material(glm::vec3(0.f), glm::vec3(0.f), glm::vec3(1.f), 0.f);
    constexpr int kSide = 20;
    const auto at = [](int i) { return -1.f + 2.f * float(i) / float(kSide); };
    for (int z = 0; z < kSide; ++z)
        for (int x = 0; x < kSide; ++x)
            b.quad({at(x), 0.f, at(z)}, {at(x), 0.f, at(z + 1)}, {at(x + 1), 0.f, at(z + 1)},
                   {at(x + 1), 0.f, at(z)}, mirror);
    return b.build();
}

/// qgi-demo's --vlf-level 4 --vlf-lines 1024: about 2 million tiles on that floor.
VlfSettings absurdSettings() {
    VlfSettings s;
    s.directionLevel = 4;
    s.linesPerSide = 1024;
    s.maxBakeBytes = std::uint64_t(1) << 50; // no memory limit here
    return s;
}

} // namespace

TEST(VlfTiling, ABakeThatWouldNeedMoreMemoryThanAllowedFailsBeforeAllocating) {
    const auto scene = glossyRoom();
    VlfSettings s = tiledSettings();
    const std::size_t need = Vlf::allocate(*scene, s).memory().bakeBytes;
    s.maxBakeBytes = need; // exactly enough
    EXPECT_NO_THROW(Vlf::allocate(*scene, s));
    s.maxBakeBytes = need - 1;
    try {
        Vlf::allocate(*scene, s);
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("lower the direction level or the lines per side"),
                  std::string::npos)
            << e.what();
    }
}

TEST(VlfTiling, ATileAtlasBeyondTheGlLimitIsRefusedBeforeTheBake) {
    // The layout alone fixes the atlas: the bake (minutes at these settings) never starts,
    // and neither do the layout's own large arrays.
    const auto scene = dividedMirrorFloor();
    ASSERT_EQ(scene->faces().size(), 1u);
    VlfSettings s = absurdSettings();
    s.maxAtlasSize = 16384; // GL 4.5's guaranteed minimum, llvmpipe's limit
    try {
        bakeVlf(*scene, s);
        ADD_FAILURE() << "no error";
    } catch (const VlfTooLarge& e) {
        const std::string message = e.what();
        EXPECT_EQ(e.limit, VlfTooLarge::Limit::Atlas);
        EXPECT_NE(e.detail.find("over the GL limit 16384"), std::string::npos) << e.detail;
        EXPECT_NE(message.find(e.detail), std::string::npos) << message;
        EXPECT_NE(message.find("(VlfSettings.maxAtlasSize): lower the direction level"),
                  std::string::npos)
            << message;
    }
}

TEST(VlfTiling, ABakeBeyondTheMemoryLimitIsRefusedBeforeTheBake) {
    const auto scene = dividedMirrorFloor();
    VlfSettings s = absurdSettings();
    s.maxBakeBytes = std::uint64_t(1) << 30; // the bake needs about 11 GB
    try {
        bakeVlf(*scene, s);
        ADD_FAILURE() << "no error";
    } catch (const VlfTooLarge& e) {
        EXPECT_EQ(e.limit, VlfTooLarge::Limit::Memory);
        EXPECT_NE(e.detail.find("GB, over the 1.07374 GB allowed"), std::string::npos) << e.detail;
        EXPECT_NE(std::string(e.what()).find("VlfSettings.maxBakeBytes"), std::string::npos)
            << e.what();
    }
}

TEST(VlfTiling, AnAtlasExactlyAtTheGlLimitIsAcceptedAndOneTexelLessIsNot) {
    const auto scene = glossyRoom();
    VlfSettings s = tiledSettings();
    const Vlf v = Vlf::allocate(*scene, s);
    // The atlas the renderer will lay out (SceneRenderer::uploadVlf), from the same function.
    const shader::VlfAtlasSize atlas = shader::vlfAtlasSize(v.tileCount(), s.tileSize);
    EXPECT_EQ(atlas.width, shader::kVlfAtlasTiles * s.tileSize);
    EXPECT_EQ(atlas.height,
              std::int64_t((v.tileCount() + shader::kVlfAtlasTiles - 1) / shader::kVlfAtlasTiles) *
                  s.tileSize);
    s.maxAtlasSize = int(std::max(atlas.width, atlas.height));
    EXPECT_NO_THROW(Vlf::allocate(*scene, s));
    s.maxAtlasSize -= 1;
    EXPECT_THROW(Vlf::allocate(*scene, s), VlfTooLarge);
    s.maxAtlasSize = 0; // not checked
    EXPECT_NO_THROW(Vlf::allocate(*scene, s));
}

TEST(VlfTiling, TheMemoryCheckedBeforeAllocatingIsWhatTheFieldReports) {
    // vlfMemory from the counts is Vlf::memory(): the check before the arrays and the figure
    // after them cannot disagree.
    const auto scene = glossyRoom();
    const Vlf v = Vlf::allocate(*scene, tiledSettings());
    const VlfMemory a = v.memory();
    const VlfMemory b =
        vlfMemory(v.directions().size(), v.tileCount(), v.tileSize(), v.irradiance().size(),
                  v.slots().size(), v.blocks().size(), v.faceMaps().size());
    EXPECT_EQ(a.bakeBytes, b.bakeBytes);
    EXPECT_EQ(a.renderBytes, b.renderBytes);
    EXPECT_EQ(a.tileCells, v.cellCount());
    EXPECT_EQ(a.diffuseTexels, v.texelCoverage().size());
}

TEST(VlfTiling, TilesCoverTheProjectionAndNoMore) {
    const auto scene = glossyRoom();
    const VlfSettings s = tiledSettings();
    const Vlf v = Vlf::allocate(*scene, s);
    ASSERT_EQ(v.specularFaceCount(), 2u);
    const int N = s.linesPerSide, m = s.tileSize;
    const float h = v.cellWidth();
    for (std::size_t sf = 0; sf < v.specularFaceCount(); ++sf) {
        const Face& f = scene->faces()[v.specularFace(sf)];
        for (std::size_t psf = 0; psf < v.directions().size(); ++psf) {
            const TileBlock& b = v.block(sf, psf);
            const float c = glm::dot(f.normal, v.directions().direction(psf));
            if (std::abs(c) < 1e-4f) {
                EXPECT_EQ(b.side, 0);
                continue;
            }
            EXPECT_EQ(b.side, c > 0.f ? 1 : -1);
            // Points sampled densely on the face project into allocated cells (all of them
            // and their bilinear neighbours).
            std::vector<glm::vec2> projected;
            for (std::uint32_t ti : f.triangles) {
                const VlfScene::Triangle& t = scene->triangles()[ti];
                for (int a = 0; a <= 40; ++a)
                    for (int bb = 0; a + bb <= 40; ++bb) {
                        const glm::vec3 p = t.p0 + (float(a) / 40.f) * (t.p1 - t.p0) +
                                            (float(bb) / 40.f) * (t.p2 - t.p0);
                        const glm::vec2 q = (v.project(psf, p) + 1.f) / h;
                        projected.push_back(q);
                        const int i = int(std::floor(q.x)), j = int(std::floor(q.y));
                        EXPECT_GE(v.cellIndex(sf, psf, i, j), 0) << psf;
                        const int bi = int(std::floor(q.x - 0.5f)),
                                  bj = int(std::floor(q.y - 0.5f));
                        for (int dj = 0; dj < 2; ++dj)
                            for (int di = 0; di < 2; ++di)
                                if (bi + di >= 0 && bj + dj >= 0 && bi + di < N && bj + dj < N) {
                                    EXPECT_GE(v.cellIndex(sf, psf, bi + di, bj + dj), 0);
                                }
                    }
            }
            // Every allocated tile lies within one cell (plus the sampling spacing) of them.
            for (int t = 0; t < b.tw; ++t)
                for (int sx = 0; sx < b.sw; ++sx) {
                    if (v.slots()[b.firstSlot + std::size_t(t) * b.sw + sx] < 0) continue;
                    const float x0 = float((b.s0 + sx) * m) - 1.5f,
                                x1 = float((b.s0 + sx + 1) * m) + 1.5f;
                    const float y0 = float((b.t0 + t) * m) - 1.5f,
                                y1 = float((b.t0 + t + 1) * m) + 1.5f;
                    bool near = false;
                    for (const glm::vec2& q : projected)
                        near |= q.x >= x0 && q.x <= x1 && q.y >= y0 && q.y <= y1;
                    EXPECT_TRUE(near) << "tile without the face, psf " << psf;
                }
        }
    }
}

TEST(VlfStructure, ProjectionOfTheBoundsFitsThePlane) {
    const auto scene = glossyRoom();
    VlfSettings s;
    s.directionLevel = 3;
    const Vlf v = Vlf::allocate(*scene, s);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (int k = 0; k < 2000; ++k) {
        const glm::vec3 p =
            scene->bounds().min + glm::vec3(u(rng), u(rng), u(rng)) * scene->bounds().extent();
        const std::size_t psf = std::size_t(k) % v.directions().size();
        const glm::vec2 q = v.project(psf, p);
        EXPECT_LE(std::abs(q.x), 1.f);
        EXPECT_LE(std::abs(q.y), 1.f);
        // Back from the plane: the line point differs from p only along the direction.
        const glm::vec3 back = v.linePoint(psf, q);
        const glm::vec3 along = p - back;
        EXPECT_LT(glm::length(along - glm::dot(along, v.frame(psf).n) * v.frame(psf).n), 1e-5f);
    }
}

TEST(VlfStructure, MemoryIsAccounted) {
    const auto scene = glossyRoom();
    const VlfSettings s = tiledSettings();
    const Vlf v = Vlf::allocate(*scene, s);
    const VlfMemory mem = v.memory();
    EXPECT_EQ(mem.directions, 33u);
    EXPECT_GT(mem.tiles, 0u);
    EXPECT_EQ(mem.tileCells, mem.tiles * 16);
    EXPECT_EQ(mem.tileCells, v.cellCount());
    std::size_t texels = 0;
    for (const FaceMap& m : v.faceMaps())
        texels += std::size_t(m.width) * m.height;
    EXPECT_EQ(mem.diffuseTexels, texels);
    // Rendering keeps a packed cell (four half floats) per cell and RGB float per texel, plus
    // the index.
    EXPECT_GE(mem.renderBytes, mem.tileCells * 8 + texels * 12);
    // The bake adds 72 B per cell (its float render table, packed at the end, another RGBA
    // array, three RGB arrays and a weight) and per
    // texel unshot and received irradiance plus one copy per work chunk (16 here). This pins
    // the account to the Baker's arrays as they are; the glossy lobe tables, sized by the
    // lobes, are left out (ARCHITECTURE.md, VLF memory).
    EXPECT_EQ(mem.bakeBytes - mem.renderBytes, mem.tileCells * 72 + texels * 18 * 12);
}

TEST(VlfStructure, BadSettingsAreRejected) {
    const auto scene = glossyRoom();
    VlfSettings s;
    s.tileSize = 7;
    EXPECT_THROW(Vlf::allocate(*scene, s), Error);
    s = {};
    s.directionLevel = 9;
    EXPECT_THROW(Vlf::allocate(*scene, s), Error);
    s = {};
    s.texelCells = std::nanf("");
    EXPECT_THROW(Vlf::allocate(*scene, s), Error);
    s = {};
    s.iterations = 0;
    EXPECT_THROW(Vlf::allocate(*scene, s), Error);
    s = {};
    s.directionLevel = 6;
    s.linesPerSide = 4096;
    EXPECT_THROW(validate(s), Error); // 1.4e11 lines per iteration: refused, not attempted
    s = {};
    s.filterSigma = -1.f;
    EXPECT_THROW(validate(s), Error);
    test::VlfSceneBuilder empty;
    EXPECT_THROW(empty.build(), Error);
}

namespace qgi::vlf {
namespace {

TEST(VlfMaterials, MetallicRoughnessBecomesAPhongLobeUnlessItIsRough) {
    qgi::Material m;
    m.baseColor = glm::vec3(0.8f, 0.6f, 0.4f);
    m.metallic = 1.f;
    // Roughness 0.5: alpha 0.25, n_s = 2 / 0.25^2 - 2 = 30.
    m.roughness = 0.5f;
    VlfScene::Material glossy = VlfScene::fromComponent(m);
    EXPECT_EQ(glossy.specular, glm::vec3(1.f));
    EXPECT_EQ(glossy.diffuse, glm::vec3(0.f));
    EXPECT_FLOAT_EQ(glossy.phongExponent, 30.f);
    // Roughness 0: a mirror. Half metal: half the lobe, the rest diffuse.
    m.roughness = 0.f;
    m.metallic = 0.5f;
    glossy = VlfScene::fromComponent(m);
    EXPECT_EQ(glossy.phongExponent, 0.f);
    EXPECT_EQ(glossy.specular, glm::vec3(0.5f));
    EXPECT_EQ(glossy.diffuse, 0.5f * m.baseColor);
    // glTF's defaults (metallic 1, roughness 1) and anything from kDiffuseRoughness on: diffuse.
    for (const float roughness : {VlfScene::kDiffuseRoughness, 1.f}) {
        m.metallic = 1.f;
        m.roughness = roughness;
        const VlfScene::Material rough = VlfScene::fromComponent(m);
        EXPECT_EQ(rough.specular, glm::vec3(0.f)) << roughness;
        EXPECT_EQ(rough.diffuse, m.baseColor) << roughness;
    }
}

} // namespace
} // namespace qgi::vlf

// ---- the renderer's half-float cells ----------------------------------------------------------

TEST(VlfGpuCells, HalfFloatsHoldEachValueWithinTheirRoundingAndTheFlagOfEachCell) {
    // Radiance from 1e-3 to 1e4 (scale 1): each component within 2^-11 of itself, the
    // nearest-half rounding of a normal half float (11 significant bits); the weight becomes
    // 1 or 0.
    std::mt19937 random(11);
    std::uniform_real_distribution<float> exponent(-3.f, 4.f);
    std::vector<glm::vec4> cells;
    for (int i = 0; i < 10'000; ++i)
        cells.emplace_back(std::pow(10.f, exponent(random)), std::pow(10.f, exponent(random)),
                           std::pow(10.f, exponent(random)),
                           i % 3 == 0 ? 0.f : 0.25f * float(i % 5));
    std::vector<glm::u16vec4> packed;
    ASSERT_EQ(packCells(cells, packed), 1.f);
    ASSERT_EQ(packed.size(), cells.size());
    for (std::size_t i = 0; i < cells.size(); ++i) {
        for (int c = 0; c < 3; ++c) {
            const float back = glm::unpackHalf1x16(packed[i][c]);
            EXPECT_LE(std::abs(back - cells[i][c]), std::ldexp(cells[i][c], -11)) << i << ", " << c;
        }
        EXPECT_EQ(glm::unpackHalf1x16(packed[i].w), cells[i].w > 0.f ? 1.f : 0.f) << i;
    }
}

TEST(VlfGpuCells, ABrightCellScalesTheWholeTableByAPowerOfTwo) {
    // 1e6 W/(m^2 sr) (a small, strong lamp seen in a mirror) would overflow a half float: the
    // table is divided by 64, the smallest power of two that brings it under 16384, and every
    // value keeps its relative precision. What is not radiance (negative, NaN, infinite)
    // reads 0; a value far below the scale keeps an absolute precision of 2^-25 of it.
    const std::vector<glm::vec4> cells = {
        {1e6f, 3.f, 0.5f, 1.f},
        {-1.f, std::nanf(""), std::numeric_limits<float>::infinity(), 1.f},
        {1e-7f, 2e-3f, 7.f, 1.f}};
    std::vector<glm::u16vec4> packed;
    const float scale = packCells(cells, packed);
    ASSERT_EQ(scale, 64.f);
    for (const std::size_t i : {std::size_t(0), std::size_t(2)})
        for (int c = 0; c < 3; ++c) {
            const float back = scale * glm::unpackHalf1x16(packed[i][c]);
            EXPECT_LE(std::abs(back - cells[i][c]),
                      std::max(std::ldexp(cells[i][c], -11), std::ldexp(scale, -25)))
                << i << ", " << c;
        }
    for (int c = 0; c < 3; ++c)
        EXPECT_EQ(glm::unpackHalf1x16(packed[1][c]), 0.f) << c;
    std::vector<glm::u16vec4> none;
    EXPECT_EQ(packCells({}, none), 1.f);
    EXPECT_TRUE(none.empty());
}
