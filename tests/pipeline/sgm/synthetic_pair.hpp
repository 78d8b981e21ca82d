#pragma once
// A synthetic rectified stereo pair with known disparities, for the matcher's tests:
// fronto-parallel textured layers (a background and rectangles nearer to the cameras),
// the right view drawn by shifting every layer left by its disparity, so that each
// surface point has exactly the same intensity in both views.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace stereod::sgm::test {

// A fronto-parallel layer: the rectangle [x0, x1) x [y0, y1) in the left view, at an
// integer disparity in pixels (right view column = left view column - disparity_px).
struct Layer {
    int x0, y0, x1, y1;
    int disparity_px;
};

struct SyntheticPair {
    int width = 0;
    int height = 0;
    std::vector<uint8_t> left, right; // width * height, row-major, stride = width
    std::vector<int> truth_px;        // disparity of the surface each left pixel sees
    // 1 where the right view does not see that surface: hidden by a nearer layer, or
    // outside the right image (x - truth_px < 0).
    std::vector<uint8_t> occluded;

    size_t at(int x, int y) const
    {
        return static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
    }
};

// Layers are drawn in the order given, later ones in front. The texture (fine random dots
// over coarser blotches) depends only on the layer, the left-view column and the row.
SyntheticPair makeSyntheticPair(int width, int height, const std::vector<Layer>& layers,
                                uint32_t seed);

// The same deterministic pseudo-random bits on every platform (SplitMix64).
class Random {
  public:
    explicit Random(uint64_t seed) : state_(seed) {}
    uint64_t next();
    // Uniform within lo..hi, both included.
    int uniform(int lo, int hi);

  private:
    uint64_t state_;
};

} // namespace stereod::sgm::test
