#include "systems/detp/NearSegments.h"

#include "runtime/core/Error.h"
#include "systems/photon_update/PhotonPathGrid.h"
#include "systems/photon_update/PhotonStore.h"

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <numeric>

namespace qgi {

void DeltaByPath::arrange(const PhotonDelta& delta) {
    const std::size_t paths = delta.paths.size();
    order.clear();
    head.assign(paths, 0);
    for (std::size_t i = 0; i < paths; ++i) {
        const std::int32_t first = delta.head(i);
        if (first < 0) continue; // nothing of it changed
        head[i] = std::uint32_t(first);
        order.push_back(std::uint32_t(i));
    }
    // The photon update lists re-shot paths first, then re-traced ones in path order.
    const auto byPath = [&](std::uint32_t a, std::uint32_t b) {
        return delta.paths[a] < delta.paths[b];
    };
    if (!std::is_sorted(order.begin(), order.end(), byPath))
        std::sort(order.begin(), order.end(), byPath);
    QGI_ASSERT(std::adjacent_find(order.begin(), order.end(),
                                  [&](std::uint32_t a, std::uint32_t b) {
                                      return delta.paths[a] == delta.paths[b];
                                  }) == order.end(),
               "PhotonDelta lists a path twice");
}

bool NearSegments::covers(const Aabb& box) const {
    return mValid && contains(mBox, box);
}

void NearSegments::clear() {
    *this = NearSegments{};
}

void NearSegments::resize(std::size_t n) {
    mKey.resize(n);
    mCopies.resize(n);
}

void NearSegments::copyRange(std::size_t to, const NearSegments& from, std::size_t first,
                             std::size_t count) {
    const auto copy = [&](const auto& src, auto& dst) {
        std::copy_n(src.begin() + std::ptrdiff_t(first), count, dst.begin() + std::ptrdiff_t(to));
    };
    copy(from.mKey, mKey);
    copy(from.mCopies, mCopies);
}

void NearSegments::build(const PhotonStore& store, const Aabb& box, float tail, Entity mobile,
                         std::span<const Pick> picks) {
    mValid = true;
    mMade = picks.size();
    mBox = box;
    mTail = tail;
    mMobile = mobile;
    resize(picks.size());
    const PhotonSegments& segments = store.segments;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, picks.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          for (std::size_t i = range.begin(); i != range.end(); ++i) {
                              const Pick pick = picks[i];
                              const PhotonPath& path = store.paths[pick.path];
                              const std::uint32_t s = pick.segment, k = s - path.first;
                              mKey[i] = key(pick.path, k);
                              mCopies[i] = {
                                  segments.origin[s],
                                  segments.direction[s],
                                  segments.power[s],
                                  segments.length[s],
                                  std::uint8_t(k),
                                  k > 0 && !mobile.isNull() && segments.hitEntity[s - 1] == mobile,
                                  path.light};
                          }
                      });
}

void NearSegments::apply(const PhotonDelta& delta, const DeltaByPath& byPath,
                         std::span<const Entity> prefixEnd, std::span<const std::uint16_t> light,
                         NearSegments& scratch) {
    if (!mValid) return;
    // What changes: per delta path, its copies from its head on (they sit after its kept
    // ones) and its new segments that meet the box. Both lists are in path order.
    const PhotonSegments& added = delta.newSegments;
    const std::size_t n = size();
    mCuts.clear();
    mIncoming.clear();
    std::size_t j = 0, kept = 0, written = 0;
    for (const std::uint32_t i : byPath.order) {
        const std::uint32_t path = delta.paths[i], head = byPath.head[i];
        const std::uint64_t first = key(path, 0), replaced = key(path, head), next = first + 256;
        while (j < n && mKey[j] < first)
            ++j;
        std::size_t from = j;
        while (from < n && mKey[from] < replaced)
            ++from;
        std::size_t to = from;
        while (to < n && mKey[to] < next)
            ++to;
        j = to;
        const auto incoming = std::uint32_t(mIncoming.size());
        for (std::uint32_t s = delta.newFirst[i]; s < delta.newFirst[i + 1]; ++s)
            if (segmentMeetsBox(added.origin[s], added.direction[s], added.length[s] + mTail, mBox))
                mIncoming.push_back(s);
        if (to == from && mIncoming.size() == incoming) continue;
        mCuts.push_back(
            {std::uint32_t(from), std::uint32_t(to), i, incoming, std::uint32_t(written)});
        written += from - kept + (mIncoming.size() - incoming);
        kept = to;
    }
    if (mCuts.empty()) return;

    // Each cut's copies since the previous one, then its new segments, in parallel.
    scratch.resize(written + n - kept);
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, mCuts.size(), 256),
        [&](const tbb::blocked_range<std::size_t>& range) {
            for (std::size_t c = range.begin(); c != range.end(); ++c) {
                const Cut& cut = mCuts[c];
                const std::size_t since = c > 0 ? mCuts[c - 1].to : 0;
                scratch.copyRange(cut.write, *this, since, cut.from - since);
                std::size_t write = cut.write + cut.from - since;
                const std::size_t end =
                    c + 1 < mCuts.size() ? mCuts[c + 1].incoming : mIncoming.size();
                const std::uint32_t first = delta.newFirst[cut.delta];
                for (std::size_t m = cut.incoming; m < end; ++m, ++write) {
                    const std::uint32_t s = mIncoming[m];
                    const Entity start = s == first ? prefixEnd[cut.delta] : added.hitEntity[s - 1];
                    scratch.mKey[write] = key(delta.paths[cut.delta], added.bounce[s]);
                    scratch.mCopies[write] = {
                        added.origin[s], added.direction[s], added.power[s],
                        added.length[s], added.bounce[s],    !mMobile.isNull() && start == mMobile,
                        light[cut.delta]};
                }
            }
        });
    scratch.copyRange(written, *this, kept, n - kept);
    std::swap(mKey, scratch.mKey);
    std::swap(mCopies, scratch.mCopies);
}

} // namespace qgi
