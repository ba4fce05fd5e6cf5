#include "systems/render/RenderSystem.h"

#include "components/Avatar.h"
#include "components/Camera.h"
#include "components/DirectionalLight.h"
#include "components/Material.h"
#include "components/Mesh.h"
#include "components/MobileMesh.h"
#include "components/Name.h"
#include "components/PointCacheShaded.h"
#include "components/PointLight.h"
#include "components/ShLighting.h"
#include "components/SpotLight.h"
#include "components/VertexIrradiance.h"
#include "components/WorldTransform.h"
#include "runtime/core/Log.h"
#include "runtime/io/Exr.h"
#include "runtime/io/Png.h"
#include "runtime/math/Pose.h"
#include "runtime/profile/FrameProfiler.h"
#include "runtime/render/GpuTexture.h"
#include "runtime/scene/SceneQueries.h"
#include "runtime/scene/TextureLibrary.h"
#include "systems/point_cache/PointCache.h"
#include "systems/render/GpuResources.h"
#include "systems/vlf/VlfField.h"

#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <cmath>

namespace qgi {
namespace {

std::string describe(const Registry& registry, Entity e) {
    const Name* name = registry.tryGet<Name>(e);
    return str("entity ", e.index, ":", e.generation, name ? " '" + name->value + "'" : "");
}

/// Why a mesh cannot be drawn, or empty when it can.
std::string meshProblem(const Mesh& mesh) {
    const std::size_t n = mesh.positions.size();
    if (n == 0 || mesh.indices.empty()) return "no triangles";
    if (mesh.normals.size() != n) return str(mesh.normals.size(), " normals for ", n, " positions");
    if (!mesh.uvs.empty() && mesh.uvs.size() != n)
        return str(mesh.uvs.size(), " uvs for ", n, " positions");
    if (mesh.indices.size() % 3 != 0) return str(mesh.indices.size(), " indices (not triangles)");
    for (const std::uint32_t index : mesh.indices)
        if (index >= n) return str("index ", index, " >= ", n, " positions");
    return {};
}

glm::vec3 worldCenter(const DrawItem& item) {
    return glm::vec3(item.model * glm::vec4(item.mesh->bounds.center(), 1.f));
}

} // namespace

RenderSystem::RenderSystem(const RenderSettings& settings) : mRenderer(settings) {}

void RenderSystem::update(Registry& registry, const FrameContext& frame) {
    GpuResources* gpu = registry.ctx().find<GpuResources>();
    if (!gpu) gpu = &registry.ctx().emplace<GpuResources>();

    RenderScene scene;
    scene.vlf = vlfTables(registry);
    if (syncPointCache(registry)) scene.pointCache = &mPointCacheView;
    syncMeshes(registry, *gpu, scene);
    collectLights(registry);
    scene.lights = mLights;
    if (findCamera(registry, scene.camera)) {
        sortFrontToBack(scene.camera.position);
        scene.items = mItems;
    } else if (!mWarnedNoCamera) {
        logWarning("no camera with a usable pose (Camera and a WorldTransform of non-zero scale): "
                   "the frame stays black");
        mWarnedNoCamera = true;
    }
    mRenderer.render(scene, registry.ctx().find<FrameProfiler>(), frame.frameIndex);

    if (mScreenshot) {
        writeScreenshot(*mScreenshot);
        mScreenshot.reset();
    }
}

void RenderSystem::syncMeshes(Registry& registry, GpuResources& gpu, RenderScene& scene) {
    // Free what no longer has a mesh to draw. Whether it was movable is gone with it: count
    // it as a static change.
    mStale.clear();
    for (const auto& [entity, mesh] : gpu.meshes)
        if (!registry.alive(entity) || !registry.has<Mesh>(entity) ||
            !registry.has<WorldTransform>(entity))
            mStale.push_back(entity);
    for (const Entity e : mStale)
        gpu.meshes.erase(e);
    scene.staticCastersChanged = !mStale.empty();
    scene.movableCastersChanged = false;

    mItems.clear();
    registry.view<const Mesh, const WorldTransform>().each([&](Entity e, const Mesh& mesh,
                                                               const WorldTransform& world) {
        const auto [slot, created] = gpu.meshes.try_emplace(e);
        GpuMesh& gpuMesh = slot->second;
        VertexIrradiance* irradiance = registry.tryGet<VertexIrradiance>(e);
        const bool movable = registry.has<MobileMesh>(e) || registry.has<Avatar>(e);
        bool& casterChanged = movable ? scene.movableCastersChanged : scene.staticCastersChanged;
        if (created || registry.wasChanged<Mesh>(e)) {
            casterChanged = true;
            if (const std::string problem = meshProblem(mesh); !problem.empty()) {
                logWarning(describe(registry, e), ": mesh not drawn: ", problem);
                gpuMesh = GpuMesh{};
                return;
            }
            gpuMesh = createGpuMesh(mesh);
            if (irradiance)
                irradiance->dirty.push_back({0, std::uint32_t(irradiance->irradiance.size())});
        }
        if (!gpuMesh.vertexArray) return; // rejected until its Mesh changes
        // Out of the world for now (MobileMesh::active): not drawn, casts no shadow; its GPU
        // mesh stays for later and takes its irradiance uploads meanwhile.
        const bool drawn = !outOfWorld(registry, e);
        if (registry.wasChanged<WorldTransform>(e) || drawn != gpuMesh.drawn) casterChanged = true;
        if (isUsablePose(world.matrix)) {
            gpuMesh.pose = world.matrix;
            gpuMesh.posed = true;
        }
        gpuMesh.drawn = drawn && gpuMesh.posed;
        if (!gpuMesh.drawn) {
            if (irradiance && !irradiance->dirty.empty())
                uploadIrradiance(gpuMesh, irradiance->irradiance, irradiance->dirty);
            return;
        }

        DrawItem& item = mItems.emplace_back();
        item.mesh = &gpuMesh;
        item.model = gpuMesh.pose;
        item.movable = movable;
        const Material* material = registry.tryGet<Material>(e);
        const Material m = material ? *material : Material{};
        item.albedo = m.baseColor;
        item.emission = m.emission;
        item.baseColorTexture = baseColorTexture(registry, gpu, m.baseColorTexture);
        if (irradiance && !irradiance->dirty.empty())
            uploadIrradiance(gpuMesh, irradiance->irradiance, irradiance->dirty);
        if (scene.vlf) {
            const VlfField& field = registry.ctx().get<VlfField>();
            if (const auto it = field.specularFaces.find(e); it != field.specularFaces.end()) {
                // An entity's faces are consecutive among the specular faces.
                item.vlfFirstFace = field.vlf.specularIndex(it->second.front());
                item.vlfFaceCount = std::int32_t(it->second.size());
                // The VLF's k_d, which a metal's k_s leaves over (VlfScene::fromComponent):
                // baseColor alone would reflect more than the surface receives.
                item.albedo = field.vlf.faces()[it->second.front()].diffuse;
            }
        }
        if (registry.has<Avatar>(e)) {
            item.lighting = SurfaceLighting::SphericalHarmonics;
            const ShLighting* sh = registry.tryGet<ShLighting>(e);
            item.sh = sh ? sh->coefficients : std::array<glm::vec3, 9>{};
        } else if (irradiance) {
            item.lighting = scene.pointCache && registry.has<PointCacheShaded>(e)
                                ? SurfaceLighting::PointCache
                                : SurfaceLighting::VertexIrradiance;
        }
    });
}

const VlfGpuTables* RenderSystem::vlfTables(const Registry& registry) {
    const VlfField* field = registry.ctx().find<VlfField>();
    if (!field) return nullptr;
    if (field == mVlfSource && field->vlf.key() == mVlfKey) return &mVlf;
    const vlf::Vlf& v = field->vlf;
    const vlf::DirectionSet& dirs = v.directions();
    VlfGpuTables t;
    t.version = mVlf.version + 1;
    t.level = dirs.level();
    t.linesPerSide = v.linesPerSide();
    t.tileSize = v.tileSize();
    t.directionCount = int(dirs.size());
    t.center = v.center();
    t.radius = v.radius();
    for (const glm::vec3& d : dirs.directions())
        t.directions.emplace_back(d, 0.f);
    for (std::uint32_t i = 0; i < dirs.triangleCount(); ++i) {
        glm::ivec4 code(0);
        for (int k = 0; k < 3; ++k)
            code[k] = int(dirs.triangle(i)[k].index) * 2 + (dirs.triangle(i)[k].sign < 0.f ? 1 : 0);
        t.triangles.push_back(code);
    }
    for (std::size_t sf = 0; sf < v.specularFaceCount(); ++sf) {
        const vlf::Face& f = v.faces()[v.specularFace(sf)];
        t.faces.emplace_back(f.normal, f.offset);
        t.faces.emplace_back(f.specular, f.isMirror() ? 1.f : 0.f);
    }
    for (const vlf::TileBlock& b : v.blocks()) {
        t.blocks.emplace_back(b.side, b.s0, b.t0, b.sw);
        t.blocks.emplace_back(b.tw, std::int32_t(b.firstSlot), 0, 0);
    }
    t.slots = v.slots();
    t.cells = v.cells();
    t.cellScale = v.cellScale();
    mVlf = std::move(t);
    mVlfSource = field;
    mVlfKey = v.key();
    return &mVlf;
}

bool RenderSystem::syncPointCache(const Registry& registry) {
    const PointCache* cache = registry.ctx().find<PointCache>();
    if (!cache || cache->size() == 0 || cache->grid.pointCount() != cache->size()) return false;
    const bool newSet = mCacheSet != cache->pointSetVersion || !mCachePoints;
    if (newSet) {
        // The grid and the point geometry: once per point set.
        mCachePoints = createBuffer();
        mCacheCellStart = createBuffer();
        mCacheCellPoints = createBuffer();
        const auto starts = cache->grid.cellStart();
        const auto entries = cache->grid.cellPoints();
        glNamedBufferStorage(mCacheCellStart.id(), GLsizeiptr(starts.size_bytes()), starts.data(),
                             0);
        const std::uint32_t none = 0;
        glNamedBufferStorage(mCacheCellPoints.id(),
                             GLsizeiptr(entries.empty() ? sizeof none : entries.size_bytes()),
                             entries.empty() ? &none : entries.data(), 0);
        glNamedBufferStorage(mCachePoints.id(), GLsizeiptr(cache->size() * 3 * sizeof(glm::vec4)),
                             nullptr, GL_DYNAMIC_STORAGE_BIT);
        const PointGrid& grid = cache->grid;
        mPointCacheView.grid = glm::vec4(grid.origin(), grid.cellSize());
        mPointCacheView.dims = glm::ivec4(grid.dims(), int(cache->settings.falloffExponent));
        mPointCacheView.minNormalCosine = grid.params().minNormalCosine;
        mPointCacheView.planeTolerance = grid.params().planeTolerance;
        mPointCacheView.points = mCachePoints.id();
        mPointCacheView.cellStart = mCacheCellStart.id();
        mPointCacheView.cellPoints = mCacheCellPoints.id();
        mCacheSet = cache->pointSetVersion;
    }
    if (newSet || mCacheVersion != cache->shadingVersion) {
        mCacheStaging.resize(cache->size() * 3);
        for (std::size_t p = 0; p < cache->size(); ++p) {
            mCacheStaging[3 * p] =
                glm::vec4(cache->position[p], cache->searchRadius(std::uint32_t(p)));
            mCacheStaging[3 * p + 1] = glm::vec4(cache->normal[p], cache->ao[p]);
            mCacheStaging[3 * p + 2] =
                glm::vec4(cache->direct[p] + cache->indirect[p], cache->radius[p]);
        }
        glNamedBufferSubData(mCachePoints.id(), 0,
                             GLsizeiptr(mCacheStaging.size() * sizeof(glm::vec4)),
                             mCacheStaging.data());
        mCacheVersion = cache->shadingVersion;
    }
    return true;
}

void RenderSystem::sortFrontToBack(const glm::vec3& eye) {
    // Nearer meshes first: the depth test then rejects hidden fragments before shading them,
    // which is most of the scene pass on a software rasterizer.
    std::sort(mItems.begin(), mItems.end(), [&](const DrawItem& a, const DrawItem& b) {
        const glm::vec3 da = worldCenter(a) - eye, db = worldCenter(b) - eye;
        return glm::dot(da, da) < glm::dot(db, db);
    });
}

GLuint RenderSystem::baseColorTexture(const Registry& registry, GpuResources& gpu, int index) {
    if (index < 0) return 0;
    const TextureLibrary* library = registry.ctx().find<TextureLibrary>();
    const Image* image =
        library && std::size_t(index) < library->images.size() ? &library->images[index] : nullptr;
    const bool valid = image && image->width > 0 && image->height > 0 &&
                       image->rgba.size() == std::size_t(image->width) * image->height * 4;
    if (!valid) {
        if (!mWarnedTexture)
            logWarning("base colour texture ", index, " is missing or malformed: drawn without");
        mWarnedTexture = true;
        return 0;
    }
    if (gpu.textures.size() <= std::size_t(index)) gpu.textures.resize(std::size_t(index) + 1);
    GlTexture& texture = gpu.textures[std::size_t(index)];
    if (!texture)
        texture = createColorTexture(image->width, image->height, image->rgba, image->srgb);
    return texture.id();
}

void RenderSystem::collectLights(const Registry& registry) {
    mLights.clear();
    registry.view<const PointLight, const WorldTransform>().each(
        [&](const PointLight& light, const WorldTransform& world) {
            RenderLight& out = mLights.emplace_back();
            out.type = LightType::Point;
            out.position = glm::vec3(world.matrix[3]);
            out.radiance = light.color * light.intensity;
        });
    registry.view<const SpotLight, const WorldTransform>().each(
        [&](const SpotLight& light, const WorldTransform& world) {
            RenderLight& out = mLights.emplace_back();
            out.type = LightType::Spot;
            out.position = glm::vec3(world.matrix[3]);
            out.direction = lightForward(world.matrix);
            out.radiance = light.color * light.intensity;
            out.innerConeAngle = light.innerConeAngle;
            out.outerConeAngle = light.outerConeAngle;
        });
    registry.view<const DirectionalLight, const WorldTransform>().each(
        [&](const DirectionalLight& light, const WorldTransform& world) {
            RenderLight& out = mLights.emplace_back();
            out.type = LightType::Directional;
            out.direction = lightForward(world.matrix);
            out.radiance = light.color * light.irradiance;
        });
    // Dark, as in every lighting system (runtime/math/Pose.h): too bright for float lighting,
    // a point or spot placed past kMaxPoseReach, a spot or sun with no axis to shine along.
    std::erase_if(mLights, [](const RenderLight& l) {
        return !isUsableLightRadiance(l.radiance) ||
               (l.type != LightType::Directional && !isUsableLightPosition(l.position)) ||
               (l.type != LightType::Point && l.direction == glm::vec3(0.f));
    });
}

bool RenderSystem::findCamera(const Registry& registry, RenderCamera& camera) {
    const Entity entity = findActiveCamera(registry);
    const Camera* chosen = registry.tryGet<Camera>(entity);
    const WorldTransform* chosenWorld = registry.tryGet<WorldTransform>(entity);
    if (!chosen || !chosenWorld) return false;
    const float aspect = float(settings().width) / float(settings().height);
    if (isUsablePose(chosenWorld->matrix)) mCameraPose = chosenWorld->matrix;
    if (!mCameraPose) return false;
    // A camera sees along its pose; a scale on its node would only distort the view.
    glm::mat4 pose = *mCameraPose;
    for (int c = 0; c < 3; ++c) {
        const float length = glm::length(glm::vec3(pose[c]));
        if (!(length > 1e-20f) || !std::isfinite(length)) return false;
        pose[c] /= length;
    }
    // A mirror on its node (scale -1 along an axis) would turn every triangle's winding, and
    // culling would leave the frame black: it sees along -Z with +Y up all the same.
    if (glm::determinant(glm::mat3(pose)) < 0.f) pose[0] = -pose[0];
    camera.view = glm::inverse(pose);
    camera.projection = std::isfinite(chosen->zfar)
                            ? glm::perspective(chosen->yfov, aspect, chosen->znear, chosen->zfar)
                            : glm::infinitePerspective(chosen->yfov, aspect, chosen->znear);
    camera.position = glm::vec3(pose[3]);
    return true;
}

void RenderSystem::requestScreenshot(const std::filesystem::path& base) {
    const std::filesystem::path folder = base.parent_path();
    if (!folder.empty() && !std::filesystem::is_directory(folder))
        fail("screenshot folder '", folder.string(), "' does not exist");
    mScreenshot = base;
}

void RenderSystem::writeScreenshot(const std::filesystem::path& base) {
    std::filesystem::path exr = base, png = base;
    exr += ".exr";
    png += ".png";
    mLastScreenshot = ScreenshotOutcome{base, {}};
    try {
        writeExr(exr, readHdr());
        writePng(png, readLdr());
        logInfo("wrote ", exr.string(), " and ", png.string());
    } catch (const Error& e) {
        mLastScreenshot->error = e.what();
        logError("screenshot not written: ", e.what());
    }
}

} // namespace qgi
