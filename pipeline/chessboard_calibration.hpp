#pragma once
// Stereo calibration from pairs of chessboard images: corners in both images of every
// pair, each camera's intrinsics, the pose of the right camera relative to the left, and
// the rectification, as a full StereoCalibration (pipeline/calibration.hpp).
//
// The method, and why (measured on the 13 real pairs of OpenCV's sample data, 640x480,
// 9x6 inner corners; docs/calibration.md has the whole table):
//  - Corners: cv::findChessboardCorners, then cv::cornerSubPix on each corner with a
//    window sized to that corner's neighbourhood (see findBoardCorners). Stereo RMS
//    0.194 px, mean epipolar distance 0.101 px, 0.27 s for all 26 images. The sector-based
//    detector (cv::findChessboardCornersSB with CALIB_CB_ACCURACY) gave 0.254 px and
//    0.102 px and took 20 times as long; with CALIB_CB_EXHAUSTIVE too it missed a board.
//    The fixed 11x11 window of OpenCV's stereo_calib sample gave 0.445 px and 0.131 px.
//  - Distortion: k1 k2 p1 p2 (k3 fixed at 0). Estimating k3 gave the same errors to the
//    third decimal; the rational model fitted coefficients of -4.5 and +15.6 and rectified
//    rows worse (0.131 px against 0.097 px); without tangential terms, 0.133 px.
//  - Each camera alone (cv::calibrateCamera), then cv::stereoCalibrate refining both
//    cameras and R, T together from there (CALIB_USE_INTRINSIC_GUESS): epipolar distance
//    0.101 px, against 0.106 px with the intrinsics fixed (CALIB_FIX_INTRINSIC).
//
// Reentrant: no state outside the arguments.

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "pipeline/calibration.hpp"

namespace stereod {

// A chessboard calibration that cannot be made from the given images: unreadable files,
// images of differing sizes, too few usable pairs, a board size found nowhere, a rig the
// service cannot use. what() names the files and numbers involved.
class ChessboardCalibrationError : public CalibrationError {
  public:
    using CalibrationError::CalibrationError;
};

struct ChessboardCalibrationOptions {
    ChessboardSpec board; // inner corners as OpenCV counts them; square side in metres
    // cv::stereoRectify's free scaling, 0..1: 0 zooms the rectified images so that every
    // pixel has image data (the edges are cropped away); 1 keeps every raw pixel (black
    // borders where the undistorted image does not reach). Values between mix the two.
    double alpha = 0.0;
    // Fewest usable pairs (board found in both images, not an outlier) to calibrate from.
    // Measured on the sample pairs: held-out epipolar distance 0.130 px mean (worst
    // 0.188 px) when calibrating from 3 pairs, 0.112 px (0.141 px) from 6, 0.105-0.109 px
    // from 10-12.
    int min_pairs = 6;
    // A pair is an outlier when its reprojection RMS (both cameras) lies above
    // median + outlier_mads * sigma, sigma = 1.4826 * MAD of all pairs' RMS, AND above
    // outlier_floor_px: a pair at 0.3 px among pairs at 0.18 px is not worth dropping.
    double outlier_mads = 3.0;
    double outlier_floor_px = 0.5;
};

// One pair of images and what became of it.
struct PairReport {
    std::string left_path;
    std::string right_path;
    bool left_found = false; // the whole board found in the left image
    bool right_found = false;
    // Corner positions in the raw images (pixels), row by row as the board's object
    // points are laid out; empty where the board was not found.
    std::vector<cv::Point2f> left_corners;
    std::vector<cv::Point2f> right_corners;
    bool used = false;     // part of the final calibration
    std::string rejection; // why the pair was left out; empty when used
    // Reprojection RMS of this pair in each camera, in the stereo fit it was last part of
    // (for an outlier, the fit that found it out).
    std::optional<double> left_rms_px;
    std::optional<double> right_rms_px;
    // With the final calibration, for every pair whose board was found in both images:
    // mean |y_left - y_right| of the corners after rectification (rectified pixels) ...
    std::optional<double> epipolar_error_px;
    // ... and mean distance of each undistorted right corner to the epipolar line of its
    // left corner (fundamental matrix of the calibration, raw pixel scale).
    std::optional<double> epipolar_distance_px;
};

struct ChessboardCalibrationResult {
    // kind Full, board, rms_px and epipolar_error_px filled; validated.
    StereoCalibration calibration;
    std::vector<PairReport> pairs; // in the order given
    int pairs_used = 0;
    int outliers_dropped = 0;
    double left_rms_px = 0.0; // each camera calibrated alone (cv::calibrateCamera)
    double right_rms_px = 0.0;
    double rms_px = 0.0; // stereo reprojection RMS over the used pairs
    // Mean over all corners of the used pairs of PairReport::epipolar_error_px: how far
    // apart the rows of matching points are after rectification, which is what the
    // matchers depend on. Written to the calibration file as epipolar_error_px.
    double epipolar_error_px = 0.0;
    // Mean over the same corners of PairReport::epipolar_distance_px. (OpenCV's
    // stereo_calib sample adds the distances in both images, about twice this figure.)
    double epipolar_distance_px = 0.0;
    double baseline_m = 0.0; // |T|
};

// Progress while corners are searched: called once per pair after both images were
// searched, with its 1-based index and the number of pairs.
struct CornerProgress {
    int index = 0;
    int count = 0;
    const PairReport* pair = nullptr;
};
using CornerProgressCallback = std::function<void(const CornerProgress&)>;

// Checks options before any image is searched (a caller that collects views first, as
// live calibration does, refuses a bad board at once). Throws std::invalid_argument
// naming the option; calibrateFromCorners and calibrateChessboard check the same.
void validateChessboardOptions(const ChessboardCalibrationOptions& options);

// Finds the board's inner corners in a grayscale image, refined to sub-pixel accuracy:
// cv::findChessboardCorners, then cv::cornerSubPix on each corner with a half window of
// 0.3 times the distance from the corner to the nearest board line that does not pass
// through it (at least 2 px), so that the window never takes in the edges of another
// corner whatever the board's distance and tilt. (Measured: 0.35 of that distance gives
// the same accuracy, 0.40 and more lets neighbouring edges in and the RMS climbs from
// 0.19 px to 0.27-3 px.) Returns false, leaving `corners` empty, when the whole board is
// not found. `gray` must be CV_8UC1 (std::invalid_argument otherwise).
bool findBoardCorners(const cv::Mat& gray, cv::Size inner_corners,
                      std::vector<cv::Point2f>& corners);

// As findBoardCorners, for images that arrive faster than a full-size search keeps up
// with (live calibration): the board is searched in a copy shrunk to `detect_width_px`
// wide (area interpolation), and the corners found there are scaled back and refined at
// full size exactly as findBoardCorners refines them. An image no wider than
// `detect_width_px` is searched at full size. A board too small to be found in the shrunk
// copy is not found.
bool findBoardCornersFast(const cv::Mat& gray, cv::Size inner_corners,
                          std::vector<cv::Point2f>& corners, int detect_width_px = 640);

// The rectified pixels of one camera that have raw image data, as an axis-aligned
// rectangle: every pixel inside maps into the raw image (checked pixel by pixel, unlike
// the sparse border grid behind cv::stereoRectify's ROIs). What valid_roi_left/right hold.
cv::Rect validRectifiedRegion(const CameraIntrinsics& camera, const cv::Matx33d& rectification,
                              const cv::Matx34d& projection, cv::Size image_size);

// Calibrates from pairs whose corners are already in `pairs` (left_found/right_found and
// the corner lists filled, e.g. by findBoardCorners); pairs without the board in both
// images are kept in the report, rejected with the reason. Drops outliers once and
// calibrates again without them. Throws ChessboardCalibrationError (too few usable pairs,
// a board found nowhere, a rig the service cannot use) and std::invalid_argument (options).
ChessboardCalibrationResult calibrateFromCorners(std::vector<PairReport> pairs, cv::Size image_size,
                                                 const ChessboardCalibrationOptions& options);

// Reads the pairs (left_paths[i] with right_paths[i]), searches the corners and
// calibrates. A pair without the board in both images is reported (progress, the pair's
// rejection) and skipped whatever its size; the pairs used must all have the size of the
// first one used. Throws ChessboardCalibrationError naming the file for an unreadable
// image, the odd pair, its file and the sizes when a used pair's size differs, and as
// calibrateFromCorners.
ChessboardCalibrationResult calibrateChessboard(const std::vector<std::string>& left_paths,
                                                const std::vector<std::string>& right_paths,
                                                const ChessboardCalibrationOptions& options,
                                                const CornerProgressCallback& progress = {});

// The pair rectified side by side (left | right, BGR), a horizontal line every
// `line_step_px` rows across both halves and the board's corners drawn where they land
// after rectification: if the calibration is right, matching corners sit on the same
// row. Raw images are grayscale, of the calibrated size; corners may be empty.
cv::Mat renderRectifiedPreview(const StereoCalibration& calibration, const cv::Mat& left_raw,
                               const cv::Mat& right_raw, cv::Size inner_corners,
                               const std::vector<cv::Point2f>& left_corners,
                               const std::vector<cv::Point2f>& right_corners,
                               int line_step_px = 32);

// Renders the first used pair of `result` as above and writes it as PNG. Throws
// ChessboardCalibrationError naming the file when it cannot read the pair or write.
void writeRectifiedPreview(const ChessboardCalibrationResult& result, const std::string& png_path,
                           int line_step_px = 32);

} // namespace stereod
