#pragma once
// The nearest object in a region of a depth map: a robust percentile of the depths found
// there, or "no reading" with the reason when the data do not support a number.

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "pipeline/nearest_settings.hpp"
#include "pipeline/reading.hpp"

namespace stereod {

// Throws std::invalid_argument naming the setting when NearestSettings cannot work
// (region outside 0..1 or empty, min_depth_m >= max_depth_m, percentile outside 0..100,
// ...).
void validateNearestSettings(const NearestSettings& settings);

// The region in pixels of an image of `image_size`: x and width scale with the width,
// y and height with the height; rounded to whole pixels and clipped to the image.
cv::Rect regionPixels(const RegionOfInterest& roi, cv::Size image_size);

// Index into the ascending-sorted in-range depths that the percentile designates:
// floor(percentile / 100 * (count - 1)). count must be > 0.
size_t percentileIndex(double percentile, size_t count);

// Reads the nearest object off depth maps, one after another.
// Thread-bound: keeps a scratch buffer between calls.
class NearestObjectFinder {
  public:
    // Reserves the scratch buffer for a region of at most `max_region_pixels`, so that
    // find() does not allocate for images up to that size.
    explicit NearestObjectFinder(size_t max_region_pixels = 0);

    // depth_m: CV_32FC1, metres, invalid = 0 (NaN and +inf count as invalid too).
    // Fills every field of the reading: stamp_ns, frame, the fractions, region_pixels and
    // min_valid_fraction, and either distance_m or the reason there is none:
    //  - range_limit_fraction of the region (and min_pixels) at the range's near limit
    //    -> NearerThanRange, nearer_than_m = closest_depth_m;
    //  - fewer than min_valid_fraction of the region valid -> TooFewValidPixels;
    //  - fewer than min_pixels, or than min_in_range_fraction of the region, within
    //    [min_depth_m, max_depth_m] -> NothingInRange;
    //  - else the configured percentile of the in-range depths.
    // confidence (CV_8UC1, or empty: all trusted) drops pixels below min_confidence;
    // range_limit (CV_8UC1, or empty: none) flags pixels matched at the range's near end.
    Reading find(const cv::Mat& depth_m, const cv::Mat& confidence, const cv::Mat& range_limit,
                 const NearestSettings& settings, double closest_depth_m, int64_t stamp_ns,
                 uint64_t frame);
    // The same without confidence or range flags (OpenCV's matchers, tests).
    Reading find(const cv::Mat& depth_m, const NearestSettings& settings, int64_t stamp_ns,
                 uint64_t frame)
    {
        return find(depth_m, cv::Mat(), cv::Mat(), settings, 0.0, stamp_ns, frame);
    }

  private:
    std::vector<float> in_range_; // the region's in-range depths, reused
};

} // namespace stereod
