#pragma once
// The geometry of a rectified stereo pair: all that triangulation needs, what a
// calibration gives (pipeline/calibration.hpp) and what `status` and ROS 2's CameraInfo
// report. Z = focal_px * baseline_m / (d + doffs_px).
//
// Plain values; the member functions are pure. Units in the field names.

#include "model/image_size.hpp"

namespace stereod {

struct RectifiedGeometry {
    ImageSize image_size;
    double focal_px = 0.0; // rectified focal length, pixels
    double cx_px = 0.0;    // principal point of the rectified left camera
    double cy_px = 0.0;
    double baseline_m = 0.0; // distance between the optical centres
    // Principal point x of the right camera minus that of the left, in pixels
    // (Middlebury's "doffs"): a pixel with disparity d lies at Z = f*B / (d + doffs).
    double doffs_px = 0.0;

    // Depth in metres of disparity d (pixels); d + doffs must be > 0.
    double depthFromDisparity(double d) const { return focal_px * baseline_m / (d + doffs_px); }
    // The disparity at depth z_m: f*B/z - doffs.
    double disparityAtDepth(double z_m) const { return focal_px * baseline_m / z_m - doffs_px; }
};

} // namespace stereod
