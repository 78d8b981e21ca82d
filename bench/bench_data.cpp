#include "bench/bench_data.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/chessboard_calibration.hpp"
#include "pipeline/cv_conversions.hpp"

namespace stereod::bench {

namespace {

cv::Mat readGray(const std::string& path)
{
    cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (image.empty()) {
        throw std::runtime_error(path + ": cannot read the image (missing or not an image)");
    }
    return image;
}

cv::Mat resized(const cv::Mat& image, cv::Size size)
{
    const bool shrinking = size.area() < image.size().area();
    cv::Mat out;
    cv::resize(image, out, size, 0.0, 0.0, shrinking ? cv::INTER_AREA : cv::INTER_LINEAR);
    return out;
}

// The inverse of rectification for one camera: every raw pixel is undistorted and
// rotated into the rectified image, and sampled there.
cv::Mat rawFromRectified(const cv::Mat& rectified, const CameraIntrinsics& camera,
                         const cv::Matx33d& rectifying_rotation, const cv::Matx34d& projection)
{
    std::vector<cv::Point2f> raw_pixels;
    raw_pixels.reserve(static_cast<size_t>(rectified.total()));
    for (int y = 0; y < rectified.rows; ++y) {
        for (int x = 0; x < rectified.cols; ++x) {
            raw_pixels.emplace_back(static_cast<float>(x), static_cast<float>(y));
        }
    }
    std::vector<cv::Point2f> rectified_pixels;
    cv::undistortPoints(
        raw_pixels, rectified_pixels, camera.camera_matrix, camera.distortion, rectifying_rotation,
        projection, cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 1e-6));
    const cv::Mat map(rectified.size(), CV_32FC2, rectified_pixels.data());
    cv::Mat raw;
    cv::remap(rectified, raw, map, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    return raw;
}

} // namespace

const std::vector<Scene>& scenes()
{
    static const std::vector<Scene> all = {
        {"aloe", STEREOD_OPENCV_SAMPLES_DIR "/aloeL.jpg", STEREOD_OPENCV_SAMPLES_DIR "/aloeR.jpg"},
        {"tsukuba", STEREOD_SHARED_DATA_DIR "/middlebury/tsukuba/im3.png",
         STEREOD_SHARED_DATA_DIR "/middlebury/tsukuba/im4.png"},
        {"venus", STEREOD_SHARED_DATA_DIR "/middlebury/venus/im2.png",
         STEREOD_SHARED_DATA_DIR "/middlebury/venus/im6.png"},
    };
    return all;
}

const Scene& chessboardScene()
{
    static const Scene rig = {"chessboard", STEREOD_OPENCV_SAMPLES_DIR "/left01.jpg",
                              STEREOD_OPENCV_SAMPLES_DIR "/right01.jpg", true};
    return rig;
}

const StereoCalibration& chessboardRigCalibration()
{
    static const StereoCalibration calibration = [] {
        std::vector<std::string> left;
        std::vector<std::string> right;
        for (int i = 1; i <= 14; ++i) {
            if (i == 10) {
                continue; // the sample set has no pair 10
            }
            char name[32];
            std::snprintf(name, sizeof name, "/left%02d.jpg", i);
            left.push_back(std::string(STEREOD_OPENCV_SAMPLES_DIR) + name);
            std::snprintf(name, sizeof name, "/right%02d.jpg", i);
            right.push_back(std::string(STEREOD_OPENCV_SAMPLES_DIR) + name);
        }
        ChessboardCalibrationOptions options;
        options.board = {9, 6, 0.025};
        return calibrateChessboard(left, right, options).calibration;
    }();
    return calibration;
}

ImagePair loadScene(const Scene& scene, cv::Size size)
{
    return {resized(readGray(scene.left_path), size), resized(readGray(scene.right_path), size)};
}

StereoCalibration makePlausibleRigCalibration(cv::Size size)
{
    // A plausible rig, not a measured one: focal length 0.9 x width (a 58 degree
    // horizontal field of view), principal point near the centre, mild barrel distortion,
    // two cameras that differ slightly as real ones do, the right camera turned by
    // 0.5 degree, and a 6 cm baseline.
    const double w = size.width;
    const double h = size.height;
    const double f = 0.9 * w;
    StereoCalibration calibration;
    calibration.kind = StereoCalibration::Kind::Full;
    calibration.left.camera_matrix =
        cv::Matx33d(f, 0.0, (w - 1.0) / 2.0, 0.0, f, (h - 1.0) / 2.0, 0.0, 0.0, 1.0);
    calibration.right.camera_matrix = cv::Matx33d(1.004 * f, 0.0, (w - 1.0) / 2.0 + 1.5, 0.0,
                                                  1.004 * f, (h - 1.0) / 2.0 - 1.0, 0.0, 0.0, 1.0);
    calibration.left.distortion = {-0.060, 0.015, 0.0004, -0.0002, 0.0};
    calibration.right.distortion = {-0.055, 0.012, -0.0003, 0.0001, 0.0};

    constexpr double kPi = 3.14159265358979323846;
    const double angle_rad = 0.5 * kPi / 180.0;
    const cv::Vec3d axis = cv::normalize(cv::Vec3d(0.3, 0.9, 0.3));
    cv::Rodrigues(axis * angle_rad, calibration.R);
    calibration.T = cv::Vec3d(-0.06, 0.0, 0.0);

    // alpha = 0: the rectified images hold valid pixels only, as a depth service wants.
    cv::stereoRectify(calibration.left.camera_matrix, calibration.left.distortion,
                      calibration.right.camera_matrix, calibration.right.distortion, size,
                      calibration.R, calibration.T, calibration.R1, calibration.R2, calibration.P1,
                      calibration.P2, calibration.Q, cv::CALIB_ZERO_DISPARITY, 0.0, size,
                      &calibration.valid_roi_left, &calibration.valid_roi_right);

    RectifiedGeometry& geometry = calibration.rectified;
    geometry.image_size = toImageSize(size);
    geometry.focal_px = calibration.P1(0, 0);
    geometry.cx_px = calibration.P1(0, 2);
    geometry.cy_px = calibration.P1(1, 2);
    // P2(0,3) = -focal * baseline for a horizontal rig rectified by stereoRectify.
    geometry.baseline_m = std::abs(calibration.P2(0, 3) / calibration.P2(0, 0));
    geometry.doffs_px = calibration.P2(0, 2) - calibration.P1(0, 2);
    return calibration;
}

ImagePair simulateRawPair(const StereoCalibration& calibration, const ImagePair& rectified)
{
    return {rawFromRectified(rectified.left, calibration.left, calibration.R1, calibration.P1),
            rawFromRectified(rectified.right, calibration.right, calibration.R2, calibration.P2)};
}

RectifyMaps makeRectifyMaps(const StereoCalibration& calibration)
{
    const cv::Size size = toCv(calibration.rectified.image_size);
    RectifyMaps maps;
    cv::initUndistortRectifyMap(calibration.left.camera_matrix, calibration.left.distortion,
                                calibration.R1, calibration.P1, size, CV_16SC2, maps.left_xy,
                                maps.left_weights);
    cv::initUndistortRectifyMap(calibration.right.camera_matrix, calibration.right.distortion,
                                calibration.R2, calibration.P2, size, CV_16SC2, maps.right_xy,
                                maps.right_weights);
    return maps;
}

void rectifyPair(const RectifyMaps& maps, const ImagePair& raw, ImagePair& rectified)
{
    cv::remap(raw.left, rectified.left, maps.left_xy, maps.left_weights, cv::INTER_LINEAR,
              cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::remap(raw.right, rectified.right, maps.right_xy, maps.right_weights, cv::INTER_LINEAR,
              cv::BORDER_CONSTANT, cv::Scalar(0));
}

} // namespace stereod::bench
