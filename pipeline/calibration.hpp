#pragma once
// The calibration of a stereo rig, in one YAML file (format in docs/calibration.md).
//
// Two forms:
//  - full: both cameras' intrinsics and distortion, R and T from left to right camera,
//    and the rectification (R1 R2 P1 P2 Q) computed from them; with the RMS and epipolar
//    error it was made with and the chessboard used;
//  - rectified-only: for cameras and datasets that deliver rectified pairs: focal length,
//    principal point(s), baseline and image size.
// Both give the rectified geometry that depth needs: Z = focal_px * baseline_m / (d + doffs_px).

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core/matx.hpp>
#include <opencv2/core/types.hpp>

#include "model/rectified_geometry.hpp"

namespace stereod {

// A calibration file that cannot be used. what() names the file, the key and the problem.
class CalibrationError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

// Throws CalibrationError with the message every calibration error has:
// "origin[:line]: [key: ]problem" (line 0: none known; key empty: the file as a whole).
// For readers of other calibration formats (pipeline/calibration_formats.hpp).
[[noreturn]] void throwCalibrationError(const std::string& origin, int line, const std::string& key,
                                        const std::string& problem);

struct CameraIntrinsics {
    cv::Matx33d camera_matrix = cv::Matx33d::eye();
    std::vector<double> distortion; // OpenCV order: k1 k2 p1 p2 [k3 [k4 k5 k6 ...]]
};

struct ChessboardSpec {
    int cols = 0; // inner corners per row, as OpenCV counts them
    int rows = 0;
    double square_m = 0.0;
};

struct StereoCalibration {
    enum class Kind { Full, RectifiedOnly };
    Kind kind = Kind::RectifiedOnly;

    RectifiedGeometry rectified;

    // Full form only.
    CameraIntrinsics left;
    CameraIntrinsics right;
    cv::Matx33d R = cv::Matx33d::eye(); // rotation from the left to the right camera
    cv::Vec3d T;                        // translation, metres
    cv::Matx33d R1 = cv::Matx33d::eye(), R2 = cv::Matx33d::eye();
    cv::Matx34d P1, P2;
    cv::Matx44d Q;
    cv::Rect valid_roi_left, valid_roi_right; // rectified pixels valid in both
    std::optional<double> rms_px;             // reprojection RMS of the stereo calibration
    std::optional<double> epipolar_error_px;  // mean epipolar error after calibration
    std::optional<ChessboardSpec> board;
};

// Reads and validates. Throws CalibrationError naming the file, the key and the problem
// (missing key, wrong matrix size, non-positive focal length or baseline, ...).
StereoCalibration loadCalibration(const std::string& path);

// Parses YAML text; `origin` names it in errors (a path, or "<string>").
StereoCalibration parseCalibration(const std::string& yaml_text, const std::string& origin);

// Writes the file (atomically: a temporary file renamed over the target). Throws
// CalibrationError when it cannot.
void saveCalibration(const StereoCalibration& calibration, const std::string& path);
// The text saveCalibration() writes (validated first; CalibrationError names `origin`).
std::string formatCalibration(const StereoCalibration& calibration, const std::string& origin);

// Throws CalibrationError unless frames of `frame_size` fit the calibration.
void checkFrameSize(const StereoCalibration& calibration, cv::Size frame_size,
                    const std::string& origin);

// Checks a calibration assembled in code with the same rules the loader applies (focal
// length and baseline positive, principal point inside the image, R a rotation, P1/P2 a
// horizontal rig, ...). Throws CalibrationError naming `origin`, the key and the problem.
void validateCalibration(const StereoCalibration& calibration, const std::string& origin);

// The rectified geometry a full calibration implies: focal = P1(0,0), principal point
// from P1, baseline = -P2(0,3) / P2(0,0), doffs = P2(0,2) - P1(0,2).
RectifiedGeometry rectifiedFromProjections(const cv::Matx34d& P1, const cv::Matx34d& P2,
                                           cv::Size image_size);

// A rectified-only calibration. cx/cy default to the image centre, (size - 1) / 2.
StereoCalibration makeRectifiedCalibration(cv::Size image_size, double focal_px, double baseline_m,
                                           std::optional<double> cx_px = std::nullopt,
                                           std::optional<double> cy_px = std::nullopt,
                                           double doffs_px = 0.0);

} // namespace stereod
