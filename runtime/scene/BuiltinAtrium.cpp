#include "runtime/scene/BuiltinAtrium.h"

#include "runtime/scene/SceneInfo.h"

#include "components/Avatar.h"
#include "components/Camera.h"
#include "components/DirectionalLight.h"
#include "components/MobileMesh.h"
#include "components/PathFollower.h"
#include "components/PointCacheShaded.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "runtime/scene/BuiltinPaths.h"

#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace qgi {
namespace {

// ---- layout, metres; the court is centred on the origin, every side alike ---------------------
constexpr float kOuter = 12.f; // inner face of the outer walls, |x| and |z|
constexpr float kWallThickness = 0.4f;
constexpr float kWallHeight = 8.1f;
constexpr float kColonnade = 7.f; // column centre lines
constexpr int kSpansPerSide = 7;  // columns every 2 m: -7, -5, ..., 7
constexpr float kArcadeHalfDepth = 0.25f;
constexpr float kArchRadius = 0.75f;   // clear half-width between ground-floor columns
constexpr float kSpringLine = 3.f;     // foot of the arches
constexpr float kImpostBottom = 2.75f; // square block between column and arches
constexpr float kFirstFloorUnderside = 4.f;
constexpr float kFirstFloorTop = 4.3f;
constexpr float kRoofUnderside = 7.8f;
constexpr float kRoofTop = 8.1f;
constexpr float kSlabInner = kColonnade - kArcadeHalfDepth; // slab edges flush with the arcade
constexpr float kParapetHeight = 1.f;
constexpr float kParapetHalfThickness = 0.08f;
constexpr float kUpperColumnRadius = 0.2f;
constexpr int kRoundSegments = 24;  // arches, fountain, sphere
constexpr int kColumnSegments = 16; // refinement splits shafts lengthwise: keep them coarse around
constexpr float kAvatarHeight = 1.75f;
constexpr float kAvatarRadius = 0.25f;

/// Places a piece built for the north side (running along x, its front looking at the court
/// along +z from z = -distance) on side 0..3, turning it by quarter turns about +Y. The
/// matrix entries are exactly 0 or +-1, so the four sides are exact copies.
glm::mat4 sidePlacement(int side, float distance) {
    static constexpr float kCos[4] = {1.f, 0.f, -1.f, 0.f};
    static constexpr float kSin[4] = {0.f, 1.f, 0.f, -1.f};
    const float c = kCos[side], s = kSin[side];
    glm::mat4 m(1.f);
    m[0] = glm::vec4(c, 0.f, -s, 0.f); // image of +x
    m[2] = glm::vec4(s, 0.f, c, 0.f);  // image of +z
    m[3] = glm::vec4(-distance * s, 0.f, -distance * c, 1.f);
    return m;
}

/// The point `local` of the north-side frame, on side `side`.
glm::vec3 onSide(int side, float distance, const glm::vec3& local) {
    return glm::vec3(sidePlacement(side, distance) * glm::vec4(local, 1.f));
}

void appendOnAllSides(ProceduralMesh& mesh, const ProceduralMesh& side, float distance) {
    for (int k = 0; k < 4; ++k)
        mesh.append(side, sidePlacement(k, distance));
}

std::vector<float> sortedUnique(std::vector<float> values) {
    std::sort(values.begin(), values.end());
    values.erase(std::unique(values.begin(), values.end()), values.end());
    return values;
}

/// Calls emit(a, b) for every pair of consecutive grid values inside [lo, hi]. Splitting
/// faces at the same grid keeps neighbouring faces edge to edge (no T-junctions).
template <typename Emit>
void forEachInterval(const std::vector<float>& grid, float lo, float hi, Emit&& emit) {
    for (std::size_t k = 0; k + 1 < grid.size(); ++k)
        if (grid[k] >= lo && grid[k + 1] <= hi) emit(grid[k], grid[k + 1]);
}

/// Ring of a horizontal floor or ceiling between two squares centred on the axis, as eight
/// rectangles that meet edge to edge.
ProceduralMesh frame(float inner, float outer, float y, const glm::vec3& facing) {
    const float edges[4] = {-outer, -inner, inner, outer};
    ProceduralMesh mesh;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            if (i == 1 && j == 1) continue;
            mesh.addQuad({edges[i], y, edges[j]}, {edges[i + 1], y, edges[j]},
                         {edges[i + 1], y, edges[j + 1]}, {edges[i], y, edges[j + 1]}, facing);
        }
    return mesh;
}

/// A floor slab over the galleries: walkable top, ceiling underneath, edge facing the court.
ProceduralMesh slab(float underside, float top) {
    ProceduralMesh mesh = frame(kSlabInner, kOuter, top, {0.f, 1.f, 0.f});
    mesh.append(frame(kSlabInner, kOuter, underside, {0.f, -1.f, 0.f}), glm::mat4(1.f));
    ProceduralMesh edge;
    edge.addQuad({-kSlabInner, underside, 0.f}, {kSlabInner, underside, 0.f},
                 {kSlabInner, top, 0.f}, {-kSlabInner, top, 0.f}, {0.f, 0.f, 1.f});
    appendOnAllSides(mesh, edge, kSlabInner);
    return mesh;
}

struct Opening {
    float u0, u1, v0, v1; // metres along the wall and above the floor
};

/// One side of the outer wall ring in the north-side frame: the inner face at z = 0 looks at
/// the court (+z) and stops at the neighbouring walls' inner faces, the outer face at
/// z = -thickness runs to the outer corners, and the top is mitred, so four copies turned by
/// quarter turns close into one solid ring. A door and two rows of windows go through it.
ProceduralMesh outerWallSide() {
    const float inner = kOuter, outer = kOuter + kWallThickness, t = kWallThickness;
    std::vector<Opening> openings{{-1.2f, 1.2f, 0.f, 3.2f}}; // door
    for (const float u : {-9.f, -5.f, 5.f, 9.f})
        openings.push_back({u - 0.8f, u + 0.8f, 1.f, 2.6f});
    for (const float u : {-8.f, -4.f, 0.f, 4.f, 8.f})
        openings.push_back({u - 0.6f, u + 0.6f, 5.f, 6.8f});
    // One grid for every face, so faces that meet share their vertices (no T-junctions).
    std::vector<float> us{-outer, -inner, inner, outer}, vs{0.f, kWallHeight};
    for (const Opening& o : openings) {
        us.insert(us.end(), {o.u0, o.u1});
        vs.insert(vs.end(), {o.v0, o.v1});
    }
    us = sortedUnique(std::move(us));
    vs = sortedUnique(std::move(vs));
    const glm::vec3 toCourt(0.f, 0.f, 1.f), alongU(1.f, 0.f, 0.f), up(0.f, 1.f, 0.f);

    ProceduralMesh mesh;
    for (std::size_t i = 0; i + 1 < us.size(); ++i)
        for (std::size_t j = 0; j + 1 < vs.size(); ++j) {
            const float u0 = us[i], u1 = us[i + 1], v0 = vs[j], v1 = vs[j + 1];
            const float uc = 0.5f * (u0 + u1), vc = 0.5f * (v0 + v1);
            if (std::any_of(openings.begin(), openings.end(), [&](const Opening& o) {
                    return uc > o.u0 && uc < o.u1 && vc > o.v0 && vc < o.v1;
                }))
                continue;
            mesh.addQuad({u0, v0, -t}, {u1, v0, -t}, {u1, v1, -t}, {u0, v1, -t}, -toCourt);
            if (u0 >= -inner && u1 <= inner)
                mesh.addQuad({u0, v0, 0.f}, {u1, v0, 0.f}, {u1, v1, 0.f}, {u0, v1, 0.f}, toCourt);
        }
    for (const Opening& o : openings) {
        forEachInterval(vs, o.v0, o.v1, [&](float a, float b) {
            mesh.addQuad({o.u0, a, 0.f}, {o.u0, b, 0.f}, {o.u0, b, -t}, {o.u0, a, -t}, alongU);
            mesh.addQuad({o.u1, a, 0.f}, {o.u1, b, 0.f}, {o.u1, b, -t}, {o.u1, a, -t}, -alongU);
        });
        forEachInterval(us, o.u0, o.u1, [&](float a, float b) {
            mesh.addQuad({a, o.v1, 0.f}, {b, o.v1, 0.f}, {b, o.v1, -t}, {a, o.v1, -t}, -up);
            if (o.v0 > 0.f)
                mesh.addQuad({a, o.v0, 0.f}, {b, o.v0, 0.f}, {b, o.v0, -t}, {a, o.v0, -t}, up);
        });
    }
    const float h = kWallHeight;
    forEachInterval(us, -inner, inner, [&](float a, float b) {
        mesh.addQuad({a, h, 0.f}, {b, h, 0.f}, {b, h, -t}, {a, h, -t}, up);
    });
    for (const float end : {-1.f, 1.f})
        mesh.addTriangle({end * inner, h, 0.f}, {end * inner, h, -t}, {end * outer, h, -t}, up);
    return mesh;
}

/// One span of the arcade in the north-side frame: the wall between the spring line and the
/// slab, pierced by a semicircular arch centred at `centre`: its court face (z = +h) from
/// court.x to court.y, its gallery face (z = -h) from gallery.x to gallery.y, the arch's curved
/// underside (intrados) and the flat underside beside the arch. The two faces differ in length
/// only at the corners, where the arcade ring is mitred.
void addArchSpan(ProceduralMesh& mesh, float centre, const glm::vec2& court,
                 const glm::vec2& gallery) {
    const float r = kArchRadius, y0 = kSpringLine, y1 = kFirstFloorUnderside;
    const float h = kArcadeHalfDepth;
    struct Face {
        float w, u0, u1, cornerLow, cornerHigh;
    };
    const auto face = [&](float w, const glm::vec2& ends) {
        return Face{w, ends.x, ends.y, std::atan2(y1 - y0, ends.x - centre),
                    std::atan2(y1 - y0, ends.y - centre)};
    };
    const Face faces[2] = {face(h, court), face(-h, gallery)};
    // Sample the arch evenly, plus the directions that hit each face's top corners, so every
    // strip between the arch and a face's rim has a straight outer edge. Both faces and the
    // intrados use all samples, so they share every vertex along the arch.
    std::vector<float> angles;
    for (const Face& f : faces)
        angles.insert(angles.end(), {f.cornerLow, f.cornerHigh});
    for (int k = 0; k <= kRoundSegments; ++k) {
        const float a = glm::pi<float>() * float(k) / float(kRoundSegments);
        if (std::all_of(angles.begin(), angles.begin() + 4,
                        [&](float corner) { return std::abs(a - corner) > 1e-4f; }))
            angles.push_back(a);
    }
    angles = sortedUnique(std::move(angles));
    const auto inner = [&](float a) {
        return glm::vec2(centre + r * std::cos(a), y0 + r * std::sin(a));
    };
    const auto outer = [&](float a, const Face& f) {
        if (a == f.cornerHigh) return glm::vec2(f.u1, y1);
        if (a == f.cornerLow) return glm::vec2(f.u0, y1);
        const float c = std::cos(a), s = std::sin(a);
        float t = std::numeric_limits<float>::max();
        if (c > 1e-6f) t = std::min(t, (f.u1 - centre) / c);
        if (c < -1e-6f) t = std::min(t, (f.u0 - centre) / c);
        if (s > 1e-6f) t = std::min(t, (y1 - y0) / s);
        return glm::vec2(centre + t * c, y0 + t * s);
    };
    const auto at = [](const glm::vec2& p, float w) { return glm::vec3(p.x, p.y, w); };
    for (std::size_t k = 0; k + 1 < angles.size(); ++k) {
        const glm::vec2 ia = inner(angles[k]), ib = inner(angles[k + 1]);
        for (const Face& f : faces)
            mesh.addQuad(at(ia, f.w), at(outer(angles[k], f), f.w),
                         at(outer(angles[k + 1], f), f.w), at(ib, f.w), {0.f, 0.f, f.w});
        const glm::vec2 towardCentre = glm::vec2(centre, y0) - 0.5f * (ia + ib);
        mesh.addQuad(at(ia, h), at(ib, h), at(ib, -h), at(ia, -h),
                     {towardCentre.x, towardCentre.y, 0.f});
    }
    // Beside the arch: a rectangle, or at a mitred corner a triangle.
    const glm::vec3 down(0.f, -1.f, 0.f);
    const float low = centre - r, high = centre + r;
    if (gallery.x < low)
        mesh.addQuad({gallery.x, y0, -h}, {low, y0, -h}, {low, y0, h}, {court.x, y0, h}, down);
    if (gallery.y > high)
        mesh.addQuad({high, y0, -h}, {gallery.y, y0, -h}, {court.y, y0, h}, {high, y0, h}, down);
}

/// A side of the ground-floor arcade in the north-side frame, centred on the column line;
/// four of them turned by quarter turns close into a ring mitred at the corners.
ProceduralMesh arcadeSide() {
    const float courtEnd = kColonnade - kArcadeHalfDepth;
    const float galleryEnd = kColonnade + kArcadeHalfDepth;
    ProceduralMesh mesh;
    for (int k = 0; k < kSpansPerSide; ++k) {
        const float centre = -kColonnade + 1.f + 2.f * float(k);
        const bool first = k == 0, last = k == kSpansPerSide - 1;
        addArchSpan(mesh, centre,
                    {first ? -courtEnd : centre - 1.f, last ? courtEnd : centre + 1.f},
                    {first ? -galleryEnd : centre - 1.f, last ? galleryEnd : centre + 1.f});
    }
    return mesh;
}

/// Column centres on the four colonnade lines, each corner once.
std::vector<glm::vec3> columnCentres() {
    std::vector<glm::vec3> centres;
    for (int side = 0; side < 4; ++side)
        for (int k = 0; k < kSpansPerSide; ++k)
            centres.push_back(onSide(side, kColonnade, {-kColonnade + 2.f * float(k), 0.f, 0.f}));
    return centres;
}

/// Ground floor: plinth, shaft, and an impost block as deep as the arcade that carries the
/// arches (its top is covered by them).
ProceduralMesh groundColumns() {
    constexpr float kPlinthHalf = 0.35f, kPlinthHeight = 0.2f, kRadius = 0.25f;
    ProceduralMesh mesh;
    for (const glm::vec3& c : columnCentres()) {
        mesh.addBox(c + glm::vec3(-kPlinthHalf, 0.f, -kPlinthHalf),
                    c + glm::vec3(kPlinthHalf, kPlinthHeight, kPlinthHalf),
                    ProceduralMesh::kAllFaces & ~ProceduralMesh::kMinY);
        mesh.addCylinder(c + glm::vec3(0.f, kPlinthHeight, 0.f), kRadius,
                         kImpostBottom - kPlinthHeight, kColumnSegments);
        mesh.addBox(c + glm::vec3(-kArcadeHalfDepth, kImpostBottom, -kArcadeHalfDepth),
                    c + glm::vec3(kArcadeHalfDepth, kSpringLine, kArcadeHalfDepth),
                    ProceduralMesh::kAllFaces & ~ProceduralMesh::kMaxY);
    }
    return mesh;
}

/// Upper floor: slender shafts with a capital under the roof, and a parapet between them
/// whose ends meet the shafts.
ProceduralMesh upperColumns() {
    constexpr float kCapitalBottom = 7.6f;
    ProceduralMesh mesh;
    for (const glm::vec3& c : columnCentres()) {
        mesh.addCylinder(c + glm::vec3(0.f, kFirstFloorTop, 0.f), kUpperColumnRadius,
                         kCapitalBottom - kFirstFloorTop, kColumnSegments);
        mesh.addBox(c + glm::vec3(-kArcadeHalfDepth, kCapitalBottom, -kArcadeHalfDepth),
                    c + glm::vec3(kArcadeHalfDepth, kRoofUnderside, kArcadeHalfDepth),
                    ProceduralMesh::kAllFaces & ~ProceduralMesh::kMaxY);
    }
    return mesh;
}

ProceduralMesh parapet() {
    // Where the parapet's faces meet the round shaft.
    const float inset = std::sqrt(kUpperColumnRadius * kUpperColumnRadius -
                                  kParapetHalfThickness * kParapetHalfThickness);
    ProceduralMesh side;
    for (int k = 0; k < kSpansPerSide; ++k) {
        const float u = -kColonnade + 2.f * float(k);
        side.addBox({u + inset, kFirstFloorTop, -kParapetHalfThickness},
                    {u + 2.f - inset, kFirstFloorTop + kParapetHeight, kParapetHalfThickness},
                    ProceduralMesh::kMaxY | ProceduralMesh::kMinZ | ProceduralMesh::kMaxZ);
    }
    ProceduralMesh mesh;
    appendOnAllSides(mesh, side, kColonnade);
    return mesh;
}

Material surface(const glm::vec3& albedo, float roughness = 1.f, float metallic = 0.f) {
    Material m;
    m.baseColor = albedo;
    m.roughness = roughness;
    m.metallic = metallic;
    return m;
}

Material emitter(const glm::vec3& radiance) {
    Material m = surface(glm::vec3(0.8f));
    m.emission = radiance;
    return m;
}

constexpr glm::quat kUpright(1.f, 0.f, 0.f, 0.f);

PathKey key(float time, const glm::vec3& position, const glm::quat& rotation = kUpright) {
    return PathKey{time, position, rotation};
}

Transform placedAt(const glm::vec3& position, const glm::quat& rotation = kUpright) {
    Transform t;
    t.translation = position;
    t.rotation = rotation;
    return t;
}

// Corners of a loop through `points` (x, z) at a height.
std::vector<glm::vec3> loopAt(float y, std::initializer_list<glm::vec2> points) {
    std::vector<glm::vec3> corners;
    for (const glm::vec2& p : points)
        corners.emplace_back(p.x, y, p.y);
    return corners;
}

std::vector<glm::vec3> polygon(float y, float radius, int corners, bool clockwise) {
    std::vector<glm::vec3> out;
    for (int k = 0; k < corners; ++k) {
        const float a = (clockwise ? -1.f : 1.f) * glm::two_pi<float>() * float(k) / float(corners);
        out.emplace_back(radius * std::cos(a), y, radius * std::sin(a));
    }
    return out;
}

void addStructure(BuiltinSceneBuilder& builder) {
    Registry& registry = builder.registry();
    const auto addStatic = [&](std::string name, ProceduralMesh&& mesh, const Material& material) {
        registry.emplace<StaticMesh>(
            builder.addMesh(std::move(name), Transform{}, std::move(mesh), material));
    };
    // Large, coarsely tessellated surfaces take their soft shadows and indirect light from the
    // point cache when one is built (PointCacheShaded).
    const auto addCoarse = [&](std::string name, ProceduralMesh&& mesh, const Material& material) {
        const Entity e = builder.addMesh(std::move(name), Transform{}, std::move(mesh), material);
        registry.emplace<StaticMesh>(e);
        registry.emplace<PointCacheShaded>(e);
    };
    const glm::vec3 up(0.f, 1.f, 0.f);

    ProceduralMesh court;
    court.addQuad({-kColonnade, 0.f, -kColonnade}, {kColonnade, 0.f, -kColonnade},
                  {kColonnade, 0.f, kColonnade}, {-kColonnade, 0.f, kColonnade}, up);
    addCoarse("court floor", std::move(court), surface({0.62f, 0.36f, 0.24f}, 0.6f));
    addCoarse("gallery floor", frame(kColonnade, kOuter, 0.f, up), surface({0.55f, 0.52f, 0.47f}));

    ProceduralMesh walls;
    const ProceduralMesh wallSide = outerWallSide();
    appendOnAllSides(walls, wallSide, kOuter);
    addCoarse("outer walls", std::move(walls), surface({0.78f, 0.72f, 0.62f}));

    addCoarse("first floor", slab(kFirstFloorUnderside, kFirstFloorTop),
              surface({0.80f, 0.78f, 0.74f}));
    addCoarse("roof", slab(kRoofUnderside, kRoofTop), surface({0.70f, 0.66f, 0.60f}));

    ProceduralMesh arcade;
    appendOnAllSides(arcade, arcadeSide(), kColonnade);
    addStatic("arcade", std::move(arcade), surface({0.58f, 0.30f, 0.22f}));
    addStatic("ground floor columns", groundColumns(), surface({0.82f, 0.79f, 0.72f}));
    addStatic("upper floor columns", upperColumns(), surface({0.82f, 0.79f, 0.72f}));
    addStatic("parapet", parapet(), surface({0.42f, 0.48f, 0.58f}));

    // The fountain: a round basin, a water surface, a pillar with a bowl, a bronze sphere.
    ProceduralMesh basin;
    const glm::vec2 basinProfile[] = {{1.6f, 0.f}, {1.6f, 0.5f}, {1.4f, 0.5f}, {1.4f, 0.3f}};
    basin.addLathe(glm::vec3(0.f), basinProfile, 48);
    const glm::vec2 pillarProfile[] = {
        {0.18f, 0.3f}, {0.18f, 1.3f}, {0.6f, 1.45f}, {0.6f, 1.52f}, {0.f, 1.52f}};
    basin.addLathe(glm::vec3(0.f), pillarProfile, kRoundSegments);
    addStatic("fountain", std::move(basin), surface({0.66f, 0.65f, 0.62f}));
    ProceduralMesh water;
    const glm::vec2 waterProfile[] = {{1.4f, 0.3f}, {0.18f, 0.3f}};
    water.addLathe(glm::vec3(0.f), waterProfile, 48);
    addStatic("fountain water", std::move(water), surface({0.06f, 0.16f, 0.20f}, 0.05f));
    ProceduralMesh sphere;
    sphere.addSphere({0.f, 1.87f, 0.f}, 0.35f, kRoundSegments, 12);
    addStatic("bronze sphere", std::move(sphere), surface({0.80f, 0.55f, 0.30f}, 0.25f, 1.f));

    ProceduralMesh planters, foliage;
    for (const glm::vec2 p : {glm::vec2(5.2f, -5.2f), glm::vec2(-5.2f, 5.2f)}) {
        planters.addBox({p.x - 0.6f, 0.f, p.y - 0.6f}, {p.x + 0.6f, 0.6f, p.y + 0.6f},
                        ProceduralMesh::kAllFaces & ~ProceduralMesh::kMinY);
        foliage.addSphere({p.x, 0.95f, p.y}, 0.55f, 16, 10);
    }
    addStatic("planters", std::move(planters), surface({0.45f, 0.36f, 0.28f}));
    addStatic("foliage", std::move(foliage), surface({0.16f, 0.38f, 0.10f}));

    // Emissive panels 2 cm under the gallery ceilings: two per side downstairs, one upstairs.
    // Radiance 30 W/(m^2 sr): pi * L * A = 90 W for a 1.6 x 0.6 m panel.
    const glm::vec3 panelRadiance(30.f, 29.f, 26.f);
    int panel = 0;
    for (int side = 0; side < 4; ++side)
        for (const auto& [u, y, halfLength, halfWidth] :
             {std::array{-5.f, kFirstFloorUnderside - 0.02f, 0.8f, 0.3f},
              std::array{5.f, kFirstFloorUnderside - 0.02f, 0.8f, 0.3f},
              std::array{0.f, kRoofUnderside - 0.02f, 0.6f, 0.25f}}) {
            ProceduralMesh quad;
            // Copied into the lambda: clang before 16 cannot capture structured bindings.
            const auto corner = [&, u = u, y = y](float du, float dw) {
                return onSide(side, 9.5f, {u + du, y, dw});
            };
            quad.addQuad(corner(-halfLength, -halfWidth), corner(halfLength, -halfWidth),
                         corner(halfLength, halfWidth), corner(-halfLength, halfWidth), -up);
            addStatic("ceiling panel " + std::to_string(++panel), std::move(quad),
                      emitter(panelRadiance));
        }
}

void addLights(BuiltinSceneBuilder& builder) {
    Registry& registry = builder.registry();
    // Late-morning sun, 62 degrees high, 60 W/m^2 on a surface facing it.
    const Entity sun = builder.addEntity(
        "sun", placedAt(glm::vec3(0.f, 30.f, 0.f), facing({-0.45f, -1.f, -0.3f})));
    registry.emplace<DirectionalLight>(sun, DirectionalLight{{1.f, 0.95f, 0.85f}, 60.f});

    // Lanterns in the corners of the ground-floor galleries: 40 W/sr, 500 W each.
    int lantern = 0;
    for (const glm::vec2 p : {glm::vec2(-9.5f, -9.5f), glm::vec2(9.5f, -9.5f),
                              glm::vec2(9.5f, 9.5f), glm::vec2(-9.5f, 9.5f)}) {
        const Entity e =
            builder.addEntity("lantern " + std::to_string(++lantern), placedAt({p.x, 3.3f, p.y}));
        registry.emplace<PointLight>(e, PointLight{{1.f, 0.85f, 0.65f}, 40.f});
    }

    // A spot under the north roof, aimed through the upper colonnade at the bronze sphere.
    const glm::vec3 spotPosition(0.f, 7.4f, -10.5f);
    const Entity spot = builder.addEntity(
        "sphere spot", placedAt(spotPosition, facing(glm::vec3(0.f, 1.87f, 0.f) - spotPosition)));
    registry.emplace<SpotLight>(
        spot, SpotLight{{1.f, 0.97f, 0.9f}, 1500.f, glm::radians(6.f), glm::radians(10.f)});
}

void addMobiles(BuiltinSceneBuilder& builder) {
    Registry& registry = builder.registry();
    const auto addMobile = [&](std::string name, ProceduralMesh&& mesh, const Material& material,
                               PathFollower path) {
        const Entity e = builder.addMesh(
            std::move(name), placedAt(path.keys.front().position, path.keys.front().rotation),
            std::move(mesh), material);
        registry.emplace<MobileMesh>(e);
        registry.emplace<PathFollower>(e, std::move(path));
    };

    // A door on the inside of the north doorway that slides 2.6 m open and shut every 11 s.
    ProceduralMesh door;
    door.addBox({-1.3f, -1.65f, -0.04f}, {1.3f, 1.65f, 0.04f});
    const glm::vec3 shut(0.f, 1.66f, -kOuter + 0.1f), open = shut + glm::vec3(2.6f, 0.f, 0.f);
    addMobile("sliding door", std::move(door), surface({0.45f, 0.28f, 0.15f}),
              PathFollower{{key(0.f, shut), key(2.f, shut), key(5.f, open), key(8.f, open),
                            key(11.f, shut)}});

    // A cart pushed up and down the east gallery along the wall, 16 m in 8 s each way.
    ProceduralMesh cart, wheel;
    cart.addBox({-0.35f, 0.3f, -0.6f}, {0.35f, 0.8f, 0.6f});
    const glm::vec2 wheelProfile[] = {{0.f, -0.04f}, {0.15f, -0.04f}, {0.15f, 0.04f}, {0.f, 0.04f}};
    wheel.addLathe(glm::vec3(0.f), wheelProfile, 16);
    for (const float x : {-0.39f, 0.39f})
        for (const float z : {-0.42f, 0.42f}) {
            glm::mat4 axle(1.f); // the wheel's axis (+y) along +x
            axle[0] = glm::vec4(0.f, -1.f, 0.f, 0.f);
            axle[1] = glm::vec4(1.f, 0.f, 0.f, 0.f);
            axle[3] = glm::vec4(x, 0.16f, z, 1.f);
            cart.append(wheel, axle);
        }
    const glm::vec3 south(10.8f, 0.f, 8.f), north(10.8f, 0.f, -8.f);
    addMobile("cart", std::move(cart), surface({0.25f, 0.35f, 0.55f}),
              PathFollower{{key(0.f, north), key(1.f, north), key(9.f, south), key(10.f, south),
                            key(18.f, north)}});

    // A crate pushed around a 2 m square in the court's north-west corner.
    ProceduralMesh crate;
    crate.addBox(glm::vec3(-0.4f), glm::vec3(0.4f));
    addMobile("crate", std::move(crate), surface({0.62f, 0.46f, 0.26f}),
              walkingLoop(loopAt(0.405f, {{-6.f, -6.f}, {-4.f, -6.f}, {-4.f, -4.f}, {-6.f, -4.f}}),
                          0.5f, 1.5f));

    // A crate hoisted from the court floor to the height of the upper gallery and back,
    // turning a quarter turn on the way up and back on the way down.
    ProceduralMesh hoisted;
    hoisted.addBox(glm::vec3(-0.35f), glm::vec3(0.35f));
    const glm::vec3 low(5.f, 0.355f, 5.f), high(5.f, 4.8f, 5.f);
    const glm::quat turned = glm::angleAxis(glm::half_pi<float>(), glm::vec3(0.f, 1.f, 0.f));
    addMobile("hoisted crate", std::move(hoisted), surface({0.55f, 0.50f, 0.30f}),
              PathFollower{{key(0.f, low), key(2.f, low), key(7.f, high, turned),
                            key(9.f, high, turned), key(14.f, low)}});
}

void addAvatars(BuiltinSceneBuilder& builder) {
    Registry& registry = builder.registry();
    struct Walker {
        const char* name;
        std::vector<glm::vec3> loop; // starting corners differ, so the walkers are out of step
        float speed;                 // m/s
        glm::vec3 color;
    };
    // Character origins are at their centre, half their height above the floor they walk on.
    const float ground = 0.5f * kAvatarHeight;
    const float upstairs = kFirstFloorTop + 0.5f * kAvatarHeight;
    const Walker walkers[] = {
        {"walker (ground gallery)",
         loopAt(ground, {{-9.2f, -9.2f}, {9.2f, -9.2f}, {9.2f, 9.2f}, {-9.2f, 9.2f}}),
         1.3f,
         {0.70f, 0.20f, 0.20f}},
        {"walker (ground gallery, reverse)",
         loopAt(ground, {{8.4f, 8.4f}, {8.4f, -8.4f}, {-8.4f, -8.4f}, {-8.4f, 8.4f}}),
         1.1f,
         {0.20f, 0.55f, 0.25f}},
        {"walker (fountain)", polygon(ground, 3.f, 8, false), 1.f, {0.85f, 0.75f, 0.20f}},
        {"walker (court)", polygon(ground, 4.2f, 8, true), 1.2f, {0.25f, 0.30f, 0.75f}},
        {"walker (upper gallery)",
         loopAt(upstairs, {{-9.5f, 9.5f}, {9.5f, 9.5f}, {9.5f, -9.5f}, {-9.5f, -9.5f}}),
         1.f,
         {0.60f, 0.30f, 0.65f}},
        {"walker (through the arches)",
         loopAt(ground, {{-9.f, 2.f}, {-5.f, 2.f}, {-5.f, 4.f}, {-9.f, 4.f}}),
         1.f,
         {0.90f, 0.50f, 0.20f}},
        {"walker (across the court)",
         loopAt(ground, {{2.f, -10.f}, {2.f, 10.f}}),
         1.2f,
         {0.20f, 0.65f, 0.70f}},
    };
    for (const Walker& w : walkers) {
        ProceduralMesh body;
        body.addCapsule(glm::vec3(0.f), kAvatarRadius, kAvatarHeight, 16, 4);
        PathFollower path = walkingLoop(w.loop, w.speed, 0.6f);
        const Entity e = builder.addMesh(
            w.name, placedAt(path.keys.front().position, path.keys.front().rotation),
            std::move(body), surface(w.color));
        registry.emplace<Avatar>(e, Avatar{0.5f * kAvatarHeight});
        registry.emplace<PathFollower>(e, std::move(path));
    }
}

void addCamera(BuiltinSceneBuilder& builder) {
    // Along the east gallery, west across the court's south half, along the west gallery and
    // back east just north of the fountain: 50 m at 2 m/s plus four 1 s turns, 29 s a loop.
    PathFollower walk = walkingLoop(
        loopAt(1.7f, {{9.5f, -2.f}, {9.5f, 4.f}, {-9.5f, 4.f}, {-9.5f, -2.f}}), 2.f, 1.f);
    const Entity camera = builder.addEntity(
        "camera", placedAt(walk.keys.front().position, walk.keys.front().rotation));
    builder.registry().emplace<Camera>(camera, Camera{1.f, 0.05f, 100.f, true});
    builder.registry().emplace<PathFollower>(camera, std::move(walk));
}

} // namespace

void buildAtrium(BuiltinSceneBuilder& builder) {
    addStructure(builder);
    addLights(builder);
    addMobiles(builder);
    addAvatars(builder);
    addCamera(builder);
    // Blue sky radiance, W/(m^2 sr): about an eighth of the sunlit court floor's
    // (0.62 / pi * 60 W/m^2 * sin 62 degrees = 10.4).
    builder.finish(glm::vec3(1.0f, 1.3f, 1.8f));
    // The sunlit floor (about 10 W/(m^2 sr)) would saturate the tonemap at exposure 1; a
    // quarter keeps the court readable while the arcades stay visible.
    builder.registry().ctx().get<SceneInfo>().exposure = 0.25f;
}

} // namespace qgi
