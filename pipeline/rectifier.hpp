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
    // point CV_16SC2 + CV_16UC1). Rectified-only: no maps; the input is already rectified.
    explicit Rectifier(const StereoCalibration& calibration);

    // True when rectify() resamples (full calibration); false when it only copies.
    bool remaps() const { return !left_.xy.empty(); }

    // Rectifies one raw CV_8UC1 image, or the left camera's colour (CV_8UC3, BGR) with the
    // same maps, into `out`, which is reused when it already has the calibrated size and
    // the input's type: no allocation of any kind in steady state (see remapBilinear).
    // Inputs must have the calibrated image size; `out` must not share its buffer with
    // `raw`.
    void rectifyLeft(const cv::Mat& raw, cv::Mat& out) const;
    void rectifyRight(const cv::Mat& raw, cv::Mat& out) const;
    // Both grey images of a pair at once: the same results as the two calls above, their
    // rows shared out over the pool's threads together.
    void rectifyPair(const cv::Mat& left_raw, const cv::Mat& right_raw, cv::Mat& left_out,
                     cv::Mat& right_out) const;

  private:
    struct Maps {
        cv::Mat xy, frac; // CV_16SC2 integer coordinates, CV_16UC1 fractions
        cv::Mat offsets;  // remapOffsets() for a continuous grey image of the calibrated size
    };
    static void apply(const cv::Mat& raw, const Maps& maps, cv::Mat& out);

    Maps left_, right_;
};

// Bilinear resampling of a CV_8UC1 or CV_8UC3 image through fixed-point maps, the same
// result as cv::remap(src, out, map_xy, map_frac, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0):
//  - map_xy (CV_16SC2) holds, for every output pixel, the integer source pixel (x, y) at
//    the top left of its 2x2 neighbourhood; map_frac (CV_16UC1, same size) the sub-pixel
//    position in 1/32 pixel as fy * 32 + fx (cv::INTER_TAB_SIZE = 32), both as
//    cv::initUndistortRectifyMap or cv::convertMaps make them;
//  - a neighbour outside `src` counts as 0, so an output pixel whose whole neighbourhood
//    lies outside is 0 and one on the image's edge fades to 0.
// `out` becomes the source's type at the maps' size, reusing its buffer when it already is; it must
// not share its buffer with `src`. Rows are split across OpenCV's thread pool
// (cv::parallel_for_), which allocates nothing per call once it has started. Throws
// std::invalid_argument naming the argument when the types or sizes do not fit.
// Reentrant.
void remapBilinear(const cv::Mat& src, const cv::Mat& map_xy, const cv::Mat& map_frac,
                   cv::Mat& out);

// Where each output pixel's 2x2 neighbourhood starts in a CV_8UC1 source of src_size whose
// rows are src_step bytes apart (CV_32SC1, map_xy's size): resample::neighbourhoodOffset()
// of each, y * src_step + x where it lies wholly inside, resample::kOnTheEdge where it
// straddles the source's edge, resample::kOutside where no neighbour is inside (the pixel
// is 0). The Rectifier computes them once per camera, so that a frame's resampling loads
// one offset rather than two coordinates and a bounds test.
cv::Mat remapOffsets(const cv::Mat& map_xy, cv::Size src_size, size_t src_step);

} // namespace stereod
