#pragma once
// From disparity to metric depth and to a point cloud, in the rectified left camera.
// Pure functions: thread-safe as long as each caller writes to its own outputs.

#include <vector>

#include <opencv2/core/mat.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/stereo_processor.hpp"

namespace stereod {

// disparity_px: CV_32FC1, pixels, invalid = +inf or NaN.
// depth_m: CV_32FC1 of the same size (reused when it already is), Z = f*B / (d + doffs)
// in metres; 0 where the disparity is invalid or d + doffs <= 0 (at or beyond infinity).
void disparityToDepth(const cv::Mat& disparity_px, const RectifiedGeometry& geometry,
                      cv::Mat& depth_m);

// Sets every depth beyond `max_depth_m` to 0 (invalid), in place; CV_32FC1.
void clearDepthBeyond(cv::Mat& depth_m, float max_depth_m);

// One point per valid (> 0) depth pixel (u, v): x = (u - cx) Z / f, y = (v - cy) Z / f,
// z = Z, intensity = the grey level (0..255) of the rectified left image at (u, v).
// `cloud` is cleared and refilled; its capacity is kept, and grown once to the full
// image so that later frames do not allocate.
void buildPointCloud(const cv::Mat& depth_m, const cv::Mat& left_rectified,
                     const RectifiedGeometry& geometry, std::vector<CloudPoint>& cloud);

} // namespace stereod
