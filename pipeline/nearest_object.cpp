#include "pipeline/nearest_object.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "base/percentile.hpp"
#include "base/settings_error.hpp"
#include "pipeline/row_stripes.hpp"

namespace stereod {
namespace {

[[noreturn]] void invalid(const std::string& key, const std::string& problem)
{
    throw SettingsError(key, problem);
}

void fraction(const std::string& key, double value)
{
    if (!(value >= 0.0 && value <= 1.0))
        invalid(key, "must be within 0..1, got " + std::to_string(value));
}

} // namespace

void validateNearestSettings(const NearestSettings& s)
{
    fraction("roi.x", s.roi.x);
    fraction("roi.y", s.roi.y);
    fraction("roi.width", s.roi.width);
    fraction("roi.height", s.roi.height);
    if (s.roi.width <= 0.0 || s.roi.height <= 0.0)
        invalid("roi", "width and height must be > 0");
    // A little slack for fractions written with a few digits (0.33 + 0.67).
    constexpr double kSlack = 1e-9;
    if (s.roi.x + s.roi.width > 1.0 + kSlack)
        invalid("roi", "x + width must be <= 1, got " + std::to_string(s.roi.x + s.roi.width));
    if (s.roi.y + s.roi.height > 1.0 + kSlack)
        invalid("roi", "y + height must be <= 1, got " + std::to_string(s.roi.y + s.roi.height));
    if (!(s.min_depth_m >= 0.0 && std::isfinite(s.min_depth_m)))
        invalid("min_depth_m",
                "must be a finite number >= 0, got " + std::to_string(s.min_depth_m));
    if (!(s.max_depth_m > s.min_depth_m && std::isfinite(s.max_depth_m)))
        invalid("max_depth_m", "must be finite and greater than min_depth_m, got " +
                                   std::to_string(s.max_depth_m));
    if (!(s.percentile >= 0.0 && s.percentile <= 100.0))
        invalid("percentile", "must be within 0..100, got " + std::to_string(s.percentile));
    fraction("min_valid_fraction", s.min_valid_fraction);
    fraction("range_limit_fraction", s.range_limit_fraction);
    fraction("min_in_range_fraction", s.min_in_range_fraction);
    if (s.min_confidence < 0 || s.min_confidence > 255)
        invalid("min_confidence", "must be within 0..255, got " + std::to_string(s.min_confidence));
    if (s.min_pixels < 1)
        invalid("min_pixels", "must be >= 1, got " + std::to_string(s.min_pixels));
}

cv::Rect regionPixels(const RegionOfInterest& roi, cv::Size image_size)
{
    const int x0 = static_cast<int>(std::lround(roi.x * image_size.width));
    const int y0 = static_cast<int>(std::lround(roi.y * image_size.height));
    const int x1 = static_cast<int>(std::lround((roi.x + roi.width) * image_size.width));
    const int y1 = static_cast<int>(std::lround((roi.y + roi.height) * image_size.height));
    const cv::Rect rect(x0, y0, std::max(0, x1 - x0), std::max(0, y1 - y0));
    return rect & cv::Rect(0, 0, image_size.width, image_size.height);
}

size_t percentileIndex(double percentile, size_t count)
{
    return lowerLinearIndex(percentile, count);
}

NearestObjectFinder::NearestObjectFinder(size_t max_region_pixels)
    : depths_(max_region_pixels), far_(max_region_pixels), inferred_(max_region_pixels)
{
}

LeftEdgeView leftEdgeView(const cv::Rect& region, int last_disparity_px,
                          const RectifiedGeometry& geometry)
{
    LeftEdgeView view;
    view.first_column = region.x;
    view.columns = region.width;
    // Column x sees disparities up to x - margin: the range's last from last + margin on.
    view.short_columns =
        std::clamp(last_disparity_px + kLeftEdgeMarginPx - region.x, 0, region.width);
    // The nearest depth column x sees: that of its largest disparity.
    const auto seen_at = [&](int x) {
        const int largest = x - kLeftEdgeMarginPx;
        return largest + geometry.doffs_px > 0.0 ? geometry.depthFromDisparity(largest)
                                                 : std::numeric_limits<double>::infinity();
    };
    view.nearest_seen_m = seen_at(region.x);
    view.last_short_seen_m = seen_at(region.x + std::max(view.short_columns, 1) - 1);
    return view;
}

uint32_t outOfViewPixels(const cv::Rect& region, double distance_m,
                         const RectifiedGeometry& geometry)
{
    if (!(distance_m > 0.0) || !std::isfinite(distance_m) || geometry.focal_px <= 0.0)
        return 0;
    const double disparity = std::ceil(geometry.disparityAtDepth(distance_m));
    // Beyond any column's reach: every column is short (and the cast below stays in range).
    const int last =
        static_cast<int>(std::min(disparity, static_cast<double>(region.x + region.width)));
    const LeftEdgeView view = leftEdgeView(region, last, geometry);
    return static_cast<uint32_t>(view.short_columns) * static_cast<uint32_t>(region.height);
}

ReadingFacts regionFacts(const RegionMeasurement& region, const NearestSettings& settings,
                         const NearFieldFacts& near, int64_t stamp_ns, uint64_t frame)
{
    ReadingFacts facts;
    facts.pair = PairOutcome::Processed;
    facts.stamp_ns = stamp_ns;
    facts.frame = frame;
    facts.region = region;
    facts.min_valid_fraction = settings.min_valid_fraction;
    facts.min_pixels = static_cast<uint32_t>(settings.min_pixels);
    facts.min_in_range_fraction = settings.min_in_range_fraction;
    facts.near_evidence_fraction = settings.range_limit_fraction;
    facts.near_field = near;
    return facts;
}

RegionMeasurement NearestObjectFinder::measure(const cv::Mat& depth_m, const cv::Mat& confidence,
                                               const cv::Mat& near_field,
                                               const cv::Mat& inferred_depth_m,
                                               const NearestSettings& settings)
{
    CV_Assert(depth_m.type() == CV_32FC1);
    CV_Assert(confidence.empty() ||
              (confidence.type() == CV_8UC1 && confidence.size() == depth_m.size()));
    CV_Assert(near_field.empty() ||
              (near_field.type() == CV_8UC1 && near_field.size() == depth_m.size()));
    CV_Assert(inferred_depth_m.empty() ||
              (inferred_depth_m.type() == CV_32FC1 && inferred_depth_m.size() == depth_m.size()));
    RegionMeasurement m;
    const cv::Rect region = regionPixels(settings.roi, depth_m.size());
    const size_t region_pixels = static_cast<size_t>(region.area());
    m.region_pixels = static_cast<uint32_t>(region_pixels);
    if (region_pixels == 0)
        return m;
    // Each row's depths go to its own slot of region.width values, then are gathered in
    // row order: the rows are counted on OpenCV's pool. Grows once when the region is
    // larger than reserved; after that the buffers keep their size.
    if (depths_.size() < region_pixels)
        depths_.resize(region_pixels);
    if (far_.size() < region_pixels)
        far_.resize(region_pixels);
    if (inferred_.size() < region_pixels)
        inferred_.resize(region_pixels);
    if (rows_.size() < static_cast<size_t>(region.height))
        rows_.resize(static_cast<size_t>(region.height));

    const float lo = static_cast<float>(settings.min_depth_m);
    const float hi = static_cast<float>(settings.max_depth_m);
    const uint8_t min_confidence =
        static_cast<uint8_t>(std::clamp(settings.min_confidence, 0, 255));
    const auto width = static_cast<size_t>(region.width);
    const float cut = cut_m_;
    forRowStripes(0, region.height, [&](int first, int end) {
        for (int r = first; r < end; ++r) {
            const int y = region.y + r;
            const float* z = depth_m.ptr<float>(y);
            const uint8_t* conf = confidence.empty() ? nullptr : confidence.ptr<uint8_t>(y);
            const uint8_t* near = near_field.empty() ? nullptr : near_field.ptr<uint8_t>(y);
            const float* inferred_z =
                inferred_depth_m.empty() ? nullptr : inferred_depth_m.ptr<float>(y);
            float* depths = depths_.data() + static_cast<size_t>(r) * width;
            float* far_depths = far_.data() + static_cast<size_t>(r) * width;
            float* inferred_depths = inferred_.data() + static_cast<size_t>(r) * width;
            RowCounts c;
            for (int x = region.x; x < region.x + region.width; ++x) {
                if (near != nullptr && near[x] != 0) {
                    ++c.nearer;
                    c.nearer_extended += near[x] >= 2;
                }
                const float depth = z[x];
                if (!(depth > 0.0f) || !std::isfinite(depth)) {
                    // Unmeasured, but other evidence says how near it may be.
                    if (inferred_z != nullptr && inferred_z[x] > 0.0f &&
                        std::isfinite(inferred_z[x])) {
                        ++c.inferred;
                        if (inferred_z[x] >= lo && inferred_z[x] <= hi) {
                            inferred_depths[c.inferred_in_range++] = inferred_z[x];
                            c.nearest_inferred = std::min(c.nearest_inferred, inferred_z[x]);
                        }
                    }
                    continue;
                }
                if (conf != nullptr && conf[x] < min_confidence)
                    continue;
                ++c.valid;
                if (depth >= lo && depth <= hi) {
                    if (depth <= cut)
                        depths[c.in_range_near++] = depth;
                    else
                        far_depths[c.in_range_far++] = depth;
                }
            }
            rows_[static_cast<size_t>(r)] = c;
        }
    });

    // The in-range depths at or below the cut gathered first, in row order. When more than
    // the percentile's index of them lie there, the percentile is among them alone: a
    // selection over a few percent of the depths rather than all of them (the same value).
    // Only otherwise are the others gathered after them.
    size_t near_cut = 0, far = 0, inferred_in_range = 0;
    float nearest_inferred = std::numeric_limits<float>::infinity();
    for (int r = 0; r < region.height; ++r) {
        const RowCounts& c = rows_[static_cast<size_t>(r)];
        m.valid_pixels += c.valid;
        m.inferred_pixels += c.inferred;
        m.nearer_than_range_pixels += c.nearer;
        m.nearer_than_extended_pixels += c.nearer_extended;
        near_cut += c.in_range_near;
        far += c.in_range_far;
        inferred_in_range += c.inferred_in_range;
        nearest_inferred = std::min(nearest_inferred, c.nearest_inferred);
    }
    const size_t in_range = near_cut + far;
    m.in_range_pixels = static_cast<uint32_t>(in_range);
    const auto first = depths_.begin();
    const auto at = [&](size_t i) { return first + static_cast<std::ptrdiff_t>(i); };
    // Appends each row's part of `from` (its slots) at `to` onwards. From depths_ itself
    // too: a row's values move only towards the front, past slots already gathered.
    const auto gather = [&](const std::vector<float>& from, uint32_t RowCounts::*count, size_t to) {
        for (int r = 0; r < region.height; ++r) {
            const uint32_t n = rows_[static_cast<size_t>(r)].*count;
            const float* row = from.data() + static_cast<size_t>(r) * width;
            std::memmove(depths_.data() + to, row, n * sizeof(float)); // depths_ into itself too
            to += n;
        }
    };
    gather(depths_, &RowCounts::in_range_near, 0);
    size_t index = 0;
    if (in_range > 0) {
        index = percentileIndex(settings.percentile, in_range);
        if (near_cut <= index)
            gather(far_, &RowCounts::in_range_far, near_cut);
        const size_t among = near_cut > index ? near_cut : in_range;
        m.percentile_depth_m = static_cast<double>(selectNth(first, at(among), index));
    }
    // The inferred depths can only bring the reading nearer: one beyond the measured
    // percentile must not carry it farther by adding to the count. None below it cannot
    // bring it nearer (the percentile of them all is then at least the measured one), so
    // the second selection is made only when one is; and then only over the in-range
    // depths up to the measured percentile (the selection left them first) with the
    // inferred ones: the others lie at or beyond it, so a value below it has the same rank
    // among these as among all of them.
    if (inferred_in_range > 0 && in_range == 0) {
        gather(inferred_, &RowCounts::inferred_in_range, 0);
        m.percentile_depth_m = static_cast<double>(
            lowerLinearPercentile(first, at(inferred_in_range), settings.percentile));
    } else if (inferred_in_range > 0 &&
               static_cast<double>(nearest_inferred) < m.percentile_depth_m) {
        gather(inferred_, &RowCounts::inferred_in_range, index + 1);
        const size_t candidates = index + 1 + inferred_in_range;
        const size_t union_index =
            percentileIndex(settings.percentile, in_range + inferred_in_range);
        if (union_index < candidates) {
            const double with_inferred =
                static_cast<double>(selectNth(first, at(candidates), union_index));
            if (with_inferred < m.percentile_depth_m)
                m.percentile_depth_m = with_inferred;
        }
    }
    // The next frame's cut: a quarter beyond this percentile, where the scene's nearest
    // depths will most likely lie again (only the selection's cost depends on it).
    cut_m_ = in_range > 0 ? static_cast<float>(m.percentile_depth_m * kCutMargin)
                          : std::numeric_limits<float>::infinity();
    return m;
}

Reading NearestObjectFinder::find(const cv::Mat& depth_m, const cv::Mat& confidence,
                                  const cv::Mat& near_field, const cv::Mat& inferred_depth_m,
                                  const NearestSettings& settings, const NearFieldFacts& near,
                                  int64_t stamp_ns, uint64_t frame)
{
    return judgeReading(
        regionFacts(measure(depth_m, confidence, near_field, inferred_depth_m, settings), settings,
                    near, stamp_ns, frame));
}

} // namespace stereod
