#pragma once
// Whether a pixel has texture: the grey levels of the 5x3 pixels around it (clipped to the
// image) span at least min_range. Where they do, the census tells matches apart; where
// they do not, a pixel matches any patch as flat as itself. texturedRow(): the same test
// for a whole row.
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

// isTextured() for every pixel of row y at once: textured[x] = 1 where it holds, else 0.
// The 3 rows' extremes per column first, then the 5 columns': a few operations per pixel
// rather than fifteen reads. Both loops have no branch inside (a row outside the image
// stands in as its neighbour, which changes no extreme; the columns near the ends are
// done apart), so that the compiler makes them vector loops. column_lo, column_hi:
// `width` bytes of scratch each.
inline void texturedRow(const uint8_t* image, size_t stride, int width, int height, int y,
                        int min_range, uint8_t* column_lo, uint8_t* column_hi, uint8_t* textured)
{
    const uint8_t* above = image + static_cast<size_t>(std::max(0, y - 1)) * stride;
    const uint8_t* row = image + static_cast<size_t>(y) * stride;
    const uint8_t* below = image + static_cast<size_t>(std::min(height - 1, y + 1)) * stride;
    for (int x = 0; x < width; ++x) {
        column_lo[x] = std::min(std::min(above[x], row[x]), below[x]);
        column_hi[x] = std::max(std::max(above[x], row[x]), below[x]);
    }
    const auto clipped = [&](int x) {
        const int x0 = std::max(0, x - 2), x1 = std::min(width - 1, x + 2);
        uint8_t lo = column_lo[x0], hi = column_hi[x0];
        for (int u = x0 + 1; u <= x1; ++u) {
            lo = std::min(lo, column_lo[u]);
            hi = std::max(hi, column_hi[u]);
        }
        textured[x] = hi - lo >= min_range ? 1 : 0;
    };
    const int interior_end = std::max(2, width - 2);
    for (int x = 0; x < std::min(2, width); ++x)
        clipped(x);
    for (int x = 2; x < interior_end; ++x) {
        const uint8_t lo = std::min(
            {column_lo[x - 2], column_lo[x - 1], column_lo[x], column_lo[x + 1], column_lo[x + 2]});
        const uint8_t hi = std::max(
            {column_hi[x - 2], column_hi[x - 1], column_hi[x], column_hi[x + 1], column_hi[x + 2]});
        textured[x] = static_cast<uint8_t>(hi - lo >= min_range);
    }
    for (int x = std::max(2, interior_end); x < width; ++x)
        clipped(x);
}

} // namespace stereod::sgm
