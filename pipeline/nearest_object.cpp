#include "pipeline/nearest_object.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "base/percentile.hpp"
#include "base/settings_error.hpp"

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
{
    in_range_.reserve(max_region_pixels);
    inferred_.reserve(max_region_pixels);
}

namespace {

// The percentile of `values` (reordered in place); not empty.
double percentileOf(std::vector<float>& values, double percentile)
{
    return static_cast<double>(lowerLinearPercentile(values.begin(), values.end(), percentile));
}

} // namespace

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
    // Grows once when the region is larger than reserved; after that clear() keeps it.
    if (in_range_.capacity() < region_pixels)
        in_range_.reserve(region_pixels);
    if (inferred_.capacity() < region_pixels)
        inferred_.reserve(region_pixels);
    in_range_.clear();
    inferred_.clear();

    const float lo = static_cast<float>(settings.min_depth_m);
    const float hi = static_cast<float>(settings.max_depth_m);
    const uint8_t min_confidence =
        static_cast<uint8_t>(std::clamp(settings.min_confidence, 0, 255));
    uint32_t valid = 0, in_range = 0, inferred = 0, nearer = 0, nearer_extended = 0;
    for (int y = region.y; y < region.y + region.height; ++y) {
        const float* z = depth_m.ptr<float>(y);
        const uint8_t* conf = confidence.empty() ? nullptr : confidence.ptr<uint8_t>(y);
        const uint8_t* near = near_field.empty() ? nullptr : near_field.ptr<uint8_t>(y);
        const float* inferred_z =
            inferred_depth_m.empty() ? nullptr : inferred_depth_m.ptr<float>(y);
        for (int x = region.x; x < region.x + region.width; ++x) {
            if (near != nullptr && near[x] != 0) {
                ++nearer;
                nearer_extended += near[x] >= 2;
            }
            const float depth = z[x];
            if (!(depth > 0.0f) || !std::isfinite(depth)) {
                // Unmeasured, but other evidence says how near it may be.
                if (inferred_z != nullptr && inferred_z[x] > 0.0f && std::isfinite(inferred_z[x])) {
                    ++inferred;
                    if (inferred_z[x] >= lo && inferred_z[x] <= hi)
                        inferred_.push_back(inferred_z[x]);
                }
                continue;
            }
            if (conf != nullptr && conf[x] < min_confidence)
                continue;
            ++valid;
            if (depth >= lo && depth <= hi) {
                ++in_range;
                in_range_.push_back(depth);
            }
        }
    }
    m.valid_pixels = valid;
    m.in_range_pixels = in_range;
    m.inferred_pixels = inferred;
    m.nearer_than_range_pixels = nearer;
    m.nearer_than_extended_pixels = nearer_extended;
    if (!in_range_.empty())
        m.percentile_depth_m = percentileOf(in_range_, settings.percentile);
    // The inferred depths can only bring the reading nearer: one beyond the measured
    // percentile must not carry it farther by adding to the count.
    if (!inferred_.empty()) {
        in_range_.insert(in_range_.end(), inferred_.begin(), inferred_.end());
        const double with_inferred = percentileOf(in_range_, settings.percentile);
        if (m.percentile_depth_m == 0.0 || with_inferred < m.percentile_depth_m)
            m.percentile_depth_m = with_inferred;
    }
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
