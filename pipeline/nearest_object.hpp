#pragma once
// The nearest object in a region of a depth map: a robust percentile of the depths found
// there, or "no reading" with the reason when the data do not support a number.

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "model/reading.hpp"
#include "model/rectified_geometry.hpp"
#include "pipeline/nearest_settings.hpp"
#include "pipeline/reading_verdict.hpp"

namespace stereod {

// Throws SettingsError naming the field ("roi") when NearestSettings cannot work
// (region outside 0..1 or empty, min_depth_m >= max_depth_m, percentile outside 0..100,
// ...).
void validateNearestSettings(const NearestSettings& settings);

// The region in pixels of an image of `image_size`: x and width scale with the width,
// y and height with the height; rounded to whole pixels and clipped to the image.
cv::Rect regionPixels(const RegionOfInterest& roi, cv::Size image_size);

// Index into the ascending-sorted in-range depths that the percentile designates:
// floor(percentile / 100 * (count - 1)). count must be > 0.
size_t percentileIndex(double percentile, size_t count);

// What a region sees near the image's left edge. At column x the right image holds
// disparities up to x (less kLeftEdgeMarginPx, the pixels a matcher keeps clear of the
// edge of its search): a surface nearer than that there lies outside the right image,
// and no matcher can see it however near it is (docs/configuration.md).
inline constexpr int kLeftEdgeMarginPx = 4;
struct LeftEdgeView {
    int first_column = 0; // the region's left column
    int columns = 0;      // the region's width in pixels
    // Of those, the columns that cannot see as near as the range measures (from the left).
    int short_columns = 0;
    // The nearest depth the region's left column sees, and its last short column, metres;
    // +inf where a column sees nothing.
    double nearest_seen_m = std::numeric_limits<double>::infinity();
    double last_short_seen_m = std::numeric_limits<double>::infinity();
};
LeftEdgeView leftEdgeView(const cv::Rect& region, int last_disparity_px,
                          const RectifiedGeometry& geometry);
// The region's pixels in the columns that cannot see as near as distance_m (0 for no
// distance): where a surface at that distance, or nearer, would go unseen.
uint32_t outOfViewPixels(const cv::Rect& region, double distance_m,
                         const RectifiedGeometry& geometry);

// The facts of a processed pair's region for judgeReading(): the measurement and the
// thresholds of `settings`.
ReadingFacts regionFacts(const RegionMeasurement& region, const NearestSettings& settings,
                         const NearFieldFacts& near, int64_t stamp_ns, uint64_t frame);

// Reads the nearest object off depth maps, one after another.
// Thread-bound: keeps a scratch buffer between calls.
class NearestObjectFinder {
  public:
    // Reserves the scratch buffer for a region of at most `max_region_pixels`, so that
    // find() does not allocate for images up to that size.
    explicit NearestObjectFinder(size_t max_region_pixels = 0);

    // What the region of a depth map holds: its valid and in-range pixels, the configured
    // percentile of the in-range depths (with the inferred ones when nearer), and the
    // near-field evidence.
    // depth_m: CV_32FC1, metres, invalid = 0 (NaN and +inf count as invalid too);
    // confidence (CV_8UC1, or empty: all trusted) drops pixels below min_confidence;
    // near_field (CV_8UC1, or empty: none) holds the matcher's near-field evidence
    // (MatchOutput::near_field: 1 nearer than the range, 2 nearer than the extended range);
    // inferred_depth_m (CV_32FC1, or empty: none), where depth_m has none, the nearest the
    // pixel may be by other evidence, 0 elsewhere: the ray past a near edge for a surface
    // hidden from the right camera (pipeline/hidden_surfaces.hpp), or the matcher's coarser
    // estimate (MatchOutput::coarse_only_px). Not valid pixels; the percentile is the
    // nearer of the in-range depths' and of those depths with the inferred ones.
    RegionMeasurement measure(const cv::Mat& depth_m, const cv::Mat& confidence,
                              const cv::Mat& near_field, const cv::Mat& inferred_depth_m,
                              const NearestSettings& settings);

    // The reading of a processed pair from its region alone (judgeReading() with the
    // region's facts; the worker adds the rest): stamp_ns, frame, the fractions, and either
    // distance_m or the reason there is none.
    Reading find(const cv::Mat& depth_m, const cv::Mat& confidence, const cv::Mat& near_field,
                 const cv::Mat& inferred_depth_m, const NearestSettings& settings,
                 const NearFieldFacts& near, int64_t stamp_ns, uint64_t frame);
    // The same from the depths alone: no confidence, near-field evidence or inferred depths.
    Reading find(const cv::Mat& depth_m, const NearestSettings& settings, int64_t stamp_ns,
                 uint64_t frame)
    {
        return find(depth_m, cv::Mat(), cv::Mat(), cv::Mat(), settings, NearFieldFacts{}, stamp_ns,
                    frame);
    }

  private:
    // What measure() counted in one row of the region.
    struct RowCounts {
        uint32_t valid = 0, in_range_near = 0, in_range_far = 0, inferred = 0,
                 inferred_in_range = 0;
        uint32_t nearer = 0, nearer_extended = 0;
        float nearest_inferred = std::numeric_limits<float>::infinity();
    };
    // The last percentile times this: the cut below which the next frame's percentile
    // most likely lies.
    static constexpr double kCutMargin = 1.25;
    // Per row of the region, a slot of its width in each: the row's in-range depths at or
    // below cut_m_, those beyond it, and its inferred depths within the range. depths_
    // then gathers what the selections need. Reused.
    std::vector<float> depths_;
    std::vector<float> far_;
    std::vector<float> inferred_;
    std::vector<RowCounts> rows_;
    float cut_m_ = std::numeric_limits<float>::infinity();
};

} // namespace stereod
