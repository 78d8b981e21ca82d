#pragma once
// Whether a pixel has texture: the grey levels of the 5x3 pixels around it (clipped to the
// image) span at least min_range. Where they do, the census tells matches apart; where
// they do not, a pixel matches any patch as flat as itself.
//
// Reentrant.

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace stereod::sgm {

inline bool isTextured(const uint8_t* image, size_t stride, int width, int height, int x, int y,
                       int min_range)
{
    const int x0 = std::max(0, x - 2), x1 = std::min(width - 1, x + 2);
    const int y0 = std::max(0, y - 1), y1 = std::min(height - 1, y + 1);
    int lo = 255, hi = 0;
    for (int v = y0; v <= y1; ++v) {
        const uint8_t* row = image + static_cast<size_t>(v) * stride;
        for (int u = x0; u <= x1; ++u) {
            lo = std::min<int>(lo, row[u]);
            hi = std::max<int>(hi, row[u]);
        }
    }
    return hi - lo >= min_range;
}

} // namespace stereod::sgm
