#include "pipeline/sgm/speckle_filter.hpp"

#include <algorithm>
#include <cstdlib>

namespace stereod::sgm {

size_t speckleFilterBytes(int width, int height)
{
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    return area * 5 * sizeof(uint32_t);
}

SpeckleFilter::SpeckleFilter(int width, int height)
    : width_(width), height_(height),
      label_(static_cast<size_t>(width) * static_cast<size_t>(height)), stack_(label_.size()),
      stack_x_(label_.size()), parent_(label_.size()), size_(label_.size())
{
}

void SpeckleFilter::apply(int16_t* disparity, int16_t invalid, int max_step, int max_size)
{
    labelBand(disparity, invalid, max_step, 0, height_);
    removeBand(disparity, invalid, max_size, 0, height_);
}

void SpeckleFilter::labelBand(const int16_t* disparity, int16_t invalid, int max_step, int y0,
                              int y1)
{
    const size_t w = static_cast<size_t>(width_);
    const size_t begin = static_cast<size_t>(y0) * w;
    const size_t end = static_cast<size_t>(y1) * w;
    std::fill(label_.begin() + static_cast<std::ptrdiff_t>(begin),
              label_.begin() + static_cast<std::ptrdiff_t>(end), 0u);
    uint32_t* stack = stack_.data() + begin;
    uint32_t* stack_x = stack_x_.data() + begin;
    size_t start_x = static_cast<size_t>(-1);
    for (size_t start = begin; start < end; ++start) {
        if (++start_x == w)
            start_x = 0;
        if (disparity[start] == invalid || label_[start] != 0)
            continue;
        // Flood the region from `start` within the band, counting its pixels.
        const auto region = static_cast<uint32_t>(start);
        const uint32_t label = region + 1;
        size_t top = 0;
        size_t count = 0;
        stack[top] = region;
        stack_x[top++] = static_cast<uint32_t>(start_x);
        label_[start] = label;
        while (top > 0) {
            --top;
            const size_t p = stack[top];
            const size_t x = stack_x[top];
            ++count;
            const int d = disparity[p];
            const auto visit = [&](size_t q, size_t qx) {
                if (label_[q] == 0 && disparity[q] != invalid &&
                    std::abs(disparity[q] - d) <= max_step) {
                    label_[q] = label;
                    stack[top] = static_cast<uint32_t>(q);
                    stack_x[top++] = static_cast<uint32_t>(qx);
                }
            };
            if (x > 0)
                visit(p - 1, x - 1);
            if (x + 1 < w)
                visit(p + 1, x + 1);
            if (p >= begin + w)
                visit(p - w, x);
            if (p + w < end)
                visit(p + w, x);
        }
        parent_[region] = region;
        size_[region] = static_cast<uint32_t>(count);
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
                std::abs(disparity[p] - disparity[q]) > max_step)
                continue;
            const uint32_t a = root(label_[p] - 1);
            const uint32_t b = root(label_[q] - 1);
            if (a == b)
                continue;
            // The larger index joins the smaller: the roots stay ordered, the chains short.
            const uint32_t keep = std::min(a, b);
            const uint32_t join = std::max(a, b);
            parent_[join] = keep;
            size_[keep] += size_[join];
            // Shortcut the pixels' own regions to the root for the next lookups.
            parent_[label_[p] - 1] = keep;
            parent_[label_[q] - 1] = keep;
        }
    }
}

void SpeckleFilter::removeBand(int16_t* disparity, int16_t invalid, int max_size, int y0,
                               int y1) const
{
    const size_t w = static_cast<size_t>(width_);
    const auto small = static_cast<uint32_t>(std::max(0, max_size));
    for (size_t i = static_cast<size_t>(y0) * w; i < static_cast<size_t>(y1) * w; ++i)
        if (disparity[i] != invalid && size_[root(label_[i] - 1)] < small)
            disparity[i] = invalid;
}

} // namespace stereod::sgm
