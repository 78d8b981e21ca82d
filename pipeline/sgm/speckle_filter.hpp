#pragma once
// Removes small isolated regions ("speckles") from a disparity image: connected regions
// of valid pixels, neighbours (4-connected) differing by at most max_step, of fewer than
// max_size pixels are set invalid. The same rule as OpenCV's filterSpeckles, without
// allocating: every buffer is sized in the constructor.
//
// Thread-bound.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace stereod::sgm {

// Bytes a SpeckleFilter for a width x height image allocates.
size_t speckleFilterBytes(int width, int height);

class SpeckleFilter {
public:
    SpeckleFilter(int width, int height);

    // disparity: width * height values, row-major; `invalid` marks no disparity.
    void apply(int16_t* disparity, int16_t invalid, int max_step, int max_size);

private:
    int width_;
    std::vector<uint32_t> label_;     // region of each pixel; 0 = not yet visited
    std::vector<uint32_t> stack_;     // pixels waiting to be visited
    std::vector<uint8_t> removed_;    // per region label: removed
};

} // namespace stereod::sgm
