#include "pipeline/sgm/speckle_filter.hpp"

#include <algorithm>
#include <cstdlib>

namespace stereod::sgm {
namespace {

// Two valid neighbours belong to one region when their disparities differ by at most this.
bool together(int a, int b, int max_step)
{
    return std::abs(a - b) <= max_step;
}

} // namespace

size_t speckleFilterBytes(int width, int height)
{
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    return area * 3 * sizeof(uint32_t);
}

SpeckleFilter::SpeckleFilter(int width, int height)
    : width_(width), height_(height),
      label_(static_cast<size_t>(width) * static_cast<size_t>(height)), parent_(label_.size()),
      size_(label_.size())
{
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
    // One pass in raster order joining each pixel to its left and upper neighbours when
    // they belong together (union-find): the same regions as a flood from every pixel,
    // read in memory order and without a stack.
    constexpr uint32_t kNone = UINT32_MAX;
    const size_t w = static_cast<size_t>(width_);
    for (int y = y0; y < y1; ++y) {
        const size_t row = static_cast<size_t>(y) * w;
        const int16_t* d = disparity + row;
        const int16_t* above = y > y0 ? d - w : nullptr;
        uint32_t left = kNone; // root of the left neighbour's region, if it joins
        // The label of the upper neighbour the left one joined (0: it joined none). Inside a
        // surface a pixel joins the same two regions as its left neighbour, already one:
        // that join is skipped rather than looked up again.
        uint32_t left_up_label = 0;
        for (size_t x = 0; x < w; ++x) {
            const size_t i = row + x;
            if (d[x] == invalid) {
                label_[i] = 0;
                left = kNone;
                left_up_label = 0;
                continue;
            }
            // `left` is a root: nothing has been joined since it was labelled.
            uint32_t region = left != kNone && together(d[x], d[x - 1], max_step) ? left : kNone;
            uint32_t up_label = 0;
            if (above != nullptr && above[x] != invalid && together(d[x], above[x], max_step)) {
                up_label = label_[i - w];
                if (region == kNone || up_label != left_up_label) {
                    const uint32_t up = rootHalving(up_label - 1);
                    region = region == kNone ? up : region == up ? region : join(region, up);
                }
            }
            // Whichever way it went, a pixel that met its upper neighbour now holds its region.
            left_up_label = up_label;
            if (region == kNone) {
                region = static_cast<uint32_t>(i);
                parent_[region] = region;
                size_[region] = 0;
            }
            ++size_[region];
            label_[i] = region + 1;
            left = region;
        }
    }
}

uint32_t SpeckleFilter::root(uint32_t region) const
{
    while (parent_[region] != region)
        region = parent_[region];
    return region;
}

void SpeckleFilter::joinBands(const int16_t* disparity, int16_t invalid, int max_step,
                              const int* band_starts, int bands)
{
    const size_t w = static_cast<size_t>(width_);
    for (int band = 1; band < bands; ++band) {
        const size_t below = static_cast<size_t>(band_starts[band]) * w;
        if (band_starts[band] <= 0 || band_starts[band] >= height_)
            continue;
        for (size_t x = 0; x < w; ++x) {
            const size_t q = below + x;
            const size_t p = q - w;
            if (disparity[p] == invalid || disparity[q] == invalid ||
                !together(disparity[p], disparity[q], max_step))
                continue;
            const uint32_t a = rootHalving(label_[p] - 1);
            const uint32_t b = rootHalving(label_[q] - 1);
            if (a != b)
                join(a, b);
        }
    }
}

void SpeckleFilter::removeBand(int16_t* disparity, int16_t invalid, int max_size, int y0,
                               int y1) const
{
    const size_t w = static_cast<size_t>(width_);
    const auto small = static_cast<uint32_t>(std::max(0, max_size));
    // Neighbours along a row mostly share their label: its verdict is kept for the next.
    uint32_t last_label = 0;
    bool last_small = false;
    for (size_t i = static_cast<size_t>(y0) * w; i < static_cast<size_t>(y1) * w; ++i) {
        if (disparity[i] == invalid)
            continue;
        if (label_[i] != last_label) {
            last_label = label_[i];
            last_small = size_[root(last_label - 1)] < small;
        }
        if (last_small)
            disparity[i] = invalid;
    }
}

} // namespace stereod::sgm
