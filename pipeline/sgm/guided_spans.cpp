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
    const size_t padded = static_cast<size_t>(coarse.width) + 2 * kPad;
    const size_t window = 2 * sizeof(int16_t) + sizeof(uint8_t);
    const size_t area = static_cast<size_t>(full.width) * static_cast<size_t>(full.height);
    return (2 * static_cast<size_t>(coarse.height) + 1) * padded * window +
           area * sizeof(LaneSpan) + static_cast<size_t>(full.threads) * sizeof(size_t);
}

GuidedSpans::GuidedSpans(const CensusSgmSettings& full, const CensusSgmSettings& coarse)
    : width_(full.width), height_(full.height), coarse_width_(coarse.width),
      coarse_height_(coarse.height), min_disparity_(full.min_disparity),
      num_disparities_(full.num_disparities),
      units_(roundUp(full.num_disparities, kLaneAlign) / kLaneAlign),
      threads_(std::max(1, full.threads)),
      padded_width_(static_cast<size_t>(coarse_width_) + 2 * kPad)
{
    const size_t padded_area = static_cast<size_t>(coarse_height_) * padded_width_;
    for (Windows* windows : {&own_, &along_}) {
        windows->lo.assign(padded_area, kNoLane);
        windows->hi.assign(padded_area, kAllLanes);
        windows->measured.assign(padded_area, 0);
    }
    none_.lo.assign(padded_width_, kNoLane);
    none_.hi.assign(padded_width_, kAllLanes);
    none_.measured.assign(padded_width_, 0);
    spans_.assign(static_cast<size_t>(width_) * static_cast<size_t>(height_),
                  LaneSpan{0, static_cast<uint8_t>(units_)});
    band_searched_.assign(static_cast<size_t>(threads_), 0);
}

void GuidedSpans::gatherRows(const float* coarse_disparity, const uint8_t* coarse_limit, int y0,
                             int y1)
{
    const int cw = coarse_width_;
    for (int y = y0; y < y1; ++y) {
        const size_t row = static_cast<size_t>(y) * static_cast<size_t>(cw);
        const size_t padded_row = static_cast<size_t>(y) * padded_width_ + kPad;
        int16_t* own_lo = own_.lo.data() + padded_row;
        int16_t* own_hi = own_.hi.data() + padded_row;
        uint8_t* own_measured = own_.measured.data() + padded_row;
        // Each coarse pixel's own lanes, full-resolution disparities relative to the range;
        // a flagged pixel's lo (kAllLanes, below every lane) makes its whole window search
        // every lane.
        for (int x = 0; x < cw; ++x) {
            const float d = coarse_disparity[row + static_cast<size_t>(x)];
            if (coarse_limit[row + static_cast<size_t>(x)] != 0) {
                own_lo[x] = kAllLanes;
                own_hi[x] = kAllLanes;
                own_measured[x] = 1;
            } else if (!std::isfinite(d)) {
                own_lo[x] = kNoLane;
                own_hi[x] = kAllLanes;
                own_measured[x] = 0;
            } else {
                const float full_px = 2.0f * d;
                const int lo =
                    static_cast<int>(std::floor(full_px)) - kGuideMarginPx - min_disparity_;
                const int hi =
                    static_cast<int>(std::ceil(full_px)) + kGuideMarginPx - min_disparity_;
                own_lo[x] = static_cast<int16_t>(std::clamp(lo, 0, 4 * kMaxDisparities));
                own_hi[x] = static_cast<int16_t>(std::clamp(hi, 0, 4 * kMaxDisparities));
                own_measured[x] = 1;
            }
        }
        // The window along the row: the pads stand for the pixels beyond the edges. One
        // field at a time, which the compiler makes vector code of.
        const auto along = [cw](const auto* own, auto* into, const auto& combine) {
            for (int x = 0; x < cw; ++x) {
                auto v = own[x];
                for (int dx = 1; dx <= kGuideRadius; ++dx)
                    v = combine(v, combine(own[x - dx], own[x + dx]));
                into[x] = v;
            }
        };
        along(own_lo, along_.lo.data() + padded_row,
              [](int16_t a, int16_t b) { return std::min(a, b); });
        along(own_hi, along_.hi.data() + padded_row,
              [](int16_t a, int16_t b) { return std::max(a, b); });
        along(own_measured, along_.measured.data() + padded_row,
              [](uint8_t a, uint8_t b) { return static_cast<uint8_t>(a + b); });
    }
}

size_t GuidedSpans::spanRows(int y0, int y1)
{
    const int cw = coarse_width_, ch = coarse_height_;
    const int last = num_disparities_ - 1;
    const LaneSpan all{0, static_cast<uint8_t>(units_)};
    const size_t w = static_cast<size_t>(width_);
    size_t searched = 0;
    for (int y = y0; y < y1; ++y) {
        // The rows of the window down the column, rows beyond the image measuring nothing.
        const int16_t* lo_rows[2 * kGuideRadius + 1];
        const int16_t* hi_rows[2 * kGuideRadius + 1];
        const uint8_t* measured_rows[2 * kGuideRadius + 1];
        for (int dy = -kGuideRadius; dy <= kGuideRadius; ++dy) {
            const bool inside = y + dy >= 0 && y + dy < ch;
            const Windows& from = inside ? along_ : none_;
            const size_t at =
                (inside ? static_cast<size_t>(y + dy) * padded_width_ : size_t{0}) + kPad;
            lo_rows[dy + kGuideRadius] = from.lo.data() + at;
            hi_rows[dy + kGuideRadius] = from.hi.data() + at;
            measured_rows[dy + kGuideRadius] = from.measured.data() + at;
        }
        // Full-resolution row 2y takes its spans, each coarse pixel's for two pixels.
        LaneSpan* out = spans_.data() + 2 * static_cast<size_t>(y) * w;
        LaneSpan span = all;
        for (int x = 0; x < cw; ++x) {
            int16_t lo = lo_rows[0][x], hi = hi_rows[0][x];
            uint8_t measured = measured_rows[0][x];
            for (int r = 1; r <= 2 * kGuideRadius; ++r) {
                lo = std::min(lo, lo_rows[r][x]);
                hi = std::max(hi, hi_rows[r][x]);
                measured = static_cast<uint8_t>(measured + measured_rows[r][x]);
            }
            span = all;
            if (measured >= kGuideMinMeasured && lo >= 0) {
                span.first = static_cast<uint8_t>(std::min<int>(lo, last) / kLaneAlign);
                span.end = static_cast<uint8_t>(std::min<int>(hi, last) / kLaneAlign + 1);
            }
            searched += static_cast<size_t>(span.end - span.first);
            out[2 * x] = span;
            out[2 * x + 1] = span;
        }
        std::fill(out + 2 * cw, out + w, span); // an odd width's last column
        // Row 2y + 1 the same, and an odd height's last row.
        const int rows_after = y == ch - 1 ? height_ - 2 * y - 1 : 1;
        for (int r = 1; r <= rows_after; ++r)
            std::copy(out, out + w, out + static_cast<size_t>(r) * w);
    }
    return searched;
}

void GuidedSpans::predict(const float* coarse_disparity, const uint8_t* coarse_limit,
                          BandPool* pool)
{
    const int ch = coarse_height_;
    const int bands = pool != nullptr ? std::min(threads_, ch) : 1;
    const auto each_band = [&](auto&& work) {
        if (bands > 1)
            pool->run(bands, work);
        else
            work(0);
    };
    // Every row's window along it before any window down a column reads it.
    each_band([&](int band) {
        gatherRows(coarse_disparity, coarse_limit, ch * band / bands, ch * (band + 1) / bands);
    });
    each_band([&](int band) {
        band_searched_[static_cast<size_t>(band)] =
            spanRows(ch * band / bands, ch * (band + 1) / bands);
    });
    size_t searched = 0;
    for (int band = 0; band < bands; ++band)
        searched += band_searched_[static_cast<size_t>(band)];
    searched_share_ =
        static_cast<double>(searched) / (static_cast<double>(coarse_width_) *
                                         static_cast<double>(ch) * static_cast<double>(units_));
}

double GuidedSpans::searchedShare() const
{
    return searched_share_;
}

} // namespace stereod::sgm
