// Photon update benchmarks, every figure a same-run ratio (docs/BENCHMARKS.md):
//  - TracePaths/<scene>: PhotonTracer re-traces every path of the first shot from its head
//    (Russian roulette, reflection, storage), segments per second; against
//    RawRandomRays/<scene> (bench_raytrace's incoherent-ray ceiling: random origins in the
//    scene bounds, uniform directions, 8-wide batches) and RawPhotonRays/<scene> (the very
//    segments the tracer traces, cast without any photon work). Same default thread count.
//  - MobileUpdate/<scene>: one frame of the quasi-static update, photon update then DETP
//    irradiance, while the mobiles move 1 cm per frame (cornell: its block, 1M photons, photon
//    mode; atrium: all four mobiles, 4M photons, hybrid mode), against FullReshoot/<scene>:
//    the same frame with fullRecompute (every photon re-shot, every vertex re-estimated).
//    Counters split the frame into its stages (ms per frame). The argument is the path grid's
//    resolution (0: the default), swept for MobileUpdate: memory against candidates and time.
//  - MobileTravel/<scene>: the same frames with the mobiles travelling 20 cm before they
//    turn back instead of 5 cm.
//  - MobileUpdate/cornell-hybrid/0 and FullReshoot/cornell-hybrid/0: cornell's pair in hybrid
//    mode (DETP leaves out the luminaire's first bounce, which the shader draws).
//  - MobileUpdatePhotons/cornell/<photons> and FullReshootPhotons/cornell/<photons>: the same
//    pair at 125k, 250k and 500k photons: the photon count that fits a frame budget.
//  - MobileUpdatePhotons/two-rooms/<photons> and FullReshootPhotons/two-rooms/<photons>: the
//    same pair on two closed rooms, a mobile cube moving in one of them, whose light keeps
//    250k photons while the other room's light takes the rest of 0.5M to 4M: the ray set
//    grows eightfold, the paths the cube can touch stay the same. The incremental frame
//    should stay flat while the full recompute grows with the ray set.
//  - MobileToggle/<scene>: the same frame when the mobiles are taken out of the world and put
//    back on alternate frames (MobileMesh::active), the pooled objects' spawn and despawn.
//  - FullShot/<scene>: a frame that shoots every photon, path grid and full estimate included
//    (a new system's first frame on the world as it stands): what a full shot costs in play.
//  - AlbedoEdit/<scene>/<mobile|floor>: a frame after the albedo of the first mobile, or of
//    the floor, was edited (the paths that hit it re-traced; for the floor, the grid rebuilt).
//  - GridBuild/<scene>: the path grid indexing the whole shot ray set (every full shot builds
//    it), at the default resolution.
//  - LampSwitch/atrium: frames while the lamps are switched off and on again (their photons
//    re-shot within the budget), mean and worst; against FullShot, what a switch cost when it
//    shot every photon anew.
//  - LampRedealt/atrium: a lamp a hundred times brighter, then back, each time dealt new
//    photons within the budget (its count 4x off its share): frames until each sweep ends.
//  - LightAdded/atrium: a point light with a quarter of the lights' power added in play (its
//    photons taken from free ranges or appended, and shot within the budget), then destroyed
//    (re-shot empty): frames until each sweep ends, mean and worst, against still frames of
//    the same run. These two come last: they leave the store grown.
#include "components/LightStandIn.h"
#include "components/Material.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointLight.h"
#include "components/SpotLight.h"
#include "components/StaticMesh.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/ecs/Registry.h"
#include "runtime/raytrace/RayScene.h"
#include "runtime/scene/BuiltinSceneBuilder.h"
#include "runtime/scene/BuiltinScenes.h"
#include "runtime/scene/SceneInfo.h"
#include "systems/detp/DetpIrradianceSystem.h"
#include "systems/photon_update/PhotonPathGrid.h"
#include "systems/photon_update/PhotonStore.h"
#include "systems/photon_update/PhotonTracer.h"
#include "systems/photon_update/PhotonUpdateSystem.h"

#include <benchmark/benchmark.h>
#include <glm/gtc/matrix_transform.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <chrono>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <tuple>
#include <vector>

namespace qgi {
namespace {

constexpr std::size_t kGrain = 1024; // rays per task, as in bench_raytrace
constexpr std::uint32_t kSeed = 1234;

/// Two closed rooms side by side, each with a point light; a mobile cube in the first
/// (buildTwoRooms).
const std::string kTwoRooms = "two-rooms";
/// Photons of the first room's light, whatever the photon count.
constexpr std::uint32_t kFirstRoomPhotons = 250'000;

std::uint32_t photonsFor(const std::string& scene) {
    return scene == "atrium" ? 4'000'000 : 1'000'000;
}

/// The walls of a closed room: an axis-aligned box of half extents `half` centred on
/// `centre`, facing in.
ProceduralMesh roomMesh(const glm::vec3& centre, const glm::vec3& half) {
    ProceduralMesh mesh;
    for (int axis = 0; axis < 3; ++axis) {
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        for (const float side : {-1.f, 1.f}) {
            glm::vec3 corner[4], facing(0.f);
            facing[axis] = -side;
            for (int k = 0; k < 4; ++k) {
                corner[k] = centre;
                corner[k][axis] += side * half[axis];
                corner[k][u] += (k == 1 || k == 2 ? 1.f : -1.f) * half[u];
                corner[k][v] += (k >= 2 ? 1.f : -1.f) * half[v];
            }
            mesh.addQuad(corner[0], corner[1], corner[2], corner[3], facing);
        }
    }
    return mesh;
}

/// kTwoRooms with `photons` in all: two closed 3 x 2.4 x 3 m rooms 1.5 m apart (albedo 0.6),
/// each lit by a point light under its ceiling and holding a 30 cm cube 2 cm above the floor,
/// the first room's mobile, the second's static. The first room's light gets
/// kFirstRoomPhotons (photons go to the lights in proportion to their power), the second's
/// the rest. No path leaves its room, so the paths the moving cube can touch are the same at
/// any photon count.
void buildTwoRooms(Registry& registry, std::uint32_t photons) {
    BuiltinSceneBuilder builder(registry, kTwoRooms, 0.1f); // meshes refined to 10 cm
    Material wall;
    wall.baseColor = glm::vec3(0.6f);
    const glm::vec3 room(1.5f, 1.2f, 1.5f), cube(0.15f);
    const float firstIntensity = 10.f;
    for (int r = 0; r < 2; ++r) {
        const glm::vec3 centre(4.5f * float(r), room.y, 0.f);
        registry.emplace<StaticMesh>(builder.addMesh(r == 0 ? "first room" : "second room",
                                                     Transform{}, roomMesh(centre, room), wall));
        const glm::vec3 at = centre + glm::vec3(0.4f, cube.y + 0.02f - room.y, 0.3f);
        ProceduralMesh block;
        block.addBox(at - cube, at + cube);
        const Entity e =
            builder.addMesh(r == 0 ? "cube" : "static cube", Transform{}, std::move(block), wall);
        if (r == 0)
            registry.emplace<MobileMesh>(e);
        else
            registry.emplace<StaticMesh>(e);
        const Entity light =
            builder.addEntity(r == 0 ? "first light" : "second light",
                              Transform{centre + glm::vec3(0.f, 0.8f * room.y, 0.f)});
        const float share = r == 0 ? 1.f
                                   : float(photons - std::min(photons, kFirstRoomPhotons)) /
                                         float(kFirstRoomPhotons);
        registry.emplace<PointLight>(light, PointLight{glm::vec3(1.f), share * firstIntensity});
    }
    builder.finish(glm::vec3(0.f)); // closed rooms: no sky
}

/// A built-in scene with its ray scene and photon system, shot once per process.
struct PhotonWorld {
    Registry registry;
    std::unique_ptr<PhotonUpdateSystem> system;
    std::unique_ptr<DetpIrradianceSystem> irradiance;
    std::vector<Entity> mobiles;
    std::vector<glm::mat4> rest;
    std::uint64_t frame = 0;
    // The first shot, kept: the tracing benchmarks do not depend on what moved since.
    std::vector<PhotonHead> heads;
    std::vector<Ray> segmentRays;

    /// photons 0: photonsFor(name); gridResolution 0: the default PhotonSettings::gridResolution.
    PhotonWorld(const std::string& name, bool fullRecompute, std::uint32_t gridResolution,
                std::uint32_t photons) {
        if (photons == 0) photons = photonsFor(name);
        const bool rooms = name == kTwoRooms;
        // "cornell-hybrid": the cornell box as the demo's default hybrid mode lights it.
        const bool cornellHybrid = name == "cornell-hybrid";
        if (rooms)
            buildTwoRooms(registry, photons);
        else
            buildBuiltinScene(registry, cornellHybrid ? "cornell" : name, SceneOptions{});
        registry.ctx().emplace<RayScene>().build(registry);
        PhotonSettings settings;
        settings.photonCount = photons;
        settings.fullRecompute = fullRecompute;
        if (gridResolution > 0) settings.gridResolution = gridResolution;
        // Photon mode on the cornell box: its luminaire, not the punctual stand-in. (In hybrid
        // mode the stand-in shoots no photons either: the shader draws its light.)
        settings.punctualLights = name != "cornell";
        system = std::make_unique<PhotonUpdateSystem>(settings);
        system->update(registry, FrameContext{});
        DetpSettings detp;
        // Photon mode on the two rooms too, with a disc radius that does not shrink as the
        // second room's photons grow (the default follows the photon count).
        detp.hybrid = settings.punctualLights && !rooms;
        if (rooms) detp.discRadius = 0.05f;
        irradiance = std::make_unique<DetpIrradianceSystem>(detp);
        irradiance->build(registry);
        irradiance->update(registry, FrameContext{});
        registry.clearChanges();
        mobiles = registry.view<const MobileMesh>().entities();
        for (const Entity e : mobiles)
            rest.push_back(registry.get<WorldTransform>(e).matrix);
        const PhotonStore& shot = store();
        for (std::uint32_t p = 0; p < shot.pathCount(); ++p) {
            const PhotonPath& path = shot.paths[p];
            const PhotonSegments& s = shot.segments;
            heads.push_back(
                {s.origin[path.first], s.direction[path.first], s.power[path.first], p, 0});
            for (std::size_t k = path.first; k < path.first + path.count; ++k)
                segmentRays.push_back(
                    Ray{s.origin[k], 0.f, s.direction[k], std::numeric_limits<float>::infinity()});
        }
    }

    const PhotonStore& store() const { return registry.ctx().get<PhotonStore>(); }

    /// One frame with nothing moved (what game code changed is already patched). Returns its
    /// milliseconds, photon update and DETP.
    double still() {
        ++frame;
        const auto start = std::chrono::steady_clock::now();
        const FrameContext context{frame, 0.0, 0.f, 0};
        system->update(registry, context);
        irradiance->update(registry, context);
        registry.clearChanges();
        return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
            .count();
    }

    /// Every mobile 1 cm further along x, turning back after `turn` cm (or, with `toggle`,
    /// taken out of the world or put back: MobileMesh::active); then the frame's update.
    /// Returns the milliseconds DETP took.
    double step(bool toggle = false, int turn = 5) {
        ++frame;
        const int phase = int(frame % std::uint64_t(2 * turn));
        const float offset = 0.01f * float(phase <= turn ? phase : 2 * turn - phase);
        for (std::size_t i = 0; i < mobiles.size(); ++i)
            if (toggle)
                registry.patch<MobileMesh>(mobiles[i]).active = frame % 2 == 0;
            else
                registry.patch<WorldTransform>(mobiles[i]).matrix =
                    glm::translate(rest[i], glm::vec3(offset, 0.f, 0.f));
        registry.ctx().get<RayScene>().syncMoved(registry);
        const FrameContext context{frame, 0.0, 0.f, 0};
        system->update(registry, context);
        const auto start = std::chrono::steady_clock::now();
        irradiance->update(registry, context);
        const double detpMs =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();
        registry.clearChanges();
        return detpMs;
    }
};

/// The world for these settings (PhotonWorld's zeros are the defaults), shot on first use.
PhotonWorld& world(const std::string& name, bool fullRecompute = false,
                   std::uint32_t gridResolution = 0, std::uint32_t photons = 0) {
    static std::map<std::tuple<std::string, bool, std::uint32_t, std::uint32_t>,
                    std::unique_ptr<PhotonWorld>>
        worlds;
    const std::tuple key(name, fullRecompute, gridResolution, photons);
    auto it = worlds.find(key);
    if (it == worlds.end()) {
        worlds.clear(); // one world at a time: 4M photons take a few GiB
        it = worlds
                 .emplace(key, std::make_unique<PhotonWorld>(name, fullRecompute, gridResolution,
                                                             photons))
                 .first;
    }
    return *it->second;
}

/// Albedo by entity index, as the system builds it.
std::vector<glm::vec3> albedoTable(const Registry& registry) {
    std::vector<glm::vec3> albedo;
    registry.view<const Material>().each([&](Entity e, const Material& m) {
        if (e.index >= albedo.size()) albedo.resize(e.index + 1, glm::vec3(0.f));
        albedo[e.index] = glm::clamp(m.baseColor, 0.f, 1.f);
    });
    return albedo;
}

void BM_TracePaths(benchmark::State& state, const std::string& name) {
    const PhotonWorld& w = world(name);
    const std::vector<glm::vec3> albedo = albedoTable(w.registry);
    const PhotonTracer::Surfaces surfaces{w.system->settings().seed,
                                          w.system->settings().maxBounces, albedo};
    const RayScene& scene = w.registry.ctx().get<RayScene>();
    PhotonTracer tracer;
    PhotonSegments out;
    std::vector<std::uint32_t> ends;
    const auto traceAll = [&] {
        out.clear();
        ends.assign(1, 0);
        tracer.trace(
            scene, surfaces, w.heads.size(), [&](std::size_t p) { return w.heads[p]; }, out, ends);
    };
    // Once untimed: the output arrays are then allocated and their pages mapped, as the
    // store's are from frame to frame; the figure is the tracing, not the first touch.
    traceAll();
    for (auto _ : state) {
        traceAll();
        benchmark::DoNotOptimize(out.origin.data());
    }
    state.counters["segments/s"] =
        benchmark::Counter(double(state.iterations() * out.size()), benchmark::Counter::kIsRate);
    state.counters["segments/path"] = double(out.size()) / double(w.heads.size());
}

/// Casts `rays` in parallel 8-wide batches; reports rays/s.
void castRays(benchmark::State& state, const RayScene& scene, const std::vector<Ray>& rays) {
    std::vector<std::optional<Hit>> hits(rays.size());
    for (auto _ : state) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), kGrain),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                              scene.intersect(std::span(rays).subspan(r.begin(), r.size()),
                                              std::span(hits).subspan(r.begin(), r.size()));
                          });
        benchmark::ClobberMemory();
    }
    state.counters["rays/s"] =
        benchmark::Counter(double(state.iterations() * rays.size()), benchmark::Counter::kIsRate);
}

void BM_RawRandomRays(benchmark::State& state, const std::string& name) {
    const PhotonWorld& w = world(name);
    const Aabb bounds = w.registry.ctx().get<SceneInfo>().bounds;
    std::mt19937 rng(kSeed);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::normal_distribution<float> gauss;
    std::vector<Ray> rays(std::size_t(1) << 20);
    for (Ray& ray : rays) {
        ray.origin = bounds.min + glm::vec3(unit(rng), unit(rng), unit(rng)) * bounds.extent();
        do
            ray.direction = {gauss(rng), gauss(rng), gauss(rng)};
        while (glm::length(ray.direction) < 1e-6f);
        ray.direction = glm::normalize(ray.direction);
    }
    castRays(state, w.registry.ctx().get<RayScene>(), rays);
}

void BM_RawPhotonRays(benchmark::State& state, const std::string& name) {
    const PhotonWorld& w = world(name);
    castRays(state, w.registry.ctx().get<RayScene>(), w.segmentRays);
}

void reportFrames(benchmark::State& state, const PhotonWorld& w, double retraced, double candidates,
                  double segments) {
    const double frames = double(state.iterations());
    state.counters["retraced/frame"] = retraced / frames;
    state.counters["candidates/frame"] = candidates / frames;
    state.counters["segments/frame"] = segments / frames;
    state.counters["paths"] = double(w.store().pathCount());
    state.counters["store_MiB"] =
        double(w.store().segments.size() * PhotonSegments::kBytesPerSegment) / (1 << 20);
    state.counters["grid_MiB"] =
        double(w.registry.ctx().get<PhotonPathGrid>().memoryBytes()) / (1 << 20);
}

/// The path grid built from the whole shot ray set, as every full shot builds it (the first
/// frame, a light added or removed): over the scene's bounds at the default resolution.
void BM_GridBuild(benchmark::State& state, const std::string& name) {
    PhotonWorld& w = world(name);
    const Aabb bounds = w.registry.ctx().get<SceneInfo>().bounds;
    const std::uint32_t resolution = PhotonSettings{}.gridResolution;
    PhotonPathGrid grid;
    // Once untimed: its lists' memory is then allocated and mapped, as in play, where each full
    // shot rebuilds the same grid in place.
    grid.build(w.store(), bounds, resolution);
    for (auto _ : state)
        grid.build(w.store(), bounds, resolution);
    if (!grid.indexes(w.store()) || grid.entryCount() == 0) state.SkipWithError("nothing indexed");
    state.counters["paths"] = double(w.store().pathCount());
    double segments = 0; // live ones (the store has room for re-traced paths too)
    for (const PhotonPath& path : w.store().paths)
        segments += path.count;
    state.counters["segments"] = segments;
    state.counters["entries"] = double(grid.entryCount());
    state.counters["grid_MiB"] = double(grid.memoryBytes()) / (1 << 20);
}

/// A full shot in play (not --full-recompute): what a light added or removed costs in the frame
/// it happens; the frame re-shoots every photon, rebuilds the path grid and re-estimates every
/// vertex. Each iteration changes which lights shoot photons: with punctual lights (the atrium)
/// a point light is added at the scene's centre or removed again; without them (the cornell
/// box in photon mode) its lamp's stand-in tag comes off or back, so the luminaire's first
/// bounce is counted or not.
/// A full shot in play: what a new PhotonUpdateSystem's first frame costs on the world as it
/// stands (every photon traced, the path grid built, DETP's full estimate), now needed only
/// when the lights' photons cannot be dealt within the store's room.
void BM_FullShot(benchmark::State& state, const std::string& name) {
    PhotonWorld& w = world(name);
    std::size_t fullFrames = 0;
    for (auto _ : state) {
        w.system = std::make_unique<PhotonUpdateSystem>(w.system->settings());
        w.still();
        fullFrames += w.system->lastFrame().full ? 1 : 0;
    }
    if (fullFrames != std::size_t(state.iterations()))
        state.SkipWithError("a frame was not a full shot");
}

/// A surface's albedo edited in play: its baseColor a tenth darker, then back, each frame; only
/// the paths that hit it are re-traced (from that hit). `surface`: a static mesh's name, or
/// empty for the first mobile.
void BM_AlbedoEdit(benchmark::State& state, const std::string& name, const std::string& surface) {
    PhotonWorld& w = world(name);
    Registry& r = w.registry;
    Entity edited = surface.empty() ? w.mobiles.front() : Entity{};
    if (!surface.empty())
        for (const Entity e : r.view<const Name, const StaticMesh>().entities())
            if (r.get<Name>(e).value == surface) edited = e;
    if (edited.isNull()) {
        state.SkipWithError("no such surface");
        return;
    }
    const glm::vec3 albedo = r.get<Material>(edited).baseColor;
    bool darker = false;
    double retraced = 0;
    for (auto _ : state) {
        darker = !darker;
        r.patch<Material>(edited).baseColor = darker ? 0.9f * albedo : albedo;
        w.still();
        retraced += double(w.system->lastFrame().retracedPaths);
        if (w.system->lastFrame().full) state.SkipWithError("a full shot");
    }
    if (darker) { // leave the world as it was for the benchmarks after this one
        r.patch<Material>(edited).baseColor = albedo;
        w.still();
    }
    state.counters["retraced/frame"] = retraced / double(state.iterations());
    state.counters["paths"] = double(w.store().pathCount());
    state.counters["grid_rebuilt"] =
        w.system->lastFrame().reindexedPaths == w.store().pathCount() ? 1.0 : 0.0;
}

void BM_MobileToggle(benchmark::State& state, const std::string& name) {
    PhotonWorld& w = world(name);
    double retraced = 0, candidates = 0, segments = 0, photons = 0, detp = 0;
    for (auto _ : state) {
        const auto start = std::chrono::steady_clock::now();
        detp += w.step(true);
        photons +=
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();
        const PhotonUpdateSystem::FrameStats& stats = w.system->lastFrame();
        retraced += double(stats.retracedPaths);
        candidates += double(stats.candidatePaths);
        segments += double(stats.tracedSegments);
    }
    reportFrames(state, w, retraced, candidates, segments);
    const double frames = double(state.iterations());
    state.counters["photons_ms"] = (photons - detp) / frames;
    state.counters["detp_ms"] = detp / frames;
    // Leave the mobiles in the world for the next benchmark on this world.
    if (w.frame % 2 == 1) w.step(true);
}

/// The lamps (point and spot lights that shoot photons) switched off, and on again once their
/// photons have all been re-shot, over and over; the mobiles stay. Each frame is timed: the
/// mean is the benchmark's time, the worst frame a counter. Before lights kept their photons
/// when off, every switch was a full shot (FullShot's frame).
void BM_LampSwitch(benchmark::State& state, const std::string& name) {
    PhotonWorld& w = world(name);
    Registry& r = w.registry;
    std::vector<Entity> points, spots;
    for (const Entity e : r.view<const PointLight>().entities())
        if (!r.has<LightStandIn>(e)) points.push_back(e);
    for (const Entity e : r.view<const SpotLight>().entities())
        if (!r.has<LightStandIn>(e)) spots.push_back(e);
    std::vector<float> intensity;
    for (const Entity e : points)
        intensity.push_back(r.get<PointLight>(e).intensity);
    for (const Entity e : spots)
        intensity.push_back(r.get<SpotLight>(e).intensity);
    std::uint64_t lampPhotons = 0;
    for (const PhotonLight& light : w.store().lights)
        if (r.has<PointLight>(light.entity) || r.has<SpotLight>(light.entity))
            lampPhotons += light.photonCount;
    const std::uint64_t budget = w.system->settings().reshootBudget;
    const std::uint64_t period =
        (lampPhotons + budget - 1) / budget + 1; // sweep, and a still frame
    const auto switchLamps = [&](bool on) {
        std::size_t i = 0;
        for (const Entity e : points)
            r.patch<PointLight>(e).intensity = on ? intensity[i++] : 0.f;
        for (const Entity e : spots)
            r.patch<SpotLight>(e).intensity = on ? intensity[i++] : 0.f;
    };

    double worst = 0, reshot = 0, fullShots = 0;
    std::uint64_t frames = 0;
    bool off = false;
    for (auto _ : state) {
        if (frames++ % period == 0) switchLamps(!(off = !off));
        const double ms = w.still();
        worst = std::max(worst, ms);
        reshot += double(w.system->lastFrame().reshotPaths);
        fullShots += w.system->lastFrame().full ? 1 : 0;
        state.SetIterationTime(ms / 1000.0);
    }
    state.counters["lamp_photons"] = double(lampPhotons);
    state.counters["frames_per_switch"] = double(period - 1);
    state.counters["reshot/frame"] = reshot / double(frames);
    state.counters["worst_frame_ms"] = worst;
    state.counters["full_shots"] = fullShots;
    // Lamps back on, and their photons with them, for the next benchmark on this world.
    if (off) switchLamps(true);
    for (std::uint64_t i = 0; i < period; ++i)
        w.still();
}

/// Frames of a light's photons being re-shot, until a frame re-shoots none.
struct Sweep {
    double total = 0, worst = 0;
    std::size_t frames = 0, fullShots = 0, gridRebuilds = 0;
};

Sweep sweepFrames(PhotonWorld& w) {
    Sweep s;
    do {
        const double ms = w.still();
        s.total += ms;
        s.worst = std::max(s.worst, ms);
        ++s.frames;
        s.fullShots += w.system->lastFrame().full ? 1 : 0;
        s.gridRebuilds += w.system->lastFrame().reindexedPaths >= w.store().pathCount() ? 1 : 0;
    } while (w.system->lastFrame().reshotPaths > 0 && s.frames < 10'000);
    return s;
}

/// Counters for two sweeps (`on`: the change, `off`: back); fails the benchmark on a full shot.
void reportSweeps(benchmark::State& state, const Sweep& on, const Sweep& off) {
    state.counters["on_frames"] = double(on.frames);
    state.counters["on_frame_ms"] = on.total / double(on.frames);
    state.counters["on_worst_ms"] = on.worst;
    state.counters["off_frames"] = double(off.frames);
    state.counters["off_frame_ms"] = off.total / double(off.frames);
    state.counters["off_worst_ms"] = off.worst;
    state.counters["grid_rebuilds"] = double(on.gridRebuilds + off.gridRebuilds);
    if (on.fullShots + off.fullShots > 0) state.SkipWithError("a frame was a full shot");
}

/// One run (Iterations(1)): still frames for a baseline, then a point light added at the
/// scene's centre with a quarter of the lights' power, frames until its photons are all shot
/// (`on`), then the light destroyed, frames until they are all empty (`off`).
void BM_LightAdded(benchmark::State& state, const std::string& name) {
    PhotonWorld& w = world(name);
    Registry& r = w.registry;
    constexpr int kStillFrames = 10;
    const glm::vec3 power = w.store().emittedPower;
    const float intensity = 0.25f * (power.x + power.y + power.z) / (3.f * 4.f * glm::pi<float>());
    const glm::vec3 centre = r.ctx().get<SceneInfo>().bounds.center();
    double still = 0, added = 0;
    Sweep on, off;
    for (auto _ : state) {
        for (int i = 0; i < kStillFrames; ++i)
            still += w.still();
        const Entity lamp = r.create();
        r.emplace<WorldTransform>(lamp, WorldTransform{glm::translate(glm::mat4(1.f), centre)});
        r.emplace<PointLight>(lamp, PointLight{glm::vec3(1.f), intensity});
        const double before = double(w.store().pathCount());
        on = sweepFrames(w);
        added = double(w.store().pathCount()) - before;
        r.destroy(lamp);
        off = sweepFrames(w);
        state.SetIterationTime((on.total + off.total) / 1000.0);
    }
    state.counters["appended_photons"] = added;
    state.counters["still_frame_ms"] = still / kStillFrames;
    reportSweeps(state, on, off);
}

/// One run (Iterations(1)): the first lamp (not a stand-in) a hundred times brighter, far
/// past its photon share, so it is dealt new photons (`on`); then back (`off`), dealt anew
/// again. Frames until each sweep ends.
void BM_LampRedealt(benchmark::State& state, const std::string& name) {
    PhotonWorld& w = world(name);
    Registry& r = w.registry;
    Entity lamp;
    for (const Entity e : r.view<const PointLight>().entities())
        if (lamp.isNull() && !r.has<LightStandIn>(e)) lamp = e;
    if (lamp.isNull()) {
        state.SkipWithError("no lamp");
        return;
    }
    const float intensity = r.get<PointLight>(lamp).intensity;
    double ghosts = 0, before = 0, brightened = 0;
    Sweep on, off;
    for (auto _ : state) {
        before = double(w.store().lights.size());
        r.patch<PointLight>(lamp).intensity = 100.f * intensity;
        on = sweepFrames(w);
        for (const PhotonLight& light : w.store().lights)
            if (light.entity == lamp) brightened = double(light.photonCount);
        r.patch<PointLight>(lamp).intensity = intensity;
        off = sweepFrames(w);
        ghosts = double(w.store().lights.size()) - before;
        state.SetIterationTime((on.total + off.total) / 1000.0);
    }
    state.counters["lamp_photons_brightened"] = brightened;
    state.counters["ghosts"] = ghosts;
    state.counters["paths"] = double(w.store().pathCount());
    reportSweeps(state, on, off);
}

/// Frames of the mobiles moving 1 cm each, turning back after `turn` cm, with each stage's
/// time and counts as counters.
void moveMobiles(benchmark::State& state, PhotonWorld& w, int turn = 5) {
    double retraced = 0, landed = 0, retested = 0, candidates = 0, segments = 0, find = 0,
           trace = 0, grid = 0, detp = 0, detpDelta = 0, detpMobile = 0, mobilePaths = 0,
           mobileSegments = 0, crossings = 0, deltaSegments = 0, nearSegments = 0,
           mobilesWalked = 0, nearPathsWalked = 0;
    for (auto _ : state) {
        detp += w.step(false, turn);
        const PhotonUpdateSystem::FrameStats& stats = w.system->lastFrame();
        retraced += double(stats.retracedPaths);
        landed += double(stats.landedPaths);
        retested += double(stats.retestedSegments);
        candidates += double(stats.candidatePaths);
        nearPathsWalked += double(stats.nearPathsWalked);
        segments += double(stats.tracedSegments);
        find += stats.findMs;
        trace += stats.traceMs;
        grid += stats.gridMs;
        detpDelta += w.irradiance->lastFrame().deltaMs;
        detpMobile += w.irradiance->lastFrame().mobileMs;
        mobilePaths += double(w.irradiance->lastFrame().candidatePaths);
        mobileSegments += double(w.irradiance->lastFrame().candidateSegments);
        nearSegments += double(w.irradiance->lastFrame().nearSegments);
        mobilesWalked += double(w.irradiance->lastFrame().mobilesWalked);
        crossings += double(w.irradiance->lastFrame().crossings);
        deltaSegments += double(w.irradiance->lastFrame().deltaSegments);
    }
    reportFrames(state, w, retraced, candidates, segments);
    const double frames = double(state.iterations());
    state.counters["landed/frame"] = landed / frames;
    state.counters["retested/frame"] = retested / frames;
    state.counters["find_ms"] = find / frames;
    state.counters["trace_ms"] = trace / frames;
    state.counters["grid_ms"] = grid / frames;
    state.counters["detp_ms"] = detp / frames;
    state.counters["detp_delta_ms"] = detpDelta / frames;
    state.counters["detp_mobiles_ms"] = detpMobile / frames;
    state.counters["detp_mobile_paths"] = mobilePaths / frames;
    state.counters["detp_mobile_segments"] = mobileSegments / frames;
    state.counters["detp_near_segments"] = nearSegments / frames;
    state.counters["near_paths_walked/frame"] = nearPathsWalked / frames;
    state.counters["detp_mobiles_walked"] = mobilesWalked / frames;
    state.counters["detp_crossings"] = crossings / frames;
    state.counters["detp_delta_segments"] = deltaSegments / frames;
}

/// Argument: the path grid's resolution (0: the default).
void BM_MobileUpdate(benchmark::State& state, const std::string& name, bool fullRecompute) {
    moveMobiles(state, world(name, fullRecompute, std::uint32_t(state.range(0))));
}

/// The same frames, the mobiles travelling 20 cm before they turn: each leaves the copy of
/// the segments near it now and then (NearSegments), which a 5 cm sway never does.
void BM_MobileTravel(benchmark::State& state, const std::string& name) {
    moveMobiles(state, world(name), 20);
}

/// Argument: the photon count, the path grid at its default resolution.
void BM_PhotonBudget(benchmark::State& state, const std::string& name, bool fullRecompute) {
    moveMobiles(state, world(name, fullRecompute, 0, std::uint32_t(state.range(0))));
}

} // namespace
} // namespace qgi

int main(int argc, char** argv) {
    using namespace qgi;
    using benchmark::RegisterBenchmark;
    setLogLevel(LogLevel::Warning);
    for (const std::string scene : {"cornell", "atrium"}) {
        const auto id = [&](const char* what) { return std::string(what) + "/" + scene; };
        RegisterBenchmark(id("TracePaths").c_str(), BM_TracePaths, scene)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark(id("RawPhotonRays").c_str(), BM_RawPhotonRays, scene)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark(id("RawRandomRays").c_str(), BM_RawRandomRays, scene)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        // Argument: the path grid's resolution (0: the default); MobileUpdate/<scene>/<r>
        // sweeps it (memory against candidates and time).
        RegisterBenchmark(id("MobileUpdate").c_str(), BM_MobileUpdate, scene, false)
            ->Arg(0)
            ->Arg(16)
            ->Arg(32)
            ->Arg(48)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark(id("MobileTravel").c_str(), BM_MobileTravel, scene)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark((id("AlbedoEdit") + "/mobile").c_str(), BM_AlbedoEdit, scene, "")
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark((id("AlbedoEdit") + "/floor").c_str(), BM_AlbedoEdit, scene,
                          std::string(scene == "cornell" ? "floor" : "court floor"))
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark(id("FullShot").c_str(), BM_FullShot, scene)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark(id("GridBuild").c_str(), BM_GridBuild, scene)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        // Every mobile taken out of the world and put back on alternate frames.
        RegisterBenchmark(id("MobileToggle").c_str(), BM_MobileToggle, scene)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        RegisterBenchmark(id("FullReshoot").c_str(), BM_MobileUpdate, scene, true)
            ->Arg(0)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
        // The frame of MobileUpdate and FullReshoot at fewer photons: what fits a frame budget.
        if (scene == "cornell")
            for (const bool full : {false, true})
                RegisterBenchmark(id(full ? "FullReshootPhotons" : "MobileUpdatePhotons").c_str(),
                                  BM_PhotonBudget, scene, full)
                    ->Arg(125'000)
                    ->Arg(250'000)
                    ->Arg(500'000)
                    ->UseRealTime()
                    ->Unit(benchmark::kMillisecond);
        // The atrium's lamps switched off and on (the cornell box has none that shoot photons:
        // its luminaire is an emissive surface).
        if (scene == "atrium") {
            RegisterBenchmark(id("LampSwitch").c_str(), BM_LampSwitch, scene)
                ->UseManualTime()
                ->Unit(benchmark::kMillisecond);
            RegisterBenchmark(id("LampRedealt").c_str(), BM_LampRedealt, scene)
                ->Iterations(1)
                ->UseManualTime()
                ->Unit(benchmark::kMillisecond);
            RegisterBenchmark(id("LightAdded").c_str(), BM_LightAdded, scene)
                ->Iterations(1)
                ->UseManualTime()
                ->Unit(benchmark::kMillisecond);
        }
    }
    // Cornell's frame in hybrid mode, against its full recompute.
    for (const bool full : {false, true})
        RegisterBenchmark(full ? "FullReshoot/cornell-hybrid" : "MobileUpdate/cornell-hybrid",
                          BM_MobileUpdate, std::string("cornell-hybrid"), full)
            ->Arg(0)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
    // The ray set grows eightfold, the paths the moving cube can touch stay (buildTwoRooms).
    for (const bool full : {false, true})
        RegisterBenchmark(
            (std::string(full ? "FullReshootPhotons/" : "MobileUpdatePhotons/") + kTwoRooms)
                .c_str(),
            BM_PhotonBudget, kTwoRooms, full)
            ->Arg(500'000)
            ->Arg(1'000'000)
            ->Arg(2'000'000)
            ->Arg(4'000'000)
            ->UseRealTime()
            ->Unit(benchmark::kMillisecond);
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
