// glTF import, animations: translation and rotation channels become a looping PathFollower on
// their node's record, with the node extras {"qgiPath": ...} that glTF cannot say.

#include "runtime/scene/GltfReader.h"

#include "runtime/core/Log.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <map>

namespace qgi::gltf_detail {

void GltfReader::readAnimations(std::vector<EntityRecord>& records) const {
    // A node may only move if no static mesh moves with it (the static BVH, the disc index and
    // the point cache are built once).
    std::vector<bool> staticBelow(records.size(), false);
    for (std::size_t r = records.size(); r-- > 0;) {
        if (records[r].source && records[r].mobility == Mobility::Static) staticBelow[r] = true;
        if (staticBelow[r] && records[r].parent >= 0)
            staticBelow[std::size_t(records[r].parent)] = true;
    }
    struct Channel {
        std::vector<float> times;
        std::vector<glm::vec4> values; // xyz (translation) or a quaternion's xyzw
        bool step = false;
        std::string field;
    };
    struct Animated {
        std::optional<Channel> translation, rotation;
    };
    std::map<int, Animated> nodes;
    bool warnedScale = false;
    for (std::size_t a = 0; a < mModel.animations.size(); ++a) {
        const tinygltf::Animation& animation = mModel.animations[a];
        for (std::size_t c = 0; c < animation.channels.size(); ++c) {
            const tinygltf::AnimationChannel& channel = animation.channels[c];
            const std::string field = str("animations[", a, "].channels[", c, "]");
            if (channel.target_node < 0) continue; // targets something else (an extension)
            checkIndex(field + ".target.node", channel.target_node, mModel.nodes.size(), "nodes");
            const std::string& path = channel.target_path;
            if (path == "scale" || path == "weights") {
                if (!warnedScale)
                    logWarning(mLabel, ": ", field, ".target.path: ", path,
                               " animation is not imported (qgi's mobiles are rigid)");
                warnedScale = true;
                continue;
            }
            if (path != "translation" && path != "rotation")
                fail(field + ".target.path", "'", path, "' is not a glTF 2.0 animation path");
            checkIndex(field + ".sampler", channel.sampler, animation.samplers.size(), "samplers");
            const tinygltf::AnimationSampler& sampler =
                animation.samplers[std::size_t(channel.sampler)];
            const std::string samplerField =
                str("animations[", a, "].samplers[", channel.sampler, "]");
            const std::string& interpolation = sampler.interpolation;
            if (interpolation != "LINEAR" && interpolation != "STEP" &&
                interpolation != "CUBICSPLINE")
                fail(samplerField + ".interpolation", "'", interpolation,
                     "' is not LINEAR, STEP or CUBICSPLINE");
            Channel out;
            out.field = field;
            out.step = interpolation == "STEP";
            out.times = readScalars(samplerField + ".input", sampler.input);
            for (std::size_t k = 0; k < out.times.size(); ++k)
                if (out.times[k] < 0.f || (k > 0 && !(out.times[k] > out.times[k - 1])))
                    fail(samplerField + ".input", "times must be >= 0 and strictly increasing (", k,
                         ": ", out.times[k], ")");
            if (path == "translation") {
                for (const glm::vec3& v : readVec3(samplerField + ".output", sampler.output))
                    out.values.emplace_back(v, 0.f);
            } else {
                out.values = readRotations(samplerField + ".output", sampler.output);
            }
            // A cubic spline stores (in-tangent, value, out-tangent) per key: keep the values
            // and join them linearly.
            if (interpolation == "CUBICSPLINE") {
                if (out.values.size() != 3 * out.times.size())
                    fail(samplerField + ".output", out.values.size(), " values for ",
                         out.times.size(), " cubic-spline keys; needs three per key");
                std::vector<glm::vec4> values;
                for (std::size_t k = 0; k < out.times.size(); ++k)
                    values.push_back(out.values[3 * k + 1]);
                out.values = std::move(values);
            }
            if (out.values.size() != out.times.size())
                fail(samplerField + ".output", out.values.size(), " values for ", out.times.size(),
                     " key times");
            if (path == "rotation")
                for (std::size_t k = 0; k < out.values.size(); ++k) {
                    const float length = glm::length(out.values[k]);
                    if (!(length > 1e-6f))
                        fail(samplerField + ".output", "key ", k, " is not a rotation (zero)");
                    out.values[k] /= length;
                }
            Animated& node = nodes[channel.target_node];
            std::optional<Channel>& slot = path == "translation" ? node.translation : node.rotation;
            if (slot) {
                logWarning(mLabel, ": ", field, ": a second ", path, " channel for nodes[",
                           channel.target_node, "]; only ", slot->field, " is imported");
                continue;
            }
            slot = std::move(out);
        }
    }

    // Value of a channel at time t: holds its ends, linear (slerp) or held between keys.
    const auto sample = [](const Channel& c, float t, bool rotation) {
        if (t <= c.times.front()) return c.values.front();
        if (t >= c.times.back()) return c.values.back();
        const std::size_t k =
            std::size_t(std::upper_bound(c.times.begin(), c.times.end(), t) - c.times.begin());
        const glm::vec4& a = c.values[k - 1];
        const glm::vec4& b = c.values[k];
        if (c.step) return a;
        const float u = (t - c.times[k - 1]) / (c.times[k] - c.times[k - 1]);
        if (!rotation) return glm::mix(a, b, u);
        const glm::quat q =
            glm::slerp(glm::quat(a.w, a.x, a.y, a.z), glm::quat(b.w, b.x, b.y, b.z), u);
        return glm::vec4(q.x, q.y, q.z, q.w);
    };
    for (auto& [index, animated] : nodes) {
        const std::string field = str("nodes[", index, "]");
        const int record = mNodeRecord[std::size_t(index)];
        if (record < 0) continue; // not in the scene
        if (staticBelow[std::size_t(record)]) {
            logWarning(mLabel, ": ", field,
                       " is animated but moves static meshes; its animation "
                       "is ignored (tag them {\"mobility\": \"mobile\"})");
            continue;
        }
        // Keys at every time of either channel; a held (STEP) value also gets a key just
        // before the next time, so that linear blending between keys keeps it.
        std::vector<float> times;
        for (const std::optional<Channel>* c : {&animated.translation, &animated.rotation}) {
            if (!*c) continue;
            const auto& t = (*c)->times;
            times.insert(times.end(), t.begin(), t.end());
            if ((*c)->step)
                for (std::size_t k = 1; k < t.size(); ++k)
                    times.push_back(t[k] - std::min(1e-3f, 0.01f * (t[k] - t[k - 1])));
        }
        std::sort(times.begin(), times.end());
        times.erase(std::unique(times.begin(), times.end()), times.end());
        const Transform& rest = records[std::size_t(record)].transform;
        PathFollower path;
        path.loop = true;
        for (const float t : times) {
            PathKey key;
            key.time = t;
            key.position = animated.translation ? glm::vec3(sample(*animated.translation, t, false))
                                                : rest.translation;
            if (animated.rotation) {
                const glm::vec4 q = sample(*animated.rotation, t, true);
                key.rotation = glm::normalize(glm::quat(q.w, q.x, q.y, q.z));
            } else {
                key.rotation = rest.rotation;
            }
            path.keys.push_back(key);
        }
        readPathExtras(index, path);
        records[std::size_t(record)].path = std::move(path);
    }
}

void GltfReader::readPathExtras(int index, PathFollower& path) const {
    const tinygltf::Value& extras = mModel.nodes[std::size_t(index)].extras;
    if (!extras.IsObject() || !extras.Has("qgiPath")) return;
    const std::string field = str("nodes[", index, "].extras.qgiPath");
    const tinygltf::Value& p = extras.Get("qgiPath");
    if (!p.IsObject()) fail(field, "must be an object {\"loop\": bool, \"timeOffset\": seconds}");
    if (p.Has("loop")) {
        if (!p.Get("loop").IsBool()) fail(field + ".loop", "must be true or false");
        path.loop = p.Get("loop").Get<bool>();
    }
    if (p.Has("timeOffset")) {
        const tinygltf::Value& offset = p.Get("timeOffset");
        if (!offset.IsNumber() || !std::isfinite(offset.GetNumberAsDouble()))
            fail(field + ".timeOffset", "must be a finite number of seconds");
        path.timeOffset = float(offset.GetNumberAsDouble());
    }
}

} // namespace qgi::gltf_detail
