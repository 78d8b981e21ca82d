// Other tools' calibration files: a ROS camera_info pair (read and written) and the files
// of OpenCV's stereo_calib sample (read), with a real calibration made from OpenCV's
// chessboard pairs. A file read back must rectify exactly as the calibration it came from.

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <unistd.h>

#include "pipeline/calibration.hpp"
#include "pipeline/calibration_formats.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/rectifier.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/files.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

const std::string kSamples = test::opencvSamplesDir() + "/";
constexpr double kSquareM = 0.025;

void writeFile(const std::string& path, const std::string& text)
{
    std::ofstream(path) << text;
}

std::string refusal(const std::function<void()>& run)
{
    return test::refusalMessage<CalibrationError>(run);
}

using test::contains;

template <int R, int C>
double maxDifference(const cv::Matx<double, R, C>& a, const cv::Matx<double, R, C>& b)
{
    return cv::norm(a, b, cv::NORM_INF);
}

class CalibrationFormatsTest : public ::testing::Test {
  protected:
    // A real full calibration: six of OpenCV's chessboard pairs.
    static void SetUpTestSuite()
    {
        std::vector<std::string> left, right;
        for (int i = 1; i <= 6; ++i) {
            char name[32];
            std::snprintf(name, sizeof name, "%02d.jpg", i);
            left.push_back(kSamples + "left" + name);
            right.push_back(kSamples + "right" + name);
        }
        ChessboardCalibrationOptions options;
        options.board = {9, 6, kSquareM};
        calibration_ = new StereoCalibration(calibrateChessboard(left, right, options).calibration);
    }
    static void TearDownTestSuite()
    {
        delete calibration_;
        calibration_ = nullptr;
    }
    static const StereoCalibration& calibration() { return *calibration_; }

    // The two rectify a raw pair to the same images, to the last grey level.
    static void expectSameRectification(const StereoCalibration& a, const StereoCalibration& b)
    {
        const cv::Mat left = cv::imread(kSamples + "left01.jpg", cv::IMREAD_GRAYSCALE);
        const cv::Mat right = cv::imread(kSamples + "right01.jpg", cv::IMREAD_GRAYSCALE);
        ASSERT_FALSE(left.empty() || right.empty());
        const Rectifier ra(a), rb(b);
        cv::Mat la, lb, rra, rrb;
        ra.rectifyLeft(left, la);
        rb.rectifyLeft(left, lb);
        ra.rectifyRight(right, rra);
        rb.rectifyRight(right, rrb);
        EXPECT_EQ(cv::norm(la, lb, cv::NORM_INF), 0.0);
        EXPECT_EQ(cv::norm(rra, rrb, cv::NORM_INF), 0.0);
    }

  private:
    static StereoCalibration* calibration_;
};

StereoCalibration* CalibrationFormatsTest::calibration_ = nullptr;

TEST_F(CalibrationFormatsTest, RosCameraInfoPairRoundTrips)
{
    const StereoCalibration& c = calibration();
    test::TempDir dir;
    const std::string left = dir.file("left.yaml"), right = dir.file("right.yaml");
    exportRosCameraInfo(c, left, right, "rig");
    const StereoCalibration back = importRosCameraInfo(left, right);

    EXPECT_EQ(back.kind, StereoCalibration::Kind::Full);
    EXPECT_EQ(back.rectified.image_size, c.rectified.image_size);
    // Written in full: the same numbers back.
    EXPECT_EQ(back.left.camera_matrix, c.left.camera_matrix);
    EXPECT_EQ(back.right.camera_matrix, c.right.camera_matrix);
    ASSERT_EQ(back.left.distortion.size(), 5u); // plumb_bob: k3 = 0 added
    for (size_t i = 0; i < 4; ++i) {
        EXPECT_EQ(back.left.distortion[i], c.left.distortion[i]);
        EXPECT_EQ(back.right.distortion[i], c.right.distortion[i]);
    }
    EXPECT_EQ(back.left.distortion[4], 0.0);
    EXPECT_EQ(back.R1, c.R1);
    EXPECT_EQ(back.R2, c.R2);
    EXPECT_EQ(back.P1, c.P1);
    EXPECT_EQ(back.P2, c.P2);
    // Recovered from the rectification: equal to rounding.
    EXPECT_LT(maxDifference(back.R, c.R), 1e-12);
    EXPECT_LT(cv::norm(back.T - c.T), 1e-12 * cv::norm(c.T));
    EXPECT_LT(maxDifference(back.Q, c.Q), 1e-9);
    EXPECT_EQ(back.rectified.focal_px, c.rectified.focal_px);
    EXPECT_EQ(back.rectified.baseline_m, c.rectified.baseline_m);
    EXPECT_EQ(back.valid_roi_left, c.valid_roi_left);
    EXPECT_EQ(back.valid_roi_right, c.valid_roi_right);
    expectSameRectification(c, back);

    const std::string text = test::readFile(left);
    EXPECT_TRUE(contains(text, "camera_name: rig/left")) << text;
    EXPECT_TRUE(contains(text, "distortion_model: plumb_bob")) << text;
}

// Depths of the two calibrations at disparities across the range agree within `relative`.
void expectSameDepths(const StereoCalibration& a, const StereoCalibration& b, double relative)
{
    for (double d : {4.0, 16.0, 64.0, 160.0}) {
        const double za = a.rectified.depthFromDisparity(d);
        EXPECT_NEAR(b.rectified.depthFromDisparity(d), za, za * relative) << "d = " << d;
    }
}

// Rewrites every number of a camera_info file with `digits` significant digits, as ROS's
// writers leave them.
void roundNumbers(const std::string& path, int digits)
{
    const std::string text = test::readFile(path);
    const std::regex number(R"(-?\d+\.\d+(e-?\d+)?)");
    std::string out;
    auto last = text.cbegin();
    for (std::sregex_iterator it(text.begin(), text.end(), number), end; it != end; ++it) {
        out.append(last, text.cbegin() + it->position());
        char buffer[64];
        std::snprintf(buffer, sizeof buffer, "%.*g", digits, std::stod(it->str()));
        out += buffer;
        last = text.cbegin() + it->position() + it->length();
    }
    out.append(last, text.cend());
    writeFile(path, out);
}

TEST_F(CalibrationFormatsTest, RosFilesWithFewDigitsImportReOrthonormalized)
{
    const StereoCalibration& c = calibration();
    test::TempDir dir;
    const std::string left = dir.file("left.yaml"), right = dir.file("right.yaml");
    exportRosCameraInfo(c, left, right, "rig");
    roundNumbers(left, 5);
    roundNumbers(right, 5);
    // Five digits: R^T R is off the identity by more than the strict check allows.
    const StereoCalibration back = importRosCameraInfo(left, right);
    const cv::Matx33d should_be_identity = back.R1.t() * back.R1;
    EXPECT_LT(maxDifference(should_be_identity, cv::Matx33d::eye()), 1e-12);
    EXPECT_LT(maxDifference(back.R1, c.R1), 1e-4);
    expectSameDepths(c, back, 1e-3);

    // A matrix that is no rotation beyond what its digits explain is still refused.
    exportRosCameraInfo(c, left, right, "rig");
    std::string text = test::readFile(left);
    const auto at = text.find("rectification_matrix:");
    ASSERT_NE(at, std::string::npos);
    const auto data = text.find("data: [", at) + 7;
    text.replace(data, text.find(']', data) - data, "0.998123, 0, 0, 0, 1, 0, 0, 0, 1");
    writeFile(left, text);
    const std::string why = refusal([&] { importRosCameraInfo(left, right); });
    EXPECT_TRUE(contains(why, "not a rotation")) << why;
}

// ROS's own tools: Debian's camera-calibration-parsers (the `convert` tool and the Python
// module). Installed by scripts/setup.sh; the test skips where they are missing.
const std::string kRosConvert = "/usr/lib/camera_calibration_parsers/convert";
const std::string kPython = "/usr/bin/python3";

TEST_F(CalibrationFormatsTest, RosOwnToolsReadOurExportAndRewriteItImportably)
{
    if (::access(kRosConvert.c_str(), X_OK) != 0)
        GTEST_SKIP() << kRosConvert << " missing (Debian package camera-calibration-parsers-tools)";
    const StereoCalibration& c = calibration();
    test::TempDir dir;
    const std::string left = dir.file("left.yaml"), right = dir.file("right.yaml");
    exportRosCameraInfo(c, left, right, "rig");

    // ROS's parser reads our export with K, D, R, P equal to ours.
    const std::string script =
        "import sys, camera_calibration_parsers as p\n"
        "for f in sys.argv[1:]:\n"
        "    name, info = p.readCalibration(f)\n"
        "    print(name, *[repr(float(v)) for m in (info.K, info.D, info.R, info.P) for v in m])\n";
    const test::ProcessResult read = test::runProcess({kPython, "-c", script, left, right});
    ASSERT_EQ(read.exit_code, 0) << read.err;
    std::istringstream lines(read.out);
    const RosCameraInfo ours[2] = {rosCameraInfoPair(c).first, rosCameraInfoPair(c).second};
    for (const RosCameraInfo& info : ours) {
        std::string name;
        lines >> name;
        EXPECT_EQ(name, &info == &ours[0] ? "rig/left" : "rig/right");
        std::vector<double> expected(info.k.val, info.k.val + 9);
        expected.insert(expected.end(), info.d.begin(), info.d.end());
        expected.insert(expected.end(), info.r.val, info.r.val + 9);
        expected.insert(expected.end(), info.p.val, info.p.val + 12);
        for (std::size_t i = 0; i < expected.size(); ++i) {
            double v = 0;
            lines >> v;
            EXPECT_EQ(v, expected[i]) << name << " value " << i;
        }
    }
    // The right camera's P[3] = -fx' * baseline, negative: ROS's sign convention.
    EXPECT_LT(ours[1].p(0, 3), 0.0);
    EXPECT_NEAR(ours[1].p(0, 3), -c.rectified.focal_px * c.rectified.baseline_m, 1e-9);

    // Rewritten by ROS's writer through its INI format (5 decimals), then imported.
    for (const std::string& side : {std::string("left"), std::string("right")}) {
        const std::string yaml = dir.file(side + ".yaml");
        const std::string ini = dir.file(side + ".ini");
        const std::string again = dir.file(side + "2.yaml");
        ASSERT_EQ(test::runProcess({kRosConvert, yaml, ini}).exit_code, 0);
        ASSERT_EQ(test::runProcess({kRosConvert, ini, again}).exit_code, 0);
    }
    const StereoCalibration back =
        importRosCameraInfo(dir.file("left2.yaml"), dir.file("right2.yaml"));
    expectSameDepths(c, back, 1e-3);
}

TEST(CalibrationFormats, ReadsARosPairAsCameraInfoWritesIt)
{
    // A rectified 752x480 module as a ROS driver publishes it: no distortion, identity
    // rectification, Tx = -fx * baseline (12 cm) in the right camera's projection. Left
    // file in the plain layout, right one as OpenCV's FileStorage writes it.
    test::TempDir dir;
    const std::string left = dir.file("left.yaml"), right = dir.file("right.yaml");
    writeFile(left, R"(image_width: 752
image_height: 480
camera_name: narrow_stereo/left
camera_matrix:
  rows: 3
  cols: 3
  data: [425.0, 0.0, 376.5, 0.0, 425.0, 239.5, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.0, 0.0, 0.0, 0.0, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [425.0, 0.0, 376.5, 0.0, 0.0, 425.0, 239.5, 0.0, 0.0, 0.0, 1.0, 0.0]
)");
    writeFile(right, R"(%YAML:1.0
image_width: 752
image_height: 480
camera_name: narrow_stereo/right
camera_matrix: !!opencv-matrix
  rows: 3
  cols: 3
  dt: d
  data: [425.0, 0.0, 376.5, 0.0, 425.0, 239.5, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients: [0.0, 0.0, 0.0, 0.0, 0.0]
rectification_matrix: !!opencv-matrix
  rows: 3
  cols: 3
  dt: d
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix: !!opencv-matrix
  rows: 3
  cols: 4
  dt: d
  data: [425.0, 0.0, 376.5, -51.0, 0.0, 425.0, 239.5, 0.0, 0.0, 0.0, 1.0, 0.0]
)");
    const StereoCalibration c = importRosCameraInfo(left, right);
    EXPECT_EQ(c.kind, StereoCalibration::Kind::Full);
    EXPECT_EQ(c.rectified.image_size, (ImageSize{752, 480}));
    EXPECT_DOUBLE_EQ(c.rectified.focal_px, 425.0);
    EXPECT_DOUBLE_EQ(c.rectified.baseline_m, 0.12);
    EXPECT_DOUBLE_EQ(c.rectified.cx_px, 376.5);
    EXPECT_DOUBLE_EQ(c.rectified.doffs_px, 0.0);
    EXPECT_EQ(c.R, cv::Matx33d::eye());
    EXPECT_DOUBLE_EQ(c.T[0], -0.12);
    EXPECT_EQ(c.valid_roi_left, cv::Rect(0, 0, 752, 480));
    // Through our own file format, as the service would get it.
    const std::string ours = dir.file("calibration.yaml");
    saveCalibration(c, ours);
    EXPECT_EQ(loadCalibration(ours).rectified.baseline_m, c.rectified.baseline_m);
}

TEST(CalibrationFormats, WritesARectifiedOnlyCalibrationAsARosPair)
{
    const StereoCalibration c = makeRectifiedCalibration({640, 480}, 500.0, 0.1, 320.0, 240.0, 4.0);
    test::TempDir dir;
    const std::string left = dir.file("left.yaml"), right = dir.file("right.yaml");
    exportRosCameraInfo(c, left, right);
    const StereoCalibration back = importRosCameraInfo(left, right);
    EXPECT_DOUBLE_EQ(back.rectified.focal_px, 500.0);
    EXPECT_DOUBLE_EQ(back.rectified.baseline_m, 0.1);
    EXPECT_DOUBLE_EQ(back.rectified.cx_px, 320.0);
    EXPECT_DOUBLE_EQ(back.rectified.cy_px, 240.0);
    EXPECT_DOUBLE_EQ(back.rectified.doffs_px, 4.0);
}

TEST(CalibrationFormats, RefusesRosFilesItCannotUseNamingFileAndKey)
{
    test::TempDir dir;
    const std::string left = dir.file("left.yaml"), right = dir.file("right.yaml");
    exportRosCameraInfo(makeRectifiedCalibration({640, 480}, 500.0, 0.1), left, right);
    const std::string good_left = test::readFile(left);

    std::string message = refusal([&] { importRosCameraInfo(right, left); });
    EXPECT_TRUE(contains(message, right)) << message;
    EXPECT_TRUE(contains(message, "swapped")) << message;

    const std::string fisheye = dir.file("fisheye.yaml");
    std::string text = good_left;
    text.replace(text.find("plumb_bob"), 9, "equidistant");
    writeFile(fisheye, text);
    message = refusal([&] { importRosCameraInfo(fisheye, right); });
    EXPECT_TRUE(contains(message, fisheye + ":")) << message;
    EXPECT_TRUE(contains(message, "distortion_model: 'equidistant' is not supported")) << message;

    const std::string wide = dir.file("wide.yaml");
    text = good_left;
    text.replace(text.find("image_width: 640"), 16, "image_width: 800");
    writeFile(wide, text);
    message = refusal([&] { importRosCameraInfo(wide, right); });
    EXPECT_TRUE(contains(message, "640x480 but the left's (" + wide + ") are 800x480")) << message;

    const std::string short_p = dir.file("short.yaml");
    text = good_left;
    text.replace(text.find("projection_matrix"), 17, "projection_matrx");
    writeFile(short_p, text);
    message = refusal([&] { importRosCameraInfo(short_p, right); });
    EXPECT_TRUE(contains(message, short_p + ": projection_matrix: missing key")) << message;

    message = refusal([&] { importRosCameraInfo(dir.file("none.yaml"), right); });
    EXPECT_TRUE(contains(message, "none.yaml: cannot open: No such file or directory")) << message;
}

// The camera_info messages of a bag or of a ROS 2 driver's topics: the real calibration
// comes back from them, and each field that cannot be used is refused by its own name.
TEST_F(CalibrationFormatsTest, CameraInfoMessagesGiveTheCalibrationAndAreCheckedByField)
{
    const StereoCalibration& c = calibration();
    const auto [left_info, right_info] = rosCameraInfoPair(c);
    const ros2::CameraInfo left = cameraInfoMessage(left_info);
    const ros2::CameraInfo right = cameraInfoMessage(right_info);
    const StereoCalibration back = calibrationFromCameraInfoMessages(left, right, "/l", "/r");
    EXPECT_EQ(back.P1, c.P1);
    EXPECT_EQ(back.P2, c.P2);
    EXPECT_EQ(back.rectified.baseline_m, c.rectified.baseline_m);
    expectSameRectification(c, back);

    struct Case {
        std::function<void(ros2::CameraInfo&)> spoil;
        std::string message;
    };
    const std::vector<Case> cases = {
        {[](ros2::CameraInfo& m) { m.width = 0; },
         "/r: width: the image is 0x480, not 1 to 8192 pixels each way"},
        {[](ros2::CameraInfo& m) { m.height = 100000; },
         "/r: height: the image is 640x100000, not 1 to 8192 pixels each way"},
        {[](ros2::CameraInfo& m) { m.distortion_model = "equidistant"; },
         "/r: distortion_model: 'equidistant' is not supported"},
        {[](ros2::CameraInfo& m) { m.d.resize(4); },
         "/r: d: 4 coefficients for plumb_bob, which has 5"},
        {[](ros2::CameraInfo& m) { m.d[2] = std::nan(""); },
         "/r: d[2]: nan is not a finite number"},
        {[](ros2::CameraInfo& m) { m.k[4] = INFINITY; }, "/r: k[4]: inf is not a finite number"},
        {[](ros2::CameraInfo& m) { m.r[8] = std::nan(""); },
         "/r: r[8]: nan is not a finite number"},
        {[](ros2::CameraInfo& m) { m.p[3] = -INFINITY; }, "/r: p[3]: -inf is not a finite number"},
        {[](ros2::CameraInfo& m) { m.binning_x = 2; },
         "/r: binning_x: binned images (2x0) are not supported"},
        {[](ros2::CameraInfo& m) {
             m.roi = {10, 0, 480, 320, false};
         },
         "/r: roi: a region of interest (320x480 at 10,0) is not supported"},
        // Well-formed but not a stereo rig's: what the shared conversion refuses.
        {[](ros2::CameraInfo& m) { m.p[3] = 0.0; },
         "/l + /r: T: the translation between the cameras must not be zero"},
    };
    for (const Case& bad : cases) {
        ros2::CameraInfo spoilt = right;
        bad.spoil(spoilt);
        const std::string message =
            refusal([&] { calibrationFromCameraInfoMessages(left, spoilt, "/l", "/r"); });
        EXPECT_TRUE(contains(message, bad.message)) << message;
    }
}

// Writes the two files exactly as OpenCV's stereo_calib sample does (FileStorage, the same
// keys), with T in squares as the sample gives it when run with its default -s 1.
void writeStereoCalibFiles(const StereoCalibration& c, const std::string& intrinsics,
                           const std::string& extrinsics)
{
    cv::FileStorage fs(intrinsics, cv::FileStorage::WRITE);
    fs << "M1" << cv::Mat(c.left.camera_matrix) << "D1" << cv::Mat(c.left.distortion).t() << "M2"
       << cv::Mat(c.right.camera_matrix) << "D2" << cv::Mat(c.right.distortion).t();
    fs.release();
    cv::Matx34d p2 = c.P2;
    p2(0, 3) /= kSquareM;
    cv::Matx44d q = c.Q;
    q(3, 2) *= kSquareM;
    q(3, 3) *= kSquareM;
    fs.open(extrinsics, cv::FileStorage::WRITE);
    fs << "R" << cv::Mat(c.R) << "T" << cv::Mat(c.T / kSquareM) << "R1" << cv::Mat(c.R1) << "R2"
       << cv::Mat(c.R2) << "P1" << cv::Mat(c.P1) << "P2" << cv::Mat(p2) << "Q" << cv::Mat(q);
    fs.release();
}

TEST_F(CalibrationFormatsTest, ReadsOpenCvStereoCalibFilesInMetres)
{
    const StereoCalibration& c = calibration();
    test::TempDir dir;
    const std::string intrinsics = dir.file("intrinsics.yml"),
                      extrinsics = dir.file("extrinsics.yml");
    writeStereoCalibFiles(c, intrinsics, extrinsics);
    const StereoCalibration back =
        importOpenCvStereoCalib(intrinsics, extrinsics, toCv(c.rectified.image_size), kSquareM);
    EXPECT_EQ(back.left.camera_matrix, c.left.camera_matrix);
    EXPECT_EQ(back.right.distortion, c.right.distortion);
    EXPECT_EQ(back.R, c.R);
    EXPECT_LT(cv::norm(back.T - c.T), 1e-12 * cv::norm(c.T));
    EXPECT_LT(maxDifference(back.P2, c.P2), 1e-12);
    EXPECT_LT(maxDifference(back.Q, c.Q), 1e-9);
    EXPECT_NEAR(back.rectified.baseline_m, c.rectified.baseline_m, 1e-12);
    expectSameRectification(c, back);

    // Read as squares (the unit left at 1): the baseline is 1/0.025 times larger.
    const StereoCalibration squares =
        importOpenCvStereoCalib(intrinsics, extrinsics, toCv(c.rectified.image_size));
    EXPECT_NEAR(squares.rectified.baseline_m, c.rectified.baseline_m / kSquareM, 1e-9);
}

TEST_F(CalibrationFormatsTest, RefusesOpenCvFilesItCannotUse)
{
    const StereoCalibration& c = calibration();
    test::TempDir dir;
    const std::string intrinsics = dir.file("intrinsics.yml"),
                      extrinsics = dir.file("extrinsics.yml");
    writeStereoCalibFiles(c, intrinsics, extrinsics);
    const std::string partial = dir.file("partial.yml");
    cv::FileStorage fs(partial, cv::FileStorage::WRITE);
    fs << "R" << cv::Mat(c.R);
    fs.release();

    std::string message = refusal(
        [&] { importOpenCvStereoCalib(intrinsics, partial, toCv(c.rectified.image_size)); });
    EXPECT_TRUE(contains(message, partial + ": T: missing key")) << message;

    message = refusal([&] { importOpenCvStereoCalib(intrinsics, dir.file("no.yml"), {640, 480}); });
    EXPECT_TRUE(contains(message, "no.yml: cannot open")) << message;

    // An image size the principal points do not fit.
    message = refusal([&] { importOpenCvStereoCalib(intrinsics, extrinsics, {320, 240}); });
    EXPECT_TRUE(contains(message, intrinsics + " + " + extrinsics)) << message;
}

} // namespace
} // namespace stereod
