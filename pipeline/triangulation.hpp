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

// The point cloud of a depth map and its points' colours, the rows shared out over
// OpenCV's thread pool (row_stripes.hpp): each row's points are counted first, so that
// every stripe knows where its points go and the order is the single-threaded one.
// Thread-bound: one builder per caller; its row offsets are kept across frames.
class PointCloudBuilder {
  public:
    // One point per valid (> 0) depth pixel (u, v), in row-major order:
    // x = (u - cx) Z / f, y = (v - cy) Z / f, z = Z, intensity = the grey level (0..255) of
    // the rectified left image at (u, v). `cloud` is resized to the points; its capacity
    // is grown once to the full image so that later frames do not allocate.
    void build(const cv::Mat& depth_m, const cv::Mat& left_rectified,
               const RectifiedGeometry& geometry, std::vector<CloudPoint>& cloud);

    // The colours of the points the last build() made, in the same order: the colour
    // left image (CV_8UC3, BGR) at each valid (> 0) depth pixel, as r, g, b. `depth_m` is
    // the one build() was given (asserted): its rows' point counts are build()'s.
    // `colours` is resized, its capacity grown once to the full image.
    void colours(const cv::Mat& depth_m, const cv::Mat& left_rectified_colour,
                 std::vector<CloudColour>& colours) const;

  private:
    // row_first_[v]: the index of row v's first point; row_first_[rows]: the count.
    std::vector<size_t> row_first_;
    std::vector<float> x_factor_;       // (u - cx) / f of each column u
    const uchar* built_from_ = nullptr; // the depth the last build() counted
};

} // namespace stereod
