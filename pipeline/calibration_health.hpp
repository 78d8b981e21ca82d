#pragma once
// How well a calibration still rectifies, measured without a chessboard: sparse features
// (ORB) matched between the rectified left and right images, and the row offset of the
// matches. After a good rectification matching points lie on the same row (offset near
// 0.1 px); a knock, heat or a loose mount moves one camera and the rows drift apart, while
// every depth still looks valid. Swapped cameras show as matches whose disparity is
// negative.
//
// Thread-bound: a CalibrationHealthChecker keeps its feature detector and buffers.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "pipeline/calibration.hpp"

namespace stereod {

struct HealthSettings {
    int max_features = 2000;         // ORB keypoints per image
    double max_row_offset_px = 24.0; // matches further apart in rows are not the same point
    int min_matches = 30;            // fewer: "unknown: not enough matches", no verdict
    // Verdict on the median and the 90th percentile of |row offset|, pixels.
    double ok_median_px = 0.5;
    double ok_p90_px = 1.5;
    double failed_median_px = 2.0;
    // Above this fraction of matches with a negative disparity the cameras are swapped.
    double swapped_fraction = 0.6;
};

enum class HealthState { Unknown, Ok, Degraded, Failed };

// "unknown", "ok", "degraded", "failed".
const char* healthStateName(HealthState state) noexcept;

// One match between the rectified images, in pixels.
struct RowMatch {
    cv::Point2f left;
    cv::Point2f right;
};

struct HealthMeasurement {
    HealthState state = HealthState::Unknown;
    // Machine code of the verdict: "not_enough_matches", "row_offset", "cameras_swapped",
    // or "" when ok.
    std::string reason;
    int matches = 0;                // matches used for the figures
    double row_offset_px = 0.0;     // signed median of right row - left row
    double row_offset_p90_px = 0.0; // 90th percentile of |right row - left row|
    double negative_disparity_fraction = 0.0;
    std::vector<RowMatch> used; // the matches behind the figures
};

// The verdict for the figures of a measurement (state and reason are set).
void classifyHealth(HealthMeasurement& measurement, const HealthSettings& settings);

class CalibrationHealthChecker {
  public:
    explicit CalibrationHealthChecker(const HealthSettings& settings = {});
    ~CalibrationHealthChecker();

    // left, right: a rectified CV_8UC1 pair of the same size.
    HealthMeasurement measure(const cv::Mat& left, const cv::Mat& right);

    const HealthSettings& settings() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The figures over several measurements (their matches pooled), classified.
HealthMeasurement poolMeasurements(const std::vector<HealthMeasurement>& measurements,
                                   const HealthSettings& settings);

// The small rotation of the right camera, about its rectified x axis (pitch: moves every
// row) and z axis (roll: moves rows in proportion to the column), that brings the rows of
// `matches` together; never about the y axis, which would shift disparities and so every
// depth. Returns the calibration with R2 (and the rectification maps made from it) turned
// by that rotation; P1, P2 and Q, hence depth, stay as they were. Throws std::invalid_argument
// when the calibration is rectified-only (there is nothing to turn) or matches are too few.
// `rotation_deg` receives the pitch and roll applied, in degrees.
StereoCalibration correctRightRotation(const StereoCalibration& calibration,
                                       const std::vector<RowMatch>& matches,
                                       cv::Vec2d* rotation_deg = nullptr);

} // namespace stereod
