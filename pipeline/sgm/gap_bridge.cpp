#include "pipeline/sgm/gap_bridge.hpp"

#include <cstddef>
#include <cstdlib>

#include "pipeline/sgm/sgm_kernels.hpp"

namespace stereod::sgm {
namespace {

// One line of `count` values `step` apart: a row or a column.
void bridgeLine(int16_t* d, uint8_t* confidence, const uint8_t* range_limit, const uint8_t* only,
                int count, size_t step, int max_gap)
{
    int last = -1; // the last position with a disparity, -1 after a barrier
    for (int k = 0; k < count; ++k) {
        const size_t at = static_cast<size_t>(k) * step;
        if (range_limit[at] != 0 || (only != nullptr && only[at] == 0)) {
            last = -1;
            continue;
        }
        if (d[at] == kNoDisparity)
            continue;
        const int gap = k - last - 1;
        if (last >= 0 && gap > 0 && gap <= max_gap) {
            const int a = d[static_cast<size_t>(last) * step];
            const int b = d[at];
            if (std::abs(a - b) <= kSubpixel) {
                // a + (b - a) j / (gap + 1), rounded half away from zero, in integers.
                const int span = gap + 1;
                for (int j = 1; j <= gap; ++j) {
                    const int scaled = 2 * (b - a) * j;
                    const int offset = (scaled + (scaled >= 0 ? span : -span)) / (2 * span);
                    const size_t fill = static_cast<size_t>(last + j) * step;
                    d[fill] = static_cast<int16_t>(a + offset);
                    confidence[fill] = kInferredConfidence;
                }
            }
        }
        last = k;
    }
}

} // namespace

void bridgeGaps(int16_t* disparity, uint8_t* confidence, const uint8_t* range_limit, int width,
                int height, int max_gap, const uint8_t* only)
{
    const size_t w = static_cast<size_t>(width);
    for (int y = 0; y < height; ++y) {
        const size_t row = static_cast<size_t>(y) * w;
        bridgeLine(disparity + row, confidence + row, range_limit + row,
                   only != nullptr ? only + row : nullptr, width, 1, max_gap);
    }
    for (int x = 0; x < width; ++x)
        bridgeLine(disparity + x, confidence + x, range_limit + x,
                   only != nullptr ? only + x : nullptr, height, w, max_gap);
}

} // namespace stereod::sgm
