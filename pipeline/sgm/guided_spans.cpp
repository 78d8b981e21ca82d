#include "pipeline/sgm/guided_spans.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stereod::sgm {
namespace {

constexpr int16_t kNoLane = std::numeric_limits<int16_t>::max(); // lo of no measurement
constexpr int16_t kAllLanes = std::numeric_limits<int16_t>::min();

int roundUp(int value, int step)
{
    return (value + step - 1) / step * step;
}

} // namespace

size_t GuidedSpans::memoryBytes(const CensusSgmSettings& full, const CensusSgmSettings& coarse)
{
    const size_t coarse_area =
        static_cast<size_t>(coarse.width) * static_cast<size_t>(coarse.height);
    const size_t area = static_cast<size_t>(full.width) * static_cast<size_t>(full.height);
    return coarse_area * (2 * sizeof(Window) + sizeof(LaneSpan)) + area * sizeof(LaneSpan);
}

GuidedSpans::GuidedSpans(const CensusSgmSettings& full, const CensusSgmSettings& coarse)
    : width_(full.width), height_(full.height), coarse_width_(coarse.width),
      coarse_height_(coarse.height), min_disparity_(full.min_disparity),
      num_disparities_(full.num_disparities),
      units_(roundUp(full.num_disparities, kLaneAlign) / kLaneAlign)
{
    const size_t coarse_area =
        static_cast<size_t>(coarse_width_) * static_cast<size_t>(coarse_height_);
    own_.assign(coarse_area, Window{});
    along_.assign(coarse_area, Window{});
    coarse_spans_.assign(coarse_area, LaneSpan{0, static_cast<uint8_t>(units_)});
    spans_.assign(static_cast<size_t>(width_) * static_cast<size_t>(height_),
                  LaneSpan{0, static_cast<uint8_t>(units_)});
}

LaneSpan GuidedSpans::spanOf(const Window& window) const
{
    const LaneSpan all{0, static_cast<uint8_t>(units_)};
    if (window.measured < kGuideMinMeasured || window.lo < 0)
        return all;
    const int last = num_disparities_ - 1;
    const int lo = std::min<int>(window.lo, last);
    const int hi = std::min<int>(window.hi, last);
    return {static_cast<uint8_t>(lo / kLaneAlign), static_cast<uint8_t>(hi / kLaneAlign + 1)};
}

void GuidedSpans::predict(const float* coarse_disparity, const uint8_t* coarse_limit)
{
    const int cw = coarse_width_, ch = coarse_height_;
    // Each coarse pixel's own lanes, full-resolution disparities relative to the range.
    for (size_t i = 0; i < own_.size(); ++i) {
        const float d = coarse_disparity[i];
        Window& own = own_[i];
        if (coarse_limit[i] != 0) {
            own = {kAllLanes, kAllLanes, 1};
        } else if (!std::isfinite(d)) {
            own = {kNoLane, kAllLanes, 0};
        } else {
            const float full_px = 2.0f * d;
            const int lo = static_cast<int>(std::floor(full_px)) - kGuideMarginPx - min_disparity_;
            const int hi = static_cast<int>(std::ceil(full_px)) + kGuideMarginPx - min_disparity_;
            own = {static_cast<int16_t>(std::clamp(lo, 0, 4 * kMaxDisparities)),
                   static_cast<int16_t>(std::clamp(hi, 0, 4 * kMaxDisparities)), 1};
        }
    }
    // A flagged pixel (lo = kAllLanes) makes its whole window search every lane.
    const auto gather = [](Window& into, const Window& w) {
        into.lo = w.lo == kAllLanes || into.lo == kAllLanes ? kAllLanes : std::min(into.lo, w.lo);
        into.hi = std::max(into.hi, w.hi);
        into.measured = static_cast<uint8_t>(into.measured + w.measured);
    };
    for (int y = 0; y < ch; ++y) {
        const size_t row = static_cast<size_t>(y) * static_cast<size_t>(cw);
        for (int x = 0; x < cw; ++x) {
            Window w{kNoLane, kAllLanes, 0};
            for (int dx = std::max(0, x - kGuideRadius); dx <= std::min(cw - 1, x + kGuideRadius);
                 ++dx)
                gather(w, own_[row + static_cast<size_t>(dx)]);
            along_[row + static_cast<size_t>(x)] = w;
        }
    }
    size_t searched = 0;
    for (int y = 0; y < ch; ++y) {
        const size_t row = static_cast<size_t>(y) * static_cast<size_t>(cw);
        for (int x = 0; x < cw; ++x) {
            Window w{kNoLane, kAllLanes, 0};
            for (int dy = std::max(0, y - kGuideRadius); dy <= std::min(ch - 1, y + kGuideRadius);
                 ++dy)
                gather(w, along_[static_cast<size_t>(dy) * static_cast<size_t>(cw) +
                                 static_cast<size_t>(x)]);
            const LaneSpan span = spanOf(w);
            coarse_spans_[row + static_cast<size_t>(x)] = span;
            searched += static_cast<size_t>(span.end - span.first);
        }
    }
    searched_share_ = static_cast<double>(searched) /
                      (static_cast<double>(own_.size()) * static_cast<double>(units_));
    // Each full-resolution pixel takes the span of the coarse pixel it lies in.
    for (int y = 0; y < height_; ++y) {
        const LaneSpan* coarse_row =
            coarse_spans_.data() +
            static_cast<size_t>(std::min(y / 2, ch - 1)) * static_cast<size_t>(cw);
        LaneSpan* row = spans_.data() + static_cast<size_t>(y) * static_cast<size_t>(width_);
        for (int x = 0; x < width_; ++x)
            row[x] = coarse_row[std::min(x / 2, cw - 1)];
    }
}

bool GuidedSpans::narrow(size_t i) const
{
    return spans_[i].first != 0 || spans_[i].end != units_;
}

const LaneSpan* GuidedSpans::spans() const
{
    return spans_.data();
}

double GuidedSpans::searchedShare() const
{
    return searched_share_;
}

} // namespace stereod::sgm
