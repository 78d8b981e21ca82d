#include "pipeline/sgm/speckle_filter.hpp"

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace stereod::sgm {
namespace {

// Two valid neighbours belong to one region when their disparities differ by at most this.
bool together(int a, int b, int max_step)
{
    return std::abs(a - b) <= max_step;
}

constexpr int kMaxWidth = 65535; // run ends are 16-bit

} // namespace

size_t speckleFilterBytes(int width, int height)
{
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    return area * (2 * sizeof(uint16_t) + 2 * sizeof(uint32_t)) +
           static_cast<size_t>(height) * sizeof(uint32_t);
}

SpeckleFilter::SpeckleFilter(int width, int height) : width_(width), height_(height)
{
    if (width < 1 || width > kMaxWidth || height < 1)
        throw std::invalid_argument("SpeckleFilter: a " + std::to_string(width) + "x" +
                                    std::to_string(height) + " image (width 1 to " +
                                    std::to_string(kMaxWidth) + ")");
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    runs_.assign(static_cast<size_t>(height), 0);
    begin_.assign(area, 0);
    end_.assign(area, 0);
    parent_.assign(area, 0);
    size_.assign(area, 0);
}

void SpeckleFilter::apply(int16_t* disparity, int16_t invalid, int max_step, int max_size)
{
    labelBand(disparity, invalid, max_step, 0, height_);
    removeBand(disparity, invalid, max_size, 0, height_);
}

uint32_t SpeckleFilter::rootHalving(uint32_t region)
{
    while (parent_[region] != region) {
        parent_[region] = parent_[parent_[region]];
        region = parent_[region];
    }
    return region;
}

uint32_t SpeckleFilter::join(uint32_t a, uint32_t b)
{
    // The larger index joins the smaller: the roots stay ordered, the chains short.
    const uint32_t keep = std::min(a, b);
    const uint32_t joined = std::max(a, b);
    parent_[joined] = keep;
    size_[keep] += size_[joined];
    return keep;
}

void SpeckleFilter::labelBand(const int16_t* disparity, int16_t invalid, int max_step, int y0,
                              int y1)
{
    const int w = width_;
    for (int y = y0; y < y1; ++y) {
        const int16_t* d = disparity + static_cast<size_t>(y) * static_cast<size_t>(w);
        const uint32_t first = static_cast<uint32_t>(y) * static_cast<uint32_t>(w);
        uint32_t run = first;
        int x = 0;
        for (;;) {
            while (x < w && d[x] == invalid)
                ++x;
            if (x == w)
                break;
            const int begin = x++;
            while (x < w && d[x] != invalid && together(d[x], d[x - 1], max_step))
                ++x;
            begin_[run] = static_cast<uint16_t>(begin);
            end_[run] = static_cast<uint16_t>(x);
            parent_[run] = run;
            size_[run] = static_cast<uint32_t>(x - begin);
            ++run;
        }
        runs_[static_cast<size_t>(y)] = run - first;
        if (y > y0)
            joinRows(disparity, max_step, y);
    }
}

void SpeckleFilter::joinRows(const int16_t* disparity, int max_step, int y)
{
    const size_t w = static_cast<size_t>(width_);
    const int16_t* d = disparity + static_cast<size_t>(y) * w;
    const int16_t* above = d - w;
    uint32_t a = static_cast<uint32_t>(y - 1) * static_cast<uint32_t>(w);
    const uint32_t a_end = a + runs_[static_cast<size_t>(y) - 1];
    uint32_t b = static_cast<uint32_t>(y) * static_cast<uint32_t>(w);
    const uint32_t b_end = b + runs_[static_cast<size_t>(y)];
    // Both rows' runs in order of position: each pair that overlaps is looked at once, and
    // the first pixel of the overlap that belongs with the one above joins the two.
    while (a < a_end && b < b_end) {
        const int from = std::max(begin_[a], begin_[b]);
        const int to = std::min(end_[a], end_[b]);
        for (int x = from; x < to; ++x) {
            if (together(d[x], above[x], max_step)) {
                const uint32_t ra = rootHalving(a), rb = rootHalving(b);
                if (ra != rb)
                    join(ra, rb);
                break;
            }
        }
        if (end_[a] <= end_[b])
            ++a;
        else
            ++b;
    }
}

uint32_t SpeckleFilter::root(uint32_t region) const
{
    while (parent_[region] != region)
        region = parent_[region];
    return region;
}

void SpeckleFilter::joinBands(const int16_t* disparity, int16_t /*invalid*/, int max_step,
                              const int* band_starts, int bands)
{
    for (int band = 1; band < bands; ++band)
        if (band_starts[band] > 0 && band_starts[band] < height_)
            joinRows(disparity, max_step, band_starts[band]);
}

void SpeckleFilter::removeBand(int16_t* disparity, int16_t invalid, int max_size, int y0,
                               int y1) const
{
    const size_t w = static_cast<size_t>(width_);
    const auto small = static_cast<uint32_t>(std::max(0, max_size));
    for (int y = y0; y < y1; ++y) {
        int16_t* d = disparity + static_cast<size_t>(y) * w;
        const uint32_t first = static_cast<uint32_t>(y) * static_cast<uint32_t>(w);
        const uint32_t end = first + runs_[static_cast<size_t>(y)];
        for (uint32_t run = first; run < end; ++run)
            if (size_[root(run)] < small)
                std::fill(d + begin_[run], d + end_[run], invalid);
    }
}

} // namespace stereod::sgm
