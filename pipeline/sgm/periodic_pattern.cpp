#include "pipeline/sgm/periodic_pattern.hpp"

#include <algorithm>
#include <cstdlib>

namespace stereod::sgm {
namespace {

// Whether spacing b follows spacing a closely enough to be the same period (a pixel of
// slack for short periods).
bool samePeriod(int a, int b)
{
    return std::abs(a - b) * 100 <= kPeriodicSpacingTolerance * std::max(a, b) + 100;
}

// Marks [from, to) of row, clipped to the row.
void markSpan(uint8_t* row, int width, int from, int to)
{
    from = std::max(from, 0);
    to = std::min(to, width);
    for (int x = from; x < to; ++x)
        row[x] = 1;
}

// edges[0..count-1]: the positions of one polarity's edges along a row, increasing.
void markRuns(const int* edges, int count, int width, int min_period, int max_period, uint8_t* row)
{
    int start = 0; // the first edge of the current run of regular spacings
    for (int i = 1; i <= count; ++i) {
        const int spacing = i < count ? edges[i] - edges[i - 1] : 0;
        const bool in_range = spacing >= min_period && spacing <= max_period;
        const bool continues = i < count && in_range &&
                               (i - start < 2 || samePeriod(edges[i - 1] - edges[i - 2], spacing));
        if (continues)
            continue;
        if (i - start >= kPeriodicMinEdges) {
            const int period = (edges[i - 1] - edges[start]) / (i - 1 - start);
            markSpan(row, width, edges[start] - period, edges[i - 1] + period + 1);
        }
        // The spacing that broke the run may start the next one.
        start = i < count && in_range ? i - 1 : i;
    }
}

} // namespace

void markPeriodicRows(const uint8_t* image, size_t stride, int width, int y0, int y1,
                      int min_period, int max_period, int* scratch, uint8_t* raw)
{
    int* rising = scratch;
    int* falling = scratch + width;
    for (int y = y0; y < y1; ++y) {
        const uint8_t* in = image + static_cast<size_t>(y) * stride;
        uint8_t* out = raw + static_cast<size_t>(y) * static_cast<size_t>(width);
        std::fill(out, out + width, uint8_t{0});
        int rises = 0, falls = 0;
        // An edge at its steepest: its two-pixel step at x is at least that at x - 1 and
        // more than that at x + 1.
        const auto step = [&](int x) { return static_cast<int>(in[x + 1]) - in[x - 1]; };
        for (int x = 2; x + 2 < width; ++x) {
            const int g = step(x);
            const int a = std::abs(g);
            if (a < kPeriodicEdgeStep || a < std::abs(step(x - 1)) || a <= std::abs(step(x + 1)))
                continue;
            if (g > 0)
                rising[rises++] = x;
            else
                falling[falls++] = x;
        }
        markRuns(rising, rises, width, min_period, max_period, out);
        markRuns(falling, falls, width, min_period, max_period, out);
    }
}

void spreadPeriodicRows(const uint8_t* raw, int width, int height, int y0, int y1, uint8_t* mask)
{
    const size_t w = static_cast<size_t>(width);
    for (int y = y0; y < y1; ++y) {
        uint8_t* out = mask + static_cast<size_t>(y) * w;
        std::fill(out, out + width, uint8_t{0});
        const int first = std::max(0, y - kPeriodicRowReach);
        const int last = std::min(height - 1, y + kPeriodicRowReach);
        for (int v = first; v <= last; ++v) {
            const uint8_t* row = raw + static_cast<size_t>(v) * w;
            for (int x = 0; x < width; ++x)
                out[x] |= row[x];
        }
    }
}

} // namespace stereod::sgm
