#include "pipeline/calibration.hpp"

#include <cmath>

#include "pipeline/calibration_checks.hpp"
#include "pipeline/cv_conversions.hpp"

namespace stereod {

using namespace calibration_detail;

void throwCalibrationError(const std::string& origin, int line, const std::string& key,
                           const std::string& problem)
{
    std::string message = origin;
    // Appended piece by piece: GCC 12 at -O3 misreads `":" + std::to_string(line)` as an
    // overlapping copy (-Wrestrict).
    if (line > 0) {
        message += ':';
        message += std::to_string(line);
    }
    message += ": ";
    if (!key.empty())
        message += key + ": ";
    message += problem;
    throw CalibrationError(message);
}

RectifiedGeometry rectifiedFromProjections(const cv::Matx34d& P1, const cv::Matx34d& P2,
                                           cv::Size image_size)
{
    RectifiedGeometry g;
    g.image_size = toImageSize(image_size);
    g.focal_px = P1(0, 0);
    g.cx_px = P1(0, 2);
    g.cy_px = P1(1, 2);
    g.baseline_m = P2(0, 0) != 0.0 ? -P2(0, 3) / P2(0, 0) : 0.0;
    g.doffs_px = P2(0, 2) - P1(0, 2);
    return g;
}

void checkFrameSize(const StereoCalibration& calibration, cv::Size frame_size,
                    const std::string& origin)
{
    const cv::Size expected = toCv(calibration.rectified.image_size);
    if (frame_size != expected)
        fail(origin, 0, "image_size",
             "frames are " + describeSize(frame_size) + " but the calibration is for " +
                 describeSize(expected) + " images");
}

StereoCalibration makeRectifiedCalibration(cv::Size image_size, double focal_px, double baseline_m,
                                           std::optional<double> cx_px, std::optional<double> cy_px,
                                           double doffs_px)
{
    StereoCalibration c;
    c.kind = StereoCalibration::Kind::RectifiedOnly;
    c.rectified.image_size = toImageSize(image_size);
    c.rectified.focal_px = focal_px;
    c.rectified.baseline_m = baseline_m;
    c.rectified.cx_px = cx_px.value_or((image_size.width - 1) / 2.0);
    c.rectified.cy_px = cy_px.value_or((image_size.height - 1) / 2.0);
    c.rectified.doffs_px = doffs_px;
    validateCalibration(c, "rectified calibration");
    return c;
}

} // namespace stereod
