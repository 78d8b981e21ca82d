#include "pipeline/rectifier.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod {

Rectifier::Rectifier(const StereoCalibration& calibration)
{
    if (calibration.kind != StereoCalibration::Kind::Full)
        return;
    const cv::Size size = calibration.rectified.image_size;
    cv::initUndistortRectifyMap(calibration.left.camera_matrix, calibration.left.distortion,
                                calibration.R1, calibration.P1, size, CV_16SC2, left_map_xy_,
                                left_map_frac_);
    cv::initUndistortRectifyMap(calibration.right.camera_matrix, calibration.right.distortion,
                                calibration.R2, calibration.P2, size, CV_16SC2, right_map_xy_,
                                right_map_frac_);
}

void Rectifier::rectifyLeft(const cv::Mat& raw, cv::Mat& out) const
{
    apply(raw, left_map_xy_, left_map_frac_, out);
}

void Rectifier::rectifyRight(const cv::Mat& raw, cv::Mat& out) const
{
    apply(raw, right_map_xy_, right_map_frac_, out);
}

void Rectifier::apply(const cv::Mat& raw, const cv::Mat& map_xy, const cv::Mat& map_frac,
                      cv::Mat& out)
{
    if (map_xy.empty()) {
        // copyTo() reuses `out` when size and type match.
        raw.copyTo(out);
        return;
    }
    // Pixels that map outside the raw image become 0; remap() reuses `out` when it
    // already has the map's size and the input's type.
    cv::remap(raw, out, map_xy, map_frac, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
}

} // namespace stereod
