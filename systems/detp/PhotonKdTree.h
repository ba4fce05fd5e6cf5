#pragma once

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace qgi {

/** The photon map of seed 004 section 4, kept to compare DETP with: photon hit points in a
 *  balanced kd-tree stored as one flat array with no child pointers. The node of the index
 *  range [lo, hi] sits at its median lo + (hi - lo) / 2, its left subtree is [lo, median - 1]
 *  and its right subtree [median + 1, hi] (an in-order layout: in 1-D the array is sorted). The
 *  split axis of a node is the axis of greatest extent of its range's bounding box, stored per
 *  node. k-nearest search is the digest's corrected range search: one side only when the
 *  search sphere lies entirely on it (|delta| against the radius), a candidate replaces the
 *  heap's head only when closer, and the radius shrinks to the head once the heap is full. */
class PhotonKdTree {
public:
    struct Photon {
        glm::vec3 position{0.f};  ///< metres, world space
        glm::vec3 power{0.f};     ///< W, linear RGB
        glm::vec3 direction{0.f}; ///< unit: the direction the photon arrived along
    };
    struct Neighbour {
        float distance2 = 0.f;   ///< squared distance to the query point, m^2
        std::uint32_t index = 0; ///< into photons()
    };

    /// Reorders `photons` into the tree: O(n log n), the two halves of large ranges in parallel
    /// (deterministic: the same input gives the same tree).
    void build(std::vector<Photon> photons);

    std::span<const Photon> photons() const { return mPhotons; }
    /// Split axis (0, 1, 2) of the node at `index`.
    int splitAxis(std::size_t index) const { return mAxes[index]; }

    /// The (at most k) photons nearest to `center` with squared distance < maxDistance2 that
    /// `accept(const Photon&)` takes, as a max-heap on distance in `out` (head: the farthest).
    /// Returns the squared radius that bounds them: the head's distance when k were found,
    /// otherwise maxDistance2.
    template <typename Accept>
    float nearest(const glm::vec3& center, std::uint32_t k, float maxDistance2, Accept accept,
                  std::vector<Neighbour>& out) const {
        out.clear();
        float radius2 = maxDistance2;
        if (k > 0 && !mPhotons.empty())
            search(center, k, radius2, accept, out, 0, std::ptrdiff_t(mPhotons.size()) - 1);
        return radius2;
    }

    /// Jensen's radiance estimate of irradiance at a surface point: the power of the k nearest
    /// photons that arrived from the front of `normal`, over the area pi r^2 of the disc that
    /// holds them (r = maxRadius where fewer than k lie within it). W/m^2.
    glm::vec3 estimateIrradiance(const glm::vec3& center, const glm::vec3& normal, std::uint32_t k,
                                 float maxRadius, std::vector<Neighbour>& scratch) const;

private:
    static bool closer(const Neighbour& a, const Neighbour& b) { return a.distance2 < b.distance2; }

    void buildRange(std::size_t lo, std::size_t end);

    template <typename Accept>
    void search(const glm::vec3& center, std::uint32_t k, float& radius2, Accept& accept,
                std::vector<Neighbour>& heap, std::ptrdiff_t lo, std::ptrdiff_t hi) const {
        if (hi < lo) return;
        const std::ptrdiff_t m = lo + (hi - lo) / 2;
        const Photon& photon = mPhotons[std::size_t(m)];
        const int axis = mAxes[std::size_t(m)];
        const float delta = center[axis] - photon.position[axis];
        // The near side first, so the radius has shrunk before the far side is considered;
        // the far side only while the sphere still reaches across the split plane.
        if (delta <= 0.f) {
            search(center, k, radius2, accept, heap, lo, m - 1);
            if (delta * delta < radius2) search(center, k, radius2, accept, heap, m + 1, hi);
        } else {
            search(center, k, radius2, accept, heap, m + 1, hi);
            if (delta * delta < radius2) search(center, k, radius2, accept, heap, lo, m - 1);
        }
        const glm::vec3 offset = photon.position - center;
        const float d2 = glm::dot(offset, offset);
        if (!(d2 < radius2) || !accept(photon)) return;
        if (heap.size() == k) { // full, and d2 < radius2 = the head's distance: replace it
            std::pop_heap(heap.begin(), heap.end(), closer);
            heap.back() = {d2, std::uint32_t(m)};
        } else {
            heap.push_back({d2, std::uint32_t(m)});
        }
        std::push_heap(heap.begin(), heap.end(), closer);
        if (heap.size() == k) radius2 = heap.front().distance2;
    }

    std::vector<Photon> mPhotons;
    std::vector<std::uint8_t> mAxes;
};

} // namespace qgi
