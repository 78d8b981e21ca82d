#pragma once
// Undistortion and rectification of a raw pair with maps computed once.
//
// Thread-safe: after construction a Rectifier only reads its maps; callers on different
// threads must bring their own output buffers.

#include <opencv2/core/mat.hpp>

#include "pipeline/calibration.hpp"

namespace stereod {

class Rectifier {
public:
    // Full calibration: computes both cameras' maps (cv::initUndistortRectifyMap, fixed
    // point CV_16SC2 + CV_16UC1, the fast path of cv::remap). Rectified-only: no maps; the
    // input is already rectified.
    explicit Rectifier(const StereoCalibration& calibration);

    // True when rectify() resamples (full calibration); false when it only copies.
    bool remaps() const { return !left_map_xy_.empty(); }

    // Rectifies one raw CV_8UC1 image into `out`, which is reused when it already has the
    // calibrated size and type (no allocation in steady state). Both inputs must have the
    // calibrated image size.
    void rectifyLeft(const cv::Mat& raw, cv::Mat& out) const;
    void rectifyRight(const cv::Mat& raw, cv::Mat& out) const;

private:
    static void apply(const cv::Mat& raw, const cv::Mat& map_xy, const cv::Mat& map_frac,
                      cv::Mat& out);

    cv::Mat left_map_xy_, left_map_frac_;     // CV_16SC2 integer coordinates, CV_16UC1 fractions
    cv::Mat right_map_xy_, right_map_frac_;
};

} // namespace stereod
