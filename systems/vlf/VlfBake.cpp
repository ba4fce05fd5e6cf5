#include "systems/vlf/VlfBake.h"

#include "runtime/core/Error.h"
#include "runtime/core/Hash.h"
#include "runtime/core/Log.h"

#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <random>

namespace qgi::vlf {
namespace {

constexpr float kInvPi = 0.31830988618f;

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::uint32_t seedFor(std::uint64_t seed, std::uint64_t a, std::uint64_t b) {
    Fnv1aHasher h;
    h.add(seed);
    h.add(a);
    h.add(b);
    const std::uint64_t v = h.value();
    return std::uint32_t(v ^ (v >> 32));
}

/// Per-chunk accumulators of one pass.
struct ChunkAccum {
    std::vector<glm::vec3> irradiance; // W/m^2 received
    VlfIterationStats stats;
    std::size_t lines = 0, crossings = 0, truncated = 0;
};

class Baker {
public:
    Baker(const VlfScene& scene, const VlfSettings& settings)
        : mScene(scene), mSettings(settings), mVlf(Vlf::allocate(scene, settings)),
          mDirs(mVlf.directions()) {
        const std::size_t cells = mVlf.cellCount();
        mTiles.assign(cells, glm::vec4(0.f));
        const std::size_t texels = mVlf.irradiance().size();
        mUnshotE.assign(texels, glm::vec3(0.f));
        mUnshotL.assign(cells, glm::vec3(0.f));
        mIncident.assign(cells, glm::vec4(0.f));
        mIncidentAvg.assign(cells, glm::vec4(0.f));
        mNextL.assign(cells, glm::vec3(0.f));
        buildLobes();
    }

    Vlf run(VlfBakeStats* stats) {
        const auto t0 = Clock::now();
        VlfBakeStats local;
        const auto td = Clock::now();
        directPass();
        local.directSeconds = since(td);
        for (int k = 1; k <= mSettings.iterations; ++k) {
            const auto ti = Clock::now();
            VlfIterationStats it = transportPass(k, local);
            const auto tg = Clock::now();
            gatherSpecular();
            it.gatherSeconds = since(tg);
            finishPass(it);
            it.seconds = since(ti);
            if (mSettings.progress)
                logInfo("VLF bake: iteration ", k, "/", mSettings.iterations, " done in ",
                        it.seconds, " s");
            local.iterations.push_back(it);
        }
        local.seconds = since(t0);
        if (local.truncatedLines > 0)
            logWarning("VLF bake: ", local.truncatedLines, " of ", local.lines,
                       " lines crossed the scene's faces more than ", kMaxLineCrossings,
                       " times; light beyond those crossings is missing from the field");
        if (stats) *stats = local;
        mVlf.storeCells(mTiles);
        return std::move(mVlf);
    }

private:
    // ---- geometry helpers --------------------------------------------------------------------
    /// World point where the centre line of cell (i, j) of subfield psf meets the face plane.
    glm::vec3 cellPoint(const Face& f, std::size_t psf, int i, int j) const {
        const float h = mVlf.cellWidth();
        const glm::vec2 uv(-1.f + (float(i) + 0.5f) * h, -1.f + (float(j) + 0.5f) * h);
        const glm::vec3 p = mVlf.linePoint(psf, uv);
        const glm::vec3& d = mDirs.direction(psf);
        const float t = (f.offset - glm::dot(f.normal, p)) / glm::dot(f.normal, d);
        return p + t * d;
    }

    /// Nearest cell of x in subfield psf for specular face sf, or -1.
    std::int64_t nearestCell(std::size_t sf, std::size_t psf, const glm::vec3& x) const {
        const glm::vec2 c = (mVlf.project(psf, x) + 1.f) / mVlf.cellWidth();
        return mVlf.cellIndex(sf, psf, int(std::floor(c.x)), int(std::floor(c.y)));
    }

    /// Covered texel for a deposit at x on face f, or UINT32_MAX.
    std::uint32_t depositTexel(std::uint32_t face, const glm::vec3& x) const {
        const std::uint32_t t = mVlf.texelAt(face, x);
        const std::vector<float>& cov = mVlf.texelCoverage();
        if (cov[t] > 0.f) return t;
        const FaceMap& m = mVlf.faceMaps()[face];
        const int tx = int((t - m.firstTexel) % m.width), ty = int((t - m.firstTexel) / m.width);
        std::uint32_t best = UINT32_MAX;
        float bestCov = 0.f;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const int x2 = tx + dx, y2 = ty + dy;
                if (x2 < 0 || y2 < 0 || x2 >= int(m.width) || y2 >= int(m.height)) continue;
                const std::uint32_t u =
                    m.firstTexel + std::uint32_t(y2) * m.width + std::uint32_t(x2);
                if (cov[u] > bestCov) {
                    bestCov = cov[u];
                    best = u;
                }
            }
        return best;
    }

    // ---- glossy lobes ------------------------------------------------------------------------
    /// For each glossy face and outgoing subfield j: (incident subfield i, weight) with
    /// weight = (n_s + 2) / (2 pi) cos^n_s(alpha) * cos(theta_i) * dOmega_i, columns scaled so
    /// that no incident direction reflects more than it receives (discrete Eq 2.21).
    void buildLobes() {
        const std::size_t l = mDirs.size();
        mLobes.assign(mVlf.specularFaceCount() * l, {});
        tbb::parallel_for(std::size_t(0), mVlf.specularFaceCount(), [&](std::size_t sf) {
            const Face& f = mVlf.faces()[mVlf.specularFace(sf)];
            if (f.isMirror()) return;
            const float ns = f.phongExponent;
            std::vector<float> w(l * l, 0.f);
            std::vector<double> albedo(l, 0.0);
            for (std::size_t j = 0; j < l; ++j) {
                const TileBlock& bj = mVlf.block(sf, j);
                if (bj.side == 0) continue;
                const glm::vec3 o = float(bj.side) * mDirs.direction(j);
                const float cosO = glm::dot(f.normal, o);
                for (std::size_t i = 0; i < l; ++i) {
                    const TileBlock& bi = mVlf.block(sf, i);
                    if (bi.side == 0) continue;
                    const glm::vec3 from = float(bi.side) * mDirs.direction(i);
                    const float cosI = glm::dot(f.normal, from);
                    const glm::vec3 mirrored = 2.f * cosI * f.normal - from;
                    const float ca = glm::dot(mirrored, o);
                    if (ca <= 0.f) continue;
                    const float value = (ns + 2.f) / (2.f * glm::pi<float>()) * std::pow(ca, ns) *
                                        cosI * mDirs.cellSolidAngle(i);
                    w[j * l + i] = value;
                    albedo[i] += double(value) / double(cosI * mDirs.cellSolidAngle(i)) * cosO *
                                 mDirs.cellSolidAngle(j);
                }
            }
            for (std::size_t j = 0; j < l; ++j) {
                float peak = 0.f;
                for (std::size_t i = 0; i < l; ++i) {
                    if (albedo[i] > 1.0) w[j * l + i] = float(w[j * l + i] / albedo[i]);
                    peak = std::max(peak, w[j * l + i]);
                }
                auto& lobe = mLobes[sf * l + j];
                double all = 0.0, kept = 0.0;
                for (std::size_t i = 0; i < l; ++i) {
                    all += w[j * l + i];
                    if (w[j * l + i] > 0.f && w[j * l + i] >= mSettings.glossyCutoff * peak) {
                        lobe.push_back({std::uint32_t(i), w[j * l + i]});
                        kept += w[j * l + i];
                    }
                }
                // The dropped tail's weight goes to the kept part: the lobe keeps its albedo.
                if (kept > 0.0)
                    for (auto& entry : lobe)
                        entry.second = float(entry.second * (all / kept));
            }
        });
    }

    /// Phong reflection towards `o` of light arriving from unit `from` with irradiance E.
    static glm::vec3 phong(const Face& f, const glm::vec3& from, const glm::vec3& o,
                           const glm::vec3& E) {
        const float cosI = glm::dot(f.normal, from);
        const float ca = glm::dot(2.f * cosI * f.normal - from, o);
        if (ca <= 0.f) return glm::vec3(0.f);
        const float ns = f.phongExponent;
        return f.specular * ((ns + 2.f) / (2.f * glm::pi<float>()) * std::pow(ca, ns)) * E;
    }

    // ---- the direct pass -----------------------------------------------------------------------
    void directPass() {
        const std::vector<PunctualLight>& lights = mScene.lights();
        if (lights.empty()) return;
        const std::vector<Face>& faces = mVlf.faces();
        const float lift = 1e-4f * mVlf.radius();
        // A directional light's shadow ray runs past every triangle of the scene.
        const float outside = 2.f * glm::length(mScene.bounds().extent()) + 1.f;
        const auto irradianceFrom = [&](const PunctualLight& light, const Face& f,
                                        const glm::vec3& x, glm::vec3& from) -> glm::vec3 {
            if (light.kind == PunctualLight::Kind::Directional) {
                from = -light.axis;
                const float c = glm::dot(f.normal, from);
                if (c <= 0.f) return glm::vec3(0.f);
                if (mScene.occluded(x + lift * f.normal, from, outside)) return glm::vec3(0.f);
                return light.intensity * c;
            }
            const glm::vec3 toLight = light.position - x;
            const float r2 = glm::dot(toLight, toLight);
            if (!(r2 > 0.f)) return glm::vec3(0.f);
            from = toLight / std::sqrt(r2);
            const float c = glm::dot(f.normal, from);
            if (c <= 0.f) return glm::vec3(0.f);
            if (mScene.occluded(x + lift * f.normal, light.position)) return glm::vec3(0.f);
            return light.intensityTowards(-from) * c / r2;
        };
        tbb::parallel_for(std::size_t(0), faces.size(), [&](std::size_t fi) {
            const Face& f = faces[fi];
            const FaceMap& m = mVlf.faceMaps()[fi];
            for (std::uint32_t y = 0; y < m.height; ++y)
                for (std::uint32_t x = 0; x < m.width; ++x) {
                    const std::uint32_t t = m.firstTexel + y * m.width + x;
                    if (mVlf.texelCoverage()[t] <= 0.f) continue;
                    const glm::vec3 p = mVlf.texelCenter(std::uint32_t(fi), x, y);
                    glm::vec3 E(0.f), from;
                    for (const PunctualLight& light : lights)
                        E += irradianceFrom(light, f, p, from);
                    mUnshotE[t] = E;
                    mVlf.irradiance()[t] = E;
                }
        });
        // Glossy cells: the lobe around the light's mirror direction. A mirror's reflection
        // of a punctual light is a delta the tiles cannot hold: it is left out, as the light
        // itself, which has no area, is invisible to the camera.
        const int m = mVlf.tileSize();
        tbb::parallel_for(std::size_t(0), mDirs.size(), [&](std::size_t j) {
            for (std::size_t sf = 0; sf < mVlf.specularFaceCount(); ++sf) {
                const Face& f = faces[mVlf.specularFace(sf)];
                const TileBlock& b = mVlf.block(sf, j);
                if (f.isMirror() || b.side == 0) continue;
                const glm::vec3 o = float(b.side) * mDirs.direction(j);
                forEachCell(b, [&](std::int32_t tile, int i, int jj) {
                    const glm::vec3 x = cellPoint(f, j, i, jj);
                    glm::vec3 L(0.f);
                    for (const PunctualLight& light : lights) {
                        glm::vec3 from;
                        const glm::vec3 E = irradianceFrom(light, f, x, from);
                        if (E != glm::vec3(0.f)) L += phong(f, from, o, E);
                    }
                    const std::size_t c = cellOffset(tile, i, jj, m);
                    mUnshotL[c] = L;
                    mTiles[c] = glm::vec4(L, 1.f);
                });
            }
        });
    }

    template <typename Fn> void forEachCell(const TileBlock& b, Fn&& fn) const {
        const int m = mVlf.tileSize();
        for (int t = 0; t < b.tw; ++t)
            for (int s = 0; s < b.sw; ++s) {
                const std::int32_t tile = mVlf.slots()[b.firstSlot + std::size_t(t) * b.sw + s];
                if (tile < 0) continue;
                for (int v = 0; v < m; ++v)
                    for (int u = 0; u < m; ++u)
                        fn(tile, (b.s0 + s) * m + u, (b.t0 + t) * m + v);
            }
    }

    // ---- transport --------------------------------------------------------------------------
    /// Outgoing radiance of a sender crossing at x travelling along sigma * direction(psf)
    /// (roughly: jittered directions deviate within the cell).
    glm::vec3 sendRadiance(std::uint32_t face, const glm::vec3& x, std::size_t psf, float sigma,
                           int iteration) const {
        const Face& f = mVlf.faces()[face];
        glm::vec3 L = f.diffuse * kInvPi * mUnshotE[mVlf.texelAt(face, x)];
        if (iteration == 1) L += f.emission;
        const std::int32_t sf = mVlf.specularIndex(face);
        if (sf >= 0 && !mUnshotL.empty()) {
            const TileBlock& b = mVlf.block(std::size_t(sf), psf);
            if (float(b.side) == sigma) {
                const std::int64_t c = nearestCell(std::size_t(sf), psf, x);
                if (c >= 0) L += mUnshotL[std::size_t(c)];
            }
        }
        return L;
    }

    void receive(ChunkAccum& acc, std::uint32_t face, const glm::vec3& x, std::size_t psf,
                 float sigma, const glm::vec3& L, float dOmega) {
        const glm::vec3 flux = L * (mVlf.lineArea() * dOmega);
        acc.stats.received += glm::dvec3(flux);
        const std::uint32_t t = depositTexel(face, x);
        if (t == UINT32_MAX) {
            ++acc.stats.lostDeposits;
        } else {
            const FaceMap& m = mVlf.faceMaps()[face];
            acc.irradiance[t] += flux / (m.texelU * m.texelV * mVlf.texelCoverage()[t]);
        }
        const std::int32_t sf = mVlf.specularIndex(face);
        if (sf >= 0) {
            // Light travelling along sigma * d arrives from -sigma * d: the face's tiles there
            // must hold the -sigma orientation.
            const TileBlock& b = mVlf.block(std::size_t(sf), psf);
            if (float(b.side) == -sigma) {
                const std::int64_t c = nearestCell(std::size_t(sf), psf, x);
                if (c >= 0) mIncident[std::size_t(c)] += glm::vec4(L * dOmega, dOmega);
            }
        }
    }

    void transportSubfield(std::size_t psf, int iteration, ChunkAccum& acc) {
        std::mt19937 rng(seedFor(mSettings.seed, std::uint64_t(iteration), psf));
        std::uniform_real_distribution<float> uniform(0.f, 1.f);
        const int N = mVlf.linesPerSide();
        const float h = mVlf.cellWidth();
        const float R = mVlf.radius();
        const int samples = std::max(1, mSettings.jitterSamples);
        std::array<Crossing, kMaxLineCrossings + 1> cross; // one more: a line's cut shows
        const glm::vec3 env = iteration == 1 ? mScene.environment() : glm::vec3(0.f);
        const std::vector<Face>& faces = mVlf.faces();
        for (int sample = 0; sample < samples; ++sample) {
            glm::vec3 d = mDirs.direction(psf);
            float dOmega = mDirs.cellSolidAngle(psf);
            if (mSettings.jitterSamples > 0) {
                const DirectionSample s = mDirs.sampleCell(psf, 1.f, rng);
                d = s.direction;
                dOmega = s.solidAngle / float(samples);
            }
            const SubfieldFrame F = makeSubfieldFrame(d);
            d = F.n;
            // A sample of an equator direction's cell may lie around the reversed direction:
            // the tiles' sides are relative to the stored direction.
            const float orient = glm::dot(d, mDirs.direction(psf)) >= 0.f ? 1.f : -1.f;
            const float lineFlux = mVlf.lineArea() * dOmega;
            for (int j = 0; j < N; ++j)
                for (int i = 0; i < N; ++i) {
                    float ju = 0.5f, jv = 0.5f;
                    if (mSettings.jitterSamples > 0) {
                        ju = uniform(rng);
                        jv = uniform(rng);
                    }
                    const float u = -1.f + (float(i) + ju) * h, v = -1.f + (float(j) + jv) * h;
                    const glm::vec3 origin = mVlf.center() + R * (u * F.u + v * F.v - 1.01f * F.n);
                    std::size_t n = mScene.crossings(origin, d, 2.02f * R, cross.data(),
                                                     cross.size(), 1e-5f * R);
                    // Crossings beyond the kept ones were dropped: the last kept one is no end.
                    const bool truncated = n > kMaxLineCrossings;
                    n = std::min(n, kMaxLineCrossings);
                    acc.truncated += truncated;
                    ++acc.lines;
                    acc.crossings += n;
                    if (n == 0) continue;
                    const auto point = [&](std::size_t k) { return origin + cross[k].t * d; };
                    const auto facing = [&](std::size_t k) {
                        return glm::dot(faces[cross[k].face].normal, d);
                    };
                    // Ends of the line: the environment in, escaping light out.
                    if (facing(0) < 0.f) {
                        if (env != glm::vec3(0.f)) {
                            acc.stats.fromEnvironment += glm::dvec3(env * lineFlux);
                            receive(acc, cross[0].face, point(0), psf, orient, env, dOmega);
                        }
                        const glm::vec3 L =
                            sendRadiance(cross[0].face, point(0), psf, -orient, iteration);
                        acc.stats.escaped += glm::dvec3(L * lineFlux);
                    }
                    if (facing(n - 1) > 0.f && !truncated) {
                        if (env != glm::vec3(0.f)) {
                            acc.stats.fromEnvironment += glm::dvec3(env * lineFlux);
                            receive(acc, cross[n - 1].face, point(n - 1), psf, -orient, env,
                                    dOmega);
                        }
                        const glm::vec3 L =
                            sendRadiance(cross[n - 1].face, point(n - 1), psf, orient, iteration);
                        acc.stats.escaped += glm::dvec3(L * lineFlux);
                    }
                    // Exchange pairs: a faces along +d, b against it.
                    for (std::size_t k = 0; k + 1 < n; ++k) {
                        if (!(facing(k) > 0.f && facing(k + 1) < 0.f)) continue;
                        const glm::vec3 xa = point(k), xb = point(k + 1);
                        const glm::vec3 La =
                            sendRadiance(cross[k].face, xa, psf, orient, iteration);
                        const glm::vec3 Lb =
                            sendRadiance(cross[k + 1].face, xb, psf, -orient, iteration);
                        acc.stats.sent += glm::dvec3((La + Lb) * lineFlux);
                        if (La != glm::vec3(0.f) || mVlf.specularIndex(cross[k + 1].face) >= 0)
                            receive(acc, cross[k + 1].face, xb, psf, orient, La, dOmega);
                        if (Lb != glm::vec3(0.f) || mVlf.specularIndex(cross[k].face) >= 0)
                            receive(acc, cross[k].face, xa, psf, -orient, Lb, dOmega);
                    }
                }
        }
    }

    VlfIterationStats transportPass(int iteration, VlfBakeStats& bake) {
        const std::size_t l = mDirs.size();
        std::fill(mIncident.begin(), mIncident.end(), glm::vec4(0.f));
        std::vector<ChunkAccum> chunks(std::min(kBakeChunks, l));
        std::atomic<std::size_t> done{0};
        std::atomic<int> reported{0};
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks.size(), 1),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                              for (std::size_t c = r.begin(); c != r.end(); ++c) {
                                  ChunkAccum& acc = chunks[c];
                                  acc.irradiance.assign(mVlf.irradiance().size(), glm::vec3(0.f));
                                  for (std::size_t psf = c; psf < l; psf += chunks.size()) {
                                      transportSubfield(psf, iteration, acc);
                                      const std::size_t now = ++done;
                                      const int tenth = int(now * 10 / l);
                                      int seen = reported.load();
                                      if (mSettings.progress && tenth > seen &&
                                          reported.compare_exchange_strong(seen, tenth))
                                          logInfo("VLF bake: iteration ", iteration, "/",
                                                  mSettings.iterations, ": ", now, "/", l,
                                                  " directions");
                                  }
                              }
                          });
        VlfIterationStats stats;
        mReceived.assign(mVlf.irradiance().size(), glm::vec3(0.f));
        for (const ChunkAccum& acc : chunks) { // fixed order: deterministic sums
            for (std::size_t t = 0; t < mReceived.size(); ++t)
                mReceived[t] += acc.irradiance[t];
            stats.sent += acc.stats.sent;
            stats.received += acc.stats.received;
            stats.escaped += acc.stats.escaped;
            stats.fromEnvironment += acc.stats.fromEnvironment;
            stats.lostDeposits += acc.stats.lostDeposits;
            bake.lines += acc.lines;
            bake.crossings += acc.crossings;
            bake.truncatedLines += acc.truncated;
        }
        for (std::size_t fi = 0; fi < mVlf.faces().size(); ++fi) {
            const FaceMap& m = mVlf.faceMaps()[fi];
            const double area = double(m.texelU) * m.texelV;
            for (std::uint32_t t = m.firstTexel; t < m.firstTexel + m.width * m.height; ++t) {
                const glm::dvec3 flux =
                    glm::dvec3(mReceived[t]) * area * double(mVlf.texelCoverage()[t]);
                stats.deposited += flux;
                stats.reflectedDiffuse += flux * glm::dvec3(mVlf.faces()[fi].diffuse);
            }
        }
        return stats;
    }

    // ---- specular gather ----------------------------------------------------------------------
    void gatherSpecular() {
        if (mVlf.specularFaceCount() == 0) return;
        for (std::size_t c = 0; c < mIncident.size(); ++c) {
            const glm::vec4& a = mIncident[c];
            mIncidentAvg[c] = a.w > 0.f ? glm::vec4(glm::vec3(a) / a.w, 1.f) : glm::vec4(0.f);
        }
        const int m = mVlf.tileSize();
        struct GatherCell {
            std::size_t index;
            glm::vec3 x, L;
        };
        tbb::parallel_for(std::size_t(0), mDirs.size(), [&](std::size_t j) {
            std::vector<GatherCell> cells;
            for (std::size_t sf = 0; sf < mVlf.specularFaceCount(); ++sf) {
                const std::uint32_t face = mVlf.specularFace(sf);
                const Face& f = mVlf.faces()[face];
                const TileBlock& b = mVlf.block(sf, j);
                if (b.side == 0) continue;
                const glm::vec3 o = float(b.side) * mDirs.direction(j);
                if (f.isMirror()) {
                    forEachCell(b, [&](std::int32_t tile, int i, int jj) {
                        const std::size_t c = cellOffset(tile, i, jj, m);
                        const glm::vec3 x = cellPoint(f, j, i, jj);
                        const glm::vec3 from = 2.f * glm::dot(f.normal, o) * f.normal - o;
                        const std::optional<glm::vec3> in =
                            mVlf.lookupTiles(mIncidentAvg, face, x, from);
                        mNextL[c] = in ? f.specular * *in : glm::vec3(0.f);
                        // Render table of a mirror: the total incident light.
                        if (mIncidentAvg[c].w > 0.f) {
                            glm::vec4& r = mTiles[c];
                            r = glm::vec4(glm::vec3(r) + glm::vec3(mIncidentAvg[c]), 1.f);
                        }
                    });
                    continue;
                }
                // Glossy: lobe entry by lobe entry over all the block's cells, so that the
                // incident cells of one subfield are read in order (each cell still sums
                // its lobe in the same order).
                cells.clear();
                forEachCell(b, [&](std::int32_t tile, int i, int jj) {
                    const std::size_t c = cellOffset(tile, i, jj, m);
                    cells.push_back({c, cellPoint(f, j, i, jj), glm::vec3(0.f)});
                });
                for (const auto& [i2, w] : mLobes[sf * mDirs.size() + j])
                    for (GatherCell& cell : cells) {
                        float valid = 0.f;
                        const glm::vec3 in = mVlf.sampleCells(mIncidentAvg, sf, i2, cell.x, valid);
                        if (valid > 0.f) cell.L += w * in;
                    }
                for (const GatherCell& cell : cells) {
                    const glm::vec3 L = cell.L * f.specular;
                    glm::vec4& r = mTiles[cell.index];
                    r = glm::vec4(glm::vec3(r) + L, 1.f);
                    mNextL[cell.index] = L;
                }
            }
        });
    }

    // ---- end of a pass --------------------------------------------------------------------------
    void finishPass(VlfIterationStats&) {
        if (mSettings.filterSigma > 0.f) filter(mReceived);
        std::vector<glm::vec3>& total = mVlf.irradiance();
        for (std::size_t t = 0; t < total.size(); ++t)
            total[t] += mReceived[t];
        mUnshotE.swap(mReceived);
        mUnshotL.swap(mNextL);
        std::fill(mNextL.begin(), mNextL.end(), glm::vec3(0.f));
    }

    /// Separable Gaussian over each face's covered texels, weights renormalised by coverage.
    void filter(std::vector<glm::vec3>& E) const {
        const float sigma = mSettings.filterSigma;
        const int radius = std::max(1, int(std::ceil(2.f * sigma)));
        std::vector<float> kernel(std::size_t(2 * radius + 1));
        for (int k = -radius; k <= radius; ++k)
            kernel[std::size_t(k + radius)] = std::exp(-0.5f * float(k * k) / (sigma * sigma));
        const std::vector<float>& cov = mVlf.texelCoverage();
        tbb::parallel_for(std::size_t(0), mVlf.faces().size(), [&](std::size_t fi) {
            const FaceMap& m = mVlf.faceMaps()[fi];
            const int W = int(m.width), H = int(m.height);
            std::vector<glm::vec3> tmp(std::size_t(W) * H), out(std::size_t(W) * H);
            std::vector<float> tmpW(std::size_t(W) * H);
            const auto at = [&](int x, int y) { return m.firstTexel + std::size_t(y) * W + x; };
            for (int y = 0; y < H; ++y)
                for (int x = 0; x < W; ++x) {
                    glm::vec3 s(0.f);
                    float w = 0.f;
                    for (int k = -radius; k <= radius; ++k) {
                        const int x2 = x + k;
                        if (x2 < 0 || x2 >= W) continue;
                        const float g = kernel[std::size_t(k + radius)] * cov[at(x2, y)];
                        s += g * E[at(x2, y)];
                        w += g;
                    }
                    tmp[std::size_t(y) * W + x] = s;
                    tmpW[std::size_t(y) * W + x] = w;
                }
            for (int y = 0; y < H; ++y)
                for (int x = 0; x < W; ++x) {
                    glm::vec3 s(0.f);
                    float w = 0.f;
                    for (int k = -radius; k <= radius; ++k) {
                        const int y2 = y + k;
                        if (y2 < 0 || y2 >= H) continue;
                        const float g = kernel[std::size_t(k + radius)];
                        s += g * tmp[std::size_t(y2) * W + x];
                        w += g * tmpW[std::size_t(y2) * W + x];
                    }
                    out[std::size_t(y) * W + x] =
                        cov[at(x, y)] > 0.f && w > 0.f ? s / w : E[at(x, y)];
                }
            for (int y = 0; y < H; ++y)
                for (int x = 0; x < W; ++x)
                    E[at(x, y)] = out[std::size_t(y) * W + x];
        });
    }

    const VlfScene& mScene;
    VlfSettings mSettings;
    Vlf mVlf;
    const DirectionSet& mDirs;
    std::vector<glm::vec3> mUnshotE, mReceived;
    std::vector<glm::vec3> mUnshotL, mNextL;
    /// The render table as floats (RGB radiance and weight), packed into the Vlf at the end.
    std::vector<glm::vec4> mTiles;
    std::vector<glm::vec4> mIncident, mIncidentAvg;
    std::vector<std::vector<std::pair<std::uint32_t, float>>> mLobes;
};

} // namespace

Vlf bakeVlf(const VlfScene& scene, const VlfSettings& settings, VlfBakeStats* stats) {
    validate(settings);
    Baker baker(scene, settings);
    return baker.run(stats);
}

} // namespace qgi::vlf
