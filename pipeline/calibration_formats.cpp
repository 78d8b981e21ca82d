#include "pipeline/calibration_formats.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include "base/system_error.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "pipeline/cv_conversions.hpp"

namespace stereod {
namespace {

[[noreturn]] void fail(const std::string& path, int line, const std::string& key,
                       const std::string& problem)
{
    throwCalibrationError(path, line, key, problem);
}

std::string readText(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in)
        fail(path, 0, "", std::string("cannot open: ") + errnoText(errno));
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

// The Q that cv::stereoRectify gives for projections P1, P2 of a horizontal rig.
cv::Matx44d disparityToDepth(const cv::Matx34d& P1, const cv::Matx34d& P2)
{
    const double tx = P2(0, 3) / P2(0, 0); // -baseline
    return {1, 0, 0, -P1(0, 2), 0, 1, 0,         -P1(1, 2),
            0, 0, 0, P1(0, 0),  0, 0, -1.0 / tx, (P1(0, 2) - P2(0, 2)) / tx};
}

// Fills what follows from the cameras and the rectification, and checks the result.
void finish(StereoCalibration& c, cv::Size image_size, const std::string& origin)
{
    c.kind = StereoCalibration::Kind::Full;
    c.rectified = rectifiedFromProjections(c.P1, c.P2, image_size);
    // Validated before the regions are computed: they need a usable camera model.
    validateCalibration(c, origin);
    c.valid_roi_left = validRectifiedRegion(c.left, c.R1, c.P1, image_size);
    c.valid_roi_right = validRectifiedRegion(c.right, c.R2, c.P2, image_size);
}

// ---------------------------------------------------------------------------------------
// ROS camera_info

struct RosCamera {
    std::string path;
    cv::Size image_size;
    CameraIntrinsics intrinsics;
    cv::Matx33d rectification;
    cv::Matx34d projection;
};

class RosReader {
  public:
    explicit RosReader(const std::string& path) : path_(path) {}

    RosCamera read()
    {
        std::string text = readText(path_);
        // Files written through OpenCV's FileStorage start with "%YAML:1.0", which is not
        // a YAML directive yaml-cpp accepts; its "!!opencv-matrix" tags are harmless.
        if (text.rfind("%YAML:", 0) == 0)
            text.replace(0, text.find('\n'), "");
        YAML::Node root;
        try {
            root = YAML::Load(text);
        } catch (const YAML::Exception& error) {
            fail(path_, error.mark.line + 1, "", "invalid YAML: " + error.msg);
        }
        if (!root.IsMap())
            fail(path_, 0, "", "expected a camera_info mapping (image_width, camera_matrix, ...)");
        RosCamera camera;
        camera.path = path_;
        camera.image_size = {integer(root, "image_width"), integer(root, "image_height")};
        camera.intrinsics.camera_matrix = matrix<3, 3>(root, "camera_matrix");
        const YAML::Node model = root["distortion_model"];
        const std::string model_name = model ? model.as<std::string>() : "plumb_bob";
        const YAML::Node d_node = require(root, "distortion_coefficients");
        camera.intrinsics.distortion = values(d_node, "distortion_coefficients");
        const size_t n = camera.intrinsics.distortion.size();
        if (model_name == "plumb_bob") {
            if (n != 5 && n != 4 && n != 0)
                fail(path_, line(d_node), "distortion_coefficients",
                     "plumb_bob takes 5 coefficients (k1 k2 p1 p2 k3), got " + std::to_string(n));
        } else if (model_name == "rational_polynomial") {
            if (n != 8)
                fail(path_, line(d_node), "distortion_coefficients",
                     "rational_polynomial takes 8 coefficients, got " + std::to_string(n));
        } else {
            fail(path_, line(model), "distortion_model",
                 "'" + model_name +
                     "' is not supported: stereod undistorts with OpenCV's "
                     "pinhole models, plumb_bob and rational_polynomial (equidistant is the "
                     "fisheye model)");
        }
        camera.rectification = matrix<3, 3>(root, "rectification_matrix");
        camera.projection = matrix<3, 4>(root, "projection_matrix");
        return camera;
    }

  private:
    static int line(const YAML::Node& node) { return node ? node.Mark().line + 1 : 0; }

    YAML::Node require(const YAML::Node& root, const char* key) const
    {
        const YAML::Node node = root[key];
        if (!node)
            fail(path_, 0, key, "missing key");
        return node;
    }

    int integer(const YAML::Node& root, const char* key) const
    {
        const YAML::Node node = require(root, key);
        try {
            return node.as<int>();
        } catch (const YAML::Exception&) {
            fail(path_, line(node), key, "expected a whole number");
        }
    }

    // A matrix as camera_info writes it ({rows, cols, data}) or a plain list.
    std::vector<double> values(const YAML::Node& node, const std::string& key) const
    {
        const YAML::Node data = node.IsMap() ? node["data"] : node;
        if (!data || !data.IsSequence())
            fail(path_, line(node), key, "expected a list of numbers or {rows, cols, data}");
        std::vector<double> out;
        for (const YAML::Node& item : data) {
            try {
                out.push_back(item.as<double>());
            } catch (const YAML::Exception&) {
                fail(path_, line(item), key, "not a number: '" + item.Scalar() + "'");
            }
        }
        return out;
    }

    template <int R, int C>
    cv::Matx<double, R, C> matrix(const YAML::Node& root, const char* key) const
    {
        const YAML::Node node = require(root, key);
        const std::vector<double> data = values(node, key);
        if (data.size() != static_cast<size_t>(R * C))
            fail(path_, line(node), key,
                 "expected " + std::to_string(R * C) + " values (" + std::to_string(R) + "x" +
                     std::to_string(C) + "), got " + std::to_string(data.size()));
        return cv::Matx<double, R, C>(data.data());
    }

    std::string path_;
};

std::string formatList(const double* values, int count, int per_line, int indent)
{
    std::string out = "[";
    for (int i = 0; i < count; ++i) {
        if (i > 0)
            out +=
                (i % per_line == 0) ? ",\n" + std::string(static_cast<size_t>(indent), ' ') : ", ";
        // Shortest text that reads back to the same double.
        out += fmt::format("{}", values[i]);
    }
    return out + "]";
}

template <int R, int C> std::string rosMatrix(const char* key, const cv::Matx<double, R, C>& m)
{
    return fmt::format("{}:\n  rows: {}\n  cols: {}\n  data: {}\n", key, R, C,
                       formatList(m.val, R * C, C, 9));
}

std::string rosCameraText(const std::string& name, const RosCameraInfo& info)
{
    std::string text = fmt::format("image_width: {}\nimage_height: {}\ncamera_name: {}\n",
                                   info.image_size.width, info.image_size.height, name);
    text += rosMatrix("camera_matrix", info.k);
    text += "distortion_model: " + info.distortion_model + "\n";
    text +=
        fmt::format("distortion_coefficients:\n  rows: 1\n  cols: {}\n  data: {}\n", info.d.size(),
                    formatList(info.d.data(), static_cast<int>(info.d.size()), 8, 9));
    text += rosMatrix("rectification_matrix", info.r);
    text += rosMatrix("projection_matrix", info.p);
    return text;
}

// Significant digits the value was written with: the fewest that read back to it, give or
// take the last bits of binary noise (ROS's INI parser, for one, computes its numbers and
// writes 0.99998 as 0.99998000000000009).
int significantDigits(double value)
{
    for (int digits = 1; digits < 15; ++digits) {
        const double back = std::strtod(fmt::format("{:.{}g}", value, digits).c_str(), nullptr);
        if (std::abs(back - value) <= 1e-14 * std::abs(value))
            return digits;
    }
    return 17;
}

// A rotation read from a file is one to the precision of its numbers only: ROS's writers
// (camera_calibration_parsers) print 5 or 6 significant digits, so R^T R of what they wrote
// differs from the identity by up to a few 1e-5. Within what the digits explain, R is
// replaced by the nearest rotation (SVD: U V^T) and the log says so; beyond that, R is left
// as it is and the validation refuses it.
cv::Matx33d nearestRotation(const cv::Matx33d& r, const std::string& origin, const char* key)
{
    const cv::Matx33d rtr = r.t() * r;
    double worst = 0.0;
    // The writer's precision: the most significant digits any element needed (its own
    // trailing zeros, or a value that rounded to 1, show fewer).
    int digits = 1;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            worst = std::max(worst, std::abs(rtr(i, j) - (i == j ? 1.0 : 0.0)));
            if (r(i, j) != 0.0)
                digits = std::max(digits, significantDigits(r(i, j)));
        }
    }
    // Half a unit in the last of those digits, for the largest elements (up to 1).
    double half_unit = 0.0;
    for (const double x : r.val) {
        if (x != 0.0)
            half_unit = std::max(
                half_unit, 0.5 * std::pow(10.0, std::floor(std::log10(std::abs(x))) - digits + 1));
    }
    // Each element of R^T R sums three products of elements up to 1: six rounding errors.
    const double explained = 6.0 * half_unit;
    if (worst <= 1e-15 || worst > explained || cv::determinant(r) <= 0.0)
        return r;
    cv::Mat w, u, vt;
    cv::SVD::compute(cv::Mat(r), w, u, vt);
    const cv::Mat nearest = u * vt;
    spdlog::info("{}: {}: re-orthonormalized: R^T R differed from the identity by {:.3g}, which "
                 "the precision of its numbers explains ({} significant digits, rounding "
                 "errors up to {:.2g})",
                 origin, key, worst, digits, half_unit);
    return cv::Matx33d(nearest.ptr<double>());
}

RosCameraInfo rosCamera(cv::Size size, const CameraIntrinsics& camera,
                        const cv::Matx33d& rectification, const cv::Matx34d& projection,
                        const std::string& origin)
{
    RosCameraInfo info;
    info.image_size = size;
    info.d = camera.distortion;
    info.distortion_model = "plumb_bob";
    if (info.d.size() <= 5) {
        info.d.resize(5, 0.0);
    } else if (info.d.size() == 8) {
        info.distortion_model = "rational_polynomial";
    } else {
        fail(origin, 0, "distortion",
             std::to_string(info.d.size()) + " coefficients have no ROS distortion model "
                                             "(plumb_bob takes 5, rational_polynomial 8)");
    }
    info.k = camera.camera_matrix;
    info.r = rectification;
    info.p = projection;
    return info;
}

void writeText(const std::string& path, const std::string& text)
{
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (out)
        out << text;
    if (!out || !out.flush())
        fail(path, 0, "", std::string("cannot write: ") + errnoText(errno));
}

// ---------------------------------------------------------------------------------------
// OpenCV FileStorage

cv::Mat readMatrix(const cv::FileStorage& fs, const std::string& path, const char* key, int rows,
                   int cols)
{
    const cv::FileNode node = fs[key];
    if (node.empty())
        fail(path, 0, key, "missing key");
    cv::Mat m;
    try {
        node >> m;
    } catch (const cv::Exception& error) {
        fail(path, 0, key, "not a matrix: " + error.err);
    }
    if (m.empty() || (rows > 0 && (m.rows != rows || m.cols != cols)))
        fail(path, 0, key,
             "expected a " + std::to_string(rows) + "x" + std::to_string(cols) + " matrix, got " +
                 std::to_string(m.rows) + "x" + std::to_string(m.cols));
    m.convertTo(m, CV_64F);
    return m;
}

cv::FileStorage openStorage(const std::string& path)
{
    readText(path); // names the file and errno when it cannot be opened
    try {
        cv::FileStorage fs(path, cv::FileStorage::READ);
        if (!fs.isOpened())
            fail(path, 0, "", "not an OpenCV FileStorage file");
        return fs;
    } catch (const cv::Exception& error) {
        fail(path, 0, "", "not an OpenCV FileStorage file: " + error.err);
    }
}

std::vector<double> distortionFrom(const cv::Mat& d, const std::string& path, const char* key)
{
    if (d.rows != 1 && d.cols != 1)
        fail(path, 0, key, "expected a row or column of coefficients");
    return {d.ptr<double>(), d.ptr<double>() + d.total()};
}

} // namespace

StereoCalibration calibrationFromRosCameraInfo(const RosCameraInfo& left,
                                               const RosCameraInfo& right,
                                               const std::string& left_origin,
                                               const std::string& right_origin)
{
    if (left.image_size != right.image_size)
        fail(right_origin, 0, "image_width",
             "the right camera's images are " + std::to_string(right.image_size.width) + "x" +
                 std::to_string(right.image_size.height) + " but the left's (" + left_origin +
                 ") are " + std::to_string(left.image_size.width) + "x" +
                 std::to_string(left.image_size.height));
    if (left.p(0, 3) != 0.0 && right.p(0, 3) == 0.0)
        fail(left_origin, 0, "projection_matrix",
             "this is the right camera of the pair (Tx = " + fmt::format("{}", left.p(0, 3)) +
                 " is not 0): are the left and right files swapped?");

    for (const auto* camera : {&left, &right}) {
        if (camera->distortion_model != "plumb_bob" &&
            camera->distortion_model != "rational_polynomial")
            fail(camera == &left ? left_origin : right_origin, 0, "distortion_model",
                 "'" + camera->distortion_model +
                     "' is not supported: stereod undistorts with "
                     "OpenCV's pinhole models, plumb_bob and rational_polynomial");
    }
    StereoCalibration c;
    c.left.camera_matrix = left.k;
    c.left.distortion = left.d;
    c.right.camera_matrix = right.k;
    c.right.distortion = right.d;
    c.R1 = nearestRotation(left.r, left_origin, "rectification_matrix");
    c.R2 = nearestRotation(right.r, right_origin, "rectification_matrix");
    c.P1 = left.p;
    c.P2 = right.p;
    // Both rectified frames are the same up to the baseline: X_rect_right = X_rect_left +
    // (Tx, Ty, 0), X_rect = R_i X_i.
    c.R = c.R2.t() * c.R1;
    const cv::Vec3d shift(c.P2(0, 3) / c.P2(0, 0), c.P2(1, 3) / c.P2(1, 1), 0.0);
    c.T = c.R2.t() * shift;
    c.Q = disparityToDepth(c.P1, c.P2);
    finish(c, left.image_size, left_origin + " + " + right_origin);
    return c;
}

ros2::CameraInfo cameraInfoMessage(const RosCameraInfo& info)
{
    ros2::CameraInfo m;
    m.width = static_cast<uint32_t>(info.image_size.width);
    m.height = static_cast<uint32_t>(info.image_size.height);
    m.distortion_model = info.distortion_model;
    m.d = info.d;
    std::copy(info.k.val, info.k.val + 9, m.k.begin());
    std::copy(info.r.val, info.r.val + 9, m.r.begin());
    std::copy(info.p.val, info.p.val + 12, m.p.begin());
    return m;
}

RosCameraInfo rosCameraInfoFromMessage(const ros2::CameraInfo& message)
{
    RosCameraInfo info;
    info.image_size = cv::Size(static_cast<int>(message.width), static_cast<int>(message.height));
    info.distortion_model = message.distortion_model;
    info.d = message.d;
    info.k = cv::Matx33d(message.k.data());
    info.r = cv::Matx33d(message.r.data());
    info.p = cv::Matx34d(message.p.data());
    return info;
}

namespace {

// The checks of calibrationFromCameraInfoMessages() on one message, in its fields' names.
void checkCameraInfoMessage(const ros2::CameraInfo& m, const std::string& origin)
{
    constexpr uint32_t kLargest = 8192; // the largest frame any source may have
    if (m.width == 0 || m.height == 0 || m.width > kLargest || m.height > kLargest)
        fail(origin, 0, m.width == 0 || m.width > kLargest ? "width" : "height",
             "the image is " + std::to_string(m.width) + "x" + std::to_string(m.height) +
                 ", not 1 to 8192 pixels each way");
    std::size_t coefficients = 0;
    if (m.distortion_model == "plumb_bob")
        coefficients = 5;
    else if (m.distortion_model == "rational_polynomial")
        coefficients = 8;
    else
        fail(origin, 0, "distortion_model",
             "'" + m.distortion_model +
                 "' is not supported: stereod undistorts with OpenCV's pinhole models, "
                 "plumb_bob (5 coefficients) and rational_polynomial (8)");
    if (m.d.size() != coefficients)
        fail(origin, 0, "d",
             std::to_string(m.d.size()) + " coefficients for " + m.distortion_model +
                 ", which has " + std::to_string(coefficients));
    const auto finite = [&origin](const char* field, const double* values, std::size_t count) {
        for (std::size_t i = 0; i < count; ++i)
            if (!std::isfinite(values[i]))
                fail(origin, 0, fmt::format("{}[{}]", field, i),
                     fmt::format("{} is not a finite number", values[i]));
    };
    finite("d", m.d.data(), m.d.size());
    finite("k", m.k.data(), m.k.size());
    finite("r", m.r.data(), m.r.size());
    finite("p", m.p.data(), m.p.size());
    if (m.binning_x > 1 || m.binning_y > 1)
        fail(origin, 0, m.binning_x > 1 ? "binning_x" : "binning_y",
             "binned images (" + std::to_string(m.binning_x) + "x" + std::to_string(m.binning_y) +
                 ") are not supported: the calibration must be for the images as they come");
    const bool whole = m.roi.width == 0 || m.roi.height == 0 ||
                       (m.roi.x_offset == 0 && m.roi.y_offset == 0 && m.roi.width == m.width &&
                        m.roi.height == m.height);
    if (!whole)
        fail(origin, 0, "roi",
             "a region of interest (" + std::to_string(m.roi.width) + "x" +
                 std::to_string(m.roi.height) + " at " + std::to_string(m.roi.x_offset) + "," +
                 std::to_string(m.roi.y_offset) +
                 ") is not supported: the images must be the full sensor's");
}

} // namespace

StereoCalibration calibrationFromCameraInfoMessages(const ros2::CameraInfo& left,
                                                    const ros2::CameraInfo& right,
                                                    const std::string& left_origin,
                                                    const std::string& right_origin)
{
    checkCameraInfoMessage(left, left_origin);
    checkCameraInfoMessage(right, right_origin);
    return calibrationFromRosCameraInfo(rosCameraInfoFromMessage(left),
                                        rosCameraInfoFromMessage(right), left_origin, right_origin);
}

StereoCalibration importRosCameraInfo(const std::string& left_path, const std::string& right_path)
{
    const RosCamera left = RosReader(left_path).read();
    const RosCamera right = RosReader(right_path).read();
    auto info = [](const RosCamera& camera) {
        RosCameraInfo i;
        i.image_size = camera.image_size;
        i.d = camera.intrinsics.distortion;
        i.k = camera.intrinsics.camera_matrix;
        i.r = camera.rectification;
        i.p = camera.projection;
        return i;
    };
    return calibrationFromRosCameraInfo(info(left), info(right), left_path, right_path);
}

std::pair<RosCameraInfo, RosCameraInfo> rosCameraInfoPair(const StereoCalibration& calibration,
                                                          const std::string& left_origin,
                                                          const std::string& right_origin)
{
    const cv::Size size = toCv(calibration.rectified.image_size);
    if (calibration.kind == StereoCalibration::Kind::Full) {
        return {rosCamera(size, calibration.left, calibration.R1, calibration.P1, left_origin),
                rosCamera(size, calibration.right, calibration.R2, calibration.P2, right_origin)};
    }
    const RectifiedGeometry& g = calibration.rectified;
    const double cx_right = g.cx_px + g.doffs_px;
    CameraIntrinsics left, right;
    left.camera_matrix = {g.focal_px, 0, g.cx_px, 0, g.focal_px, g.cy_px, 0, 0, 1};
    right.camera_matrix = {g.focal_px, 0, cx_right, 0, g.focal_px, g.cy_px, 0, 0, 1};
    const cv::Matx34d p1(g.focal_px, 0, g.cx_px, 0, 0, g.focal_px, g.cy_px, 0, 0, 0, 1, 0);
    const cv::Matx34d p2(g.focal_px, 0, cx_right, -g.focal_px * g.baseline_m, 0, g.focal_px,
                         g.cy_px, 0, 0, 0, 1, 0);
    return {rosCamera(size, left, cv::Matx33d::eye(), p1, left_origin),
            rosCamera(size, right, cv::Matx33d::eye(), p2, right_origin)};
}

void exportRosCameraInfo(const StereoCalibration& calibration, const std::string& left_path,
                         const std::string& right_path, const std::string& camera_name)
{
    const auto pair = rosCameraInfoPair(calibration, left_path, right_path);
    writeText(left_path, rosCameraText(camera_name + "/left", pair.first));
    writeText(right_path, rosCameraText(camera_name + "/right", pair.second));
}

StereoCalibration fullFromRectified(const StereoCalibration& rectified)
{
    if (rectified.kind != StereoCalibration::Kind::RectifiedOnly)
        throw CalibrationError("the calibration is a full one already");
    // The camera_info pair of a rectified rig says exactly this; read back, it is the full
    // form.
    const auto [left, right] = rosCameraInfoPair(rectified);
    return calibrationFromRosCameraInfo(left, right, "rectified calibration (left)",
                                        "rectified calibration (right)");
}

StereoCalibration importOpenCvStereoCalib(const std::string& intrinsics_path,
                                          const std::string& extrinsics_path, cv::Size image_size,
                                          double metres_per_unit)
{
    if (!(metres_per_unit > 0.0) || !std::isfinite(metres_per_unit))
        throw CalibrationError("metres per unit of T must be > 0, got " +
                               fmt::format("{}", metres_per_unit));
    const cv::FileStorage intrinsics = openStorage(intrinsics_path);
    const cv::FileStorage extrinsics = openStorage(extrinsics_path);
    StereoCalibration c;
    c.left.camera_matrix = cv::Matx33d(readMatrix(intrinsics, intrinsics_path, "M1", 3, 3));
    c.left.distortion =
        distortionFrom(readMatrix(intrinsics, intrinsics_path, "D1", 0, 0), intrinsics_path, "D1");
    c.right.camera_matrix = cv::Matx33d(readMatrix(intrinsics, intrinsics_path, "M2", 3, 3));
    c.right.distortion =
        distortionFrom(readMatrix(intrinsics, intrinsics_path, "D2", 0, 0), intrinsics_path, "D2");
    c.R = cv::Matx33d(readMatrix(extrinsics, extrinsics_path, "R", 3, 3));
    const cv::Mat t = readMatrix(extrinsics, extrinsics_path, "T", 0, 0);
    if (t.total() != 3)
        fail(extrinsics_path, 0, "T", "expected 3 values, got " + std::to_string(t.total()));
    c.T = cv::Vec3d(t.ptr<double>()) * metres_per_unit;
    c.R1 = cv::Matx33d(readMatrix(extrinsics, extrinsics_path, "R1", 3, 3));
    c.R2 = cv::Matx33d(readMatrix(extrinsics, extrinsics_path, "R2", 3, 3));
    c.P1 = cv::Matx34d(readMatrix(extrinsics, extrinsics_path, "P1", 3, 4));
    c.P2 = cv::Matx34d(readMatrix(extrinsics, extrinsics_path, "P2", 3, 4));
    c.P2(0, 3) *= metres_per_unit;
    c.P2(1, 3) *= metres_per_unit;
    c.Q = cv::Matx44d(readMatrix(extrinsics, extrinsics_path, "Q", 4, 4));
    c.Q(3, 2) /= metres_per_unit;
    c.Q(3, 3) /= metres_per_unit;
    finish(c, image_size, intrinsics_path + " + " + extrinsics_path);
    return c;
}

} // namespace stereod
