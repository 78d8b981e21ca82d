#pragma once
// The inputs the benchmarks run on: real stereo pairs, used by path and never copied,
// resized to the frame sizes a robot's cameras deliver, and a full calibration so that
// rectification does the work it does on a real rig.
//
// Reentrant: no shared state; each call builds its own result.

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "pipeline/calibration.hpp"

namespace stereod::bench {

// One real stereo pair on disk: either rectified by its authors (the benchmark turns it
// into what a plausible rig would capture), or raw views of a real rig that the benchmark
// calibrates from its chessboard pairs.
struct Scene {
    std::string name; // short, used in benchmark names: "aloe"
    std::string left_path;
    std::string right_path;
    bool raw_rig_views = false; // true: raw views of the chessboard rig (chessboardRig())
};

// Aloe (Middlebury 2006, from OpenCV's samples), Tsukuba and Venus (Middlebury 2001,
// from the shared data folder). Paths come from the compile definitions
// STEREOD_OPENCV_SAMPLES_DIR and STEREOD_SHARED_DATA_DIR.
const std::vector<Scene>& scenes();

// The real rig: pair 01 of OpenCV's 13 chessboard pairs (left01.jpg / right01.jpg,
// 640x480, raw views of a wide-angle stereo camera; opencv-doc samples).
const Scene& chessboardScene();

// The calibration of that rig, made by the project's own chessboard calibration
// (pipeline/chessboard_calibration.hpp) from all 13 pairs (01..14 without 10), board
// 9x6 inner corners, 25 mm squares (the sample board's square size is not published;
// depths scale with it, disparities do not), alpha 0. Computed on the first call (a few
// seconds) and kept for the process. Throws ChessboardCalibrationError when the images
// are missing or unusable.
const StereoCalibration& chessboardRigCalibration();

// A pair of CV_8UC1 images of the same size.
struct ImagePair {
    cv::Mat left;
    cv::Mat right;
};

// Reads both images as grayscale and resizes them to `size` (area averaging when
// shrinking, bilinear when enlarging). Throws std::runtime_error naming the file that
// cannot be read.
ImagePair loadScene(const Scene& scene, cv::Size size);

// A full calibration for frames of `size`: intrinsics with distortion, a small rotation
// between the cameras, and the rectification computed from them with cv::stereoRectify.
// The numbers describe a plausible rig, not a measured one; they exist so that remap has
// real distortion and rotation to undo.
StereoCalibration makePlausibleRigCalibration(cv::Size size);

// The pair the rig's cameras would have captured of a scene whose rectified views are
// `rectified`: each raw pixel takes the value of the rectified pixel it maps to (through
// the distortion and the rectifying rotation). Rectifying the result gives the scene
// back, so the matcher sees real images, not ones bent by a made-up calibration.
ImagePair simulateRawPair(const StereoCalibration& calibration, const ImagePair& rectified);

// Fixed-point rectification maps of both cameras (CV_16SC2 integer positions and CV_16UC1
// interpolation weights), as cv::initUndistortRectifyMap makes them and the pipeline's
// rectify stage uses them.
struct RectifyMaps {
    cv::Mat left_xy, left_weights;
    cv::Mat right_xy, right_weights;
};
RectifyMaps makeRectifyMaps(const StereoCalibration& calibration);

// Undistorts and rectifies a raw pair with cv::remap (bilinear, outside pixels 0), as the
// pipeline's rectify stage does; reuses the buffers of `rectified` when they fit.
void rectifyPair(const RectifyMaps& maps, const ImagePair& raw, ImagePair& rectified);

} // namespace stereod::bench
