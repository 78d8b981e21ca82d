#include "pipeline/sgm/speckle_filter.hpp"

#include <algorithm>
#include <cstdlib>

namespace stereod::sgm {

size_t speckleFilterBytes(int width, int height)
{
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    return area * (2 * sizeof(uint32_t) + 1) + 1;
}

SpeckleFilter::SpeckleFilter(int width, int height)
    : width_(width),
      label_(static_cast<size_t>(width) * static_cast<size_t>(height)),
      stack_(label_.size()),
      removed_(label_.size() + 1)
{
}

void SpeckleFilter::apply(int16_t* disparity, int16_t invalid, int max_step, int max_size)
{
    std::fill(label_.begin(), label_.end(), 0u);
    const size_t w = static_cast<size_t>(width_);
    const size_t area = label_.size();
    uint32_t next_label = 0;
    for (size_t start = 0; start < area; ++start) {
        if (disparity[start] == invalid)
            continue;
        if (label_[start] != 0) {
            if (removed_[label_[start]])
                disparity[start] = invalid;
            continue;
        }
        // Flood the region from `start`, counting its pixels.
        const uint32_t label = ++next_label;
        size_t top = 0;
        size_t count = 0;
        stack_[top++] = static_cast<uint32_t>(start);
        label_[start] = label;
        while (top > 0) {
            const size_t p = stack_[--top];
            ++count;
            const int d = disparity[p];
            const size_t x = p % w;
            const auto visit = [&](size_t q) {
                if (label_[q] == 0 && disparity[q] != invalid &&
                    std::abs(disparity[q] - d) <= max_step) {
                    label_[q] = label;
                    stack_[top++] = static_cast<uint32_t>(q);
                }
            };
            if (x > 0) visit(p - 1);
            if (x + 1 < w) visit(p + 1);
            if (p >= w) visit(p - w);
            if (p + w < area) visit(p + w);
        }
        removed_[label] = count < static_cast<size_t>(max_size) ? 1 : 0;
        if (removed_[label])
            disparity[start] = invalid;
    }
}

} // namespace stereod::sgm
