// The calibration file: both forms round-trip exactly, and every rejected file says
// which file, which key, on which line, and what is wrong with it.

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <unistd.h>

#include "pipeline/calibration.hpp"

namespace stereod {
namespace {

std::string tempPath(const std::string& name)
{
    return std::string(STEREOD_BINARY_DIR) + "/pipeline_calibration_test_" +
           std::to_string(::getpid()) + "_" + name;
}

std::string readText(const std::string& path)
{
    std::ifstream in(path);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

// 1-based line of the first line that starts with `prefix` (after indentation).
int lineStarting(const std::string& text, const std::string& prefix)
{
    std::istringstream in(text);
    std::string line;
    for (int n = 1; std::getline(in, line); ++n)
        if (line.find_first_not_of(' ') != std::string::npos &&
            line.compare(line.find_first_not_of(' '), prefix.size(), prefix) == 0)
            return n;
    return 0;
}

std::string replaceOnce(std::string text, const std::string& from, const std::string& to)
{
    const auto at = text.find(from);
    EXPECT_NE(at, std::string::npos) << "'" << from << "' not in the text";
    if (at != std::string::npos)
        text.replace(at, from.size(), to);
    return text;
}

// The message of the CalibrationError that parsing `text` throws ("" if none).
std::string rejection(const std::string& text, const std::string& origin = "calib.yaml")
{
    try {
        parseCalibration(text, origin);
    } catch (const CalibrationError& e) {
        return e.what();
    }
    return "";
}

// A full calibration as cv::stereoRectify makes it, from a plausible 640x480 rig: 12 cm
// baseline, slightly rotated, with radial and tangential distortion.
StereoCalibration syntheticFull()
{
    StereoCalibration c;
    c.kind = StereoCalibration::Kind::Full;
    const cv::Size size(640, 480);
    c.left.camera_matrix = cv::Matx33d(702.31, 0, 318.77, 0, 701.94, 241.03, 0, 0, 1);
    c.left.distortion = {-0.281, 0.0913, 0.00041, -0.00022, 0.0107};
    c.right.camera_matrix = cv::Matx33d(698.12, 0, 325.1, 0, 698.55, 237.9, 0, 0, 1);
    c.right.distortion = {-0.275, 0.0871, -0.00015, 0.00031, 0.0093};
    cv::Mat rvec = (cv::Mat_<double>(3, 1) << 0.0031, -0.0122, 0.0017);
    cv::Mat r;
    cv::Rodrigues(rvec, r);
    c.R = cv::Matx33d(r);
    c.T = cv::Vec3d(-0.1197, 0.0012, -0.0008);
    cv::Mat R1, R2, P1, P2, Q;
    cv::stereoRectify(c.left.camera_matrix, c.left.distortion, c.right.camera_matrix,
                      c.right.distortion, size, c.R, c.T, R1, R2, P1, P2, Q,
                      cv::CALIB_ZERO_DISPARITY, 0, size, &c.valid_roi_left, &c.valid_roi_right);
    c.R1 = cv::Matx33d(R1);
    c.R2 = cv::Matx33d(R2);
    c.P1 = cv::Matx34d(P1);
    c.P2 = cv::Matx34d(P2);
    c.Q = cv::Matx44d(Q);
    c.rms_px = 0.2731;
    c.epipolar_error_px = 0.1842;
    c.board = ChessboardSpec{9, 6, 0.025};
    c.rectified = rectifiedFromProjections(c.P1, c.P2, size);
    return c;
}

template <int R, int C>
void expectSame(const cv::Matx<double, R, C>& a, const cv::Matx<double, R, C>& b, const char* what)
{
    for (int i = 0; i < R * C; ++i)
        EXPECT_EQ(a.val[i], b.val[i]) << what << " element " << i;
}

void expectSameGeometry(const RectifiedGeometry& a, const RectifiedGeometry& b)
{
    EXPECT_EQ(a.image_size, b.image_size);
    EXPECT_EQ(a.focal_px, b.focal_px);
    EXPECT_EQ(a.cx_px, b.cx_px);
    EXPECT_EQ(a.cy_px, b.cy_px);
    EXPECT_EQ(a.baseline_m, b.baseline_m);
    EXPECT_EQ(a.doffs_px, b.doffs_px);
}

const char* const kRectified = R"(stereod_calibration: 1
kind: rectified
image_size: {width: 1282, height: 1110}
focal_px: 3740
cx_px: 640.5
cy_px: 554.5
baseline_m: 0.16
doffs_px: 270
)";

TEST(Calibration, ParsesRectifiedForm)
{
    const StereoCalibration c = parseCalibration(kRectified, "calib.yaml");
    EXPECT_EQ(c.kind, StereoCalibration::Kind::RectifiedOnly);
    EXPECT_EQ(c.rectified.image_size, (ImageSize{1282, 1110}));
    EXPECT_EQ(c.rectified.focal_px, 3740.0);
    EXPECT_EQ(c.rectified.baseline_m, 0.16);
    EXPECT_EQ(c.rectified.doffs_px, 270.0);
    // Z = f*B / (d + doffs): 211 px on Aloe is 598.4 / 481 m.
    EXPECT_NEAR(c.rectified.depthFromDisparity(211.0), 598.4 / 481.0, 1e-12);
}

TEST(Calibration, RectifiedFormDefaultsPrincipalPointAndDoffs)
{
    const std::string text = "stereod_calibration: 1\nkind: rectified\n"
                             "image_size: {width: 640, height: 480}\n"
                             "focal_px: 500\nbaseline_m: 0.1\n";
    const StereoCalibration c = parseCalibration(text, "calib.yaml");
    EXPECT_EQ(c.rectified.cx_px, 319.5);
    EXPECT_EQ(c.rectified.cy_px, 239.5);
    EXPECT_EQ(c.rectified.doffs_px, 0.0);
}

TEST(Calibration, RectifiedRoundTripIsExact)
{
    // Values with no short decimal form must survive the text unchanged.
    const StereoCalibration c = makeRectifiedCalibration({752, 480}, 0.1 + 425.2, 0.1 + 0.02,
                                                         375.0 / 3.0, 240.0 / 7.0, 1.0 / 3.0);
    const std::string path = tempPath("rectified.yaml");
    saveCalibration(c, path);
    const StereoCalibration back = loadCalibration(path);
    EXPECT_EQ(back.kind, StereoCalibration::Kind::RectifiedOnly);
    expectSameGeometry(back.rectified, c.rectified);
    // A second save gives the same bytes.
    const std::string first = readText(path);
    saveCalibration(back, path);
    EXPECT_EQ(readText(path), first);
    std::remove(path.c_str());
}

TEST(Calibration, FullRoundTripIsExact)
{
    const StereoCalibration c = syntheticFull();
    const std::string path = tempPath("full.yaml");
    saveCalibration(c, path);
    const std::string text = readText(path);
    // A person can find their way in it.
    EXPECT_NE(text.find("kind: full"), std::string::npos);
    EXPECT_NE(text.find("camera_matrix:"), std::string::npos);
    EXPECT_NE(text.find("board: {cols: 9, rows: 6, square_m: 0.025}"), std::string::npos);

    const StereoCalibration back = loadCalibration(path);
    EXPECT_EQ(back.kind, StereoCalibration::Kind::Full);
    expectSame(back.left.camera_matrix, c.left.camera_matrix, "left K");
    expectSame(back.right.camera_matrix, c.right.camera_matrix, "right K");
    EXPECT_EQ(back.left.distortion, c.left.distortion);
    EXPECT_EQ(back.right.distortion, c.right.distortion);
    expectSame(back.R, c.R, "R");
    for (int i = 0; i < 3; ++i)
        EXPECT_EQ(back.T[i], c.T[i]);
    expectSame(back.R1, c.R1, "R1");
    expectSame(back.R2, c.R2, "R2");
    expectSame(back.P1, c.P1, "P1");
    expectSame(back.P2, c.P2, "P2");
    expectSame(back.Q, c.Q, "Q");
    EXPECT_EQ(back.valid_roi_left, c.valid_roi_left);
    EXPECT_EQ(back.valid_roi_right, c.valid_roi_right);
    EXPECT_EQ(back.rms_px, c.rms_px);
    EXPECT_EQ(back.epipolar_error_px, c.epipolar_error_px);
    ASSERT_TRUE(back.board.has_value());
    EXPECT_EQ(back.board->cols, 9);
    EXPECT_EQ(back.board->rows, 6);
    EXPECT_EQ(back.board->square_m, 0.025);
    expectSameGeometry(back.rectified, c.rectified);
    // The derived geometry is the rig's: baseline |T|, focal of P1.
    EXPECT_NEAR(back.rectified.baseline_m, cv::norm(c.T), 1e-9);
    EXPECT_EQ(back.rectified.focal_px, c.P1(0, 0));
    std::remove(path.c_str());
}

TEST(Calibration, SaveReplacesAtomicallyAndLeavesNoTemporary)
{
    const std::string path = tempPath("atomic.yaml");
    saveCalibration(makeRectifiedCalibration({640, 480}, 500, 0.1), path);
    saveCalibration(makeRectifiedCalibration({640, 480}, 600, 0.1), path);
    EXPECT_EQ(loadCalibration(path).rectified.focal_px, 600.0);
    // The temporary is named path + ".tmp.XXXXXX": none may be left behind.
    const std::string temp_prefix = std::filesystem::path(path).filename().string() + ".tmp.";
    for (const auto& entry : std::filesystem::directory_iterator(STEREOD_BINARY_DIR))
        EXPECT_NE(entry.path().filename().string().rfind(temp_prefix, 0), 0u) << entry.path();
    std::remove(path.c_str());
}

TEST(Calibration, SaveToMissingDirectoryNamesTheFile)
{
    const std::string path = "/nonexistent-dir-for-stereod/calib.yaml";
    try {
        saveCalibration(makeRectifiedCalibration({640, 480}, 500, 0.1), path);
        FAIL() << "saved into a missing directory";
    } catch (const CalibrationError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("No such file or directory"), std::string::npos)
            << e.what();
    }
}

TEST(Calibration, MissingFileNamesPathAndReason)
{
    const std::string path = tempPath("does-not-exist.yaml");
    try {
        loadCalibration(path);
        FAIL() << "loaded a missing file";
    } catch (const CalibrationError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(path), std::string::npos) << what;
        EXPECT_NE(what.find("No such file or directory"), std::string::npos) << what;
    }
}

// One edit of the rectified example, and the message it must give.
struct Rejection {
    const char* from;
    const char* to;
    const char* message;
};

const Rejection kRectifiedRejections[] = {
    {"focal_px: 3740\n", "", "calib.yaml: focal_px: missing key"},
    {", height: 1110", "", "calib.yaml:3: image_size.height: missing key"},
    {"focal_px: 3740", "focal_px: -3740", "calib.yaml:4: focal_px: must be > 0, got -3740"},
    {"baseline_m: 0.16", "baseline_m: 0", "calib.yaml:7: baseline_m: must be > 0, got 0"},
    {"doffs_px: 270", "doffs_px: 270px", "calib.yaml:8: doffs_px: not a number: '270px'"},
    {"width: 1282", "width: 0",
     "calib.yaml:3: image_size: width and height must be > 0, got 0x1110"},
    {"width: 1282", "width: 12.5", "calib.yaml:3: image_size.width: not an integer: '12.5'"},
    {"cx_px: 640.5", "cx_px: 1282",
     "calib.yaml:5: cx_px: 1282 lies outside the image (width 1282)"},
    {"cy_px: 554.5", "cy_px: -1", "calib.yaml:6: cy_px: -1 lies outside the image (height 1110)"},
    // A misspelt optional key must not be ignored silently.
    {"doffs_px: 270", "doffs: 270", "calib.yaml:8: doffs: unknown key"},
    {"kind: rectified", "kind: mono",
     "calib.yaml:2: kind: expected 'full' or 'rectified', got 'mono'"},
    {"stereod_calibration: 1", "stereod_calibration: 2",
     "calib.yaml:1: stereod_calibration: unsupported format version 2 (this build reads 1)"},
    {"stereod_calibration: 1\n", "", "calib.yaml: stereod_calibration: missing key"},
};

TEST(Calibration, RejectionsNameFileLineKeyAndProblem)
{
    for (const Rejection& r : kRectifiedRejections) {
        SCOPED_TRACE(std::string(r.from) + " -> " + r.to);
        EXPECT_EQ(rejection(replaceOnce(kRectified, r.from, r.to)), r.message);
    }
}

TEST(Calibration, RejectsBadYamlWithLine)
{
    const std::string text = replaceOnce(kRectified, "focal_px: 3740", "focal_px: [3740");
    const std::string what = rejection(text);
    EXPECT_EQ(what.rfind("calib.yaml:", 0), 0u) << what;
    EXPECT_NE(what.find("invalid YAML"), std::string::npos) << what;
}

TEST(Calibration, RejectsOpenCvFileStorageWithAHint)
{
    const std::string what = rejection("%YAML:1.0\n---\nM1: !!opencv-matrix\n   rows: 3\n");
    EXPECT_NE(what.find("OpenCV FileStorage"), std::string::npos) << what;
}

class FullCalibrationText : public ::testing::Test {
  protected:
    void SetUp() override
    {
        const std::string path = tempPath("full-text.yaml");
        saveCalibration(syntheticFull(), path);
        text_ = readText(path);
        std::remove(path.c_str());
    }
    std::string text_;
};

TEST_F(FullCalibrationText, LoadsAsSaved)
{
    EXPECT_EQ(rejection(text_), "");
}

TEST_F(FullCalibrationText, RejectsWrongMatrixSizeAtTheKey)
{
    // P1 declared 3x3 with its 12 values.
    const int line = lineStarting(text_, "P1:");
    const std::string bad =
        replaceOnce(text_, "P1:\n  rows: 3\n  cols: 4", "P1:\n  rows: 3\n  cols: 3");
    EXPECT_EQ(rejection(bad), "calib.yaml:" + std::to_string(line) +
                                  ": P1: expected a 3x4 matrix, got rows 3 cols 3");
}

TEST_F(FullCalibrationText, RejectsWrongNumberOfMatrixValues)
{
    // R with one value missing from its data.
    const auto at = text_.find("R:\n");
    ASSERT_NE(at, std::string::npos);
    const auto data = text_.find("data: [", at);
    const auto comma = text_.find(", ", data);
    std::string bad = text_;
    bad.erase(data + 7, comma + 2 - (data + 7));
    const std::string what = rejection(bad);
    EXPECT_NE(what.find(": R.data: expected 9 values (3x3), got 8"), std::string::npos) << what;
}

TEST_F(FullCalibrationText, RejectsNegativeFocalInCameraMatrix)
{
    const int line = lineStarting(text_, "camera_matrix:");
    const std::string bad = replaceOnce(text_, "data: [702.31,", "data: [-702.31,");
    EXPECT_EQ(rejection(bad), "calib.yaml:" + std::to_string(line) +
                                  ": left.camera_matrix: focal length fx (element 0,0) must be "
                                  "> 0, got -702.31");
}

TEST_F(FullCalibrationText, RejectsRotationThatIsNotOne)
{
    // Scale R's first element: R^T R is no longer the identity.
    const auto at = text_.find("\nR:\n");
    ASSERT_NE(at, std::string::npos);
    const auto data = text_.find("data: [", at) + 7;
    std::string bad = text_;
    bad.insert(data, "2"); // 0.99... becomes 20.99...
    const int line = lineStarting(text_, "R:");
    const std::string what = rejection(bad);
    EXPECT_EQ(what.rfind("calib.yaml:" + std::to_string(line) + ": R: not a rotation matrix", 0),
              0u)
        << what;
}

TEST_F(FullCalibrationText, RejectsMissingMatrix)
{
    const auto from = text_.find("Q:\n");
    const auto to = text_.find("valid_roi_left");
    ASSERT_NE(from, std::string::npos);
    ASSERT_NE(to, std::string::npos);
    std::string bad = text_;
    bad.erase(from, to - from);
    EXPECT_EQ(rejection(bad), "calib.yaml: Q: missing key");
}

TEST_F(FullCalibrationText, RejectsBaselineThatDisagreesWithT)
{
    // T in millimetres while P2 stays in metres.
    const int line = lineStarting(text_, "P2:");
    const std::string bad =
        replaceOnce(text_, "T: [-0.1197, 0.0012, -0.0008]", "T: [-119.7, 1.2, -0.8]");
    const std::string what = rejection(bad);
    EXPECT_EQ(what.rfind("calib.yaml:" + std::to_string(line) + ": P2: baseline", 0), 0u) << what;
    EXPECT_NE(what.find("disagrees with |T|"), std::string::npos) << what;
}

TEST(Calibration, DocumentedExamplesLoad)
{
    const std::string doc = readText(std::string(STEREOD_SOURCE_DIR) + "/docs/calibration.md");
    ASSERT_FALSE(doc.empty());
    std::vector<StereoCalibration> examples;
    for (size_t at = doc.find("```yaml\n"); at != std::string::npos;
         at = doc.find("```yaml\n", at + 1)) {
        const size_t begin = at + 8;
        const size_t end = doc.find("```", begin);
        ASSERT_NE(end, std::string::npos);
        examples.push_back(parseCalibration(doc.substr(begin, end - begin), "docs/calibration.md"));
    }
    ASSERT_EQ(examples.size(), 2u);
    EXPECT_EQ(examples[0].kind, StereoCalibration::Kind::RectifiedOnly);
    EXPECT_EQ(examples[0].rectified.focal_px, 3740.0);
    EXPECT_EQ(examples[1].kind, StereoCalibration::Kind::Full);
    EXPECT_NEAR(examples[1].rectified.baseline_m, 0.0836, 1e-4);
    EXPECT_EQ(examples[1].left.distortion.size(), 8u);
}

TEST(Calibration, CheckFrameSizeNamesBothSizes)
{
    const StereoCalibration c = makeRectifiedCalibration({1282, 1110}, 3740, 0.16);
    EXPECT_NO_THROW(checkFrameSize(c, {1282, 1110}, "camera"));
    try {
        checkFrameSize(c, {640, 480}, "/dev/video0");
        FAIL() << "accepted 640x480 frames for a 1282x1110 calibration";
    } catch (const CalibrationError& e) {
        EXPECT_EQ(std::string(e.what()), "/dev/video0: image_size: frames are 640x480 but the "
                                         "calibration is for 1282x1110 images");
    }
}

TEST(Calibration, MakeRectifiedCalibrationValidates)
{
    EXPECT_THROW(makeRectifiedCalibration({640, 480}, -500, 0.1), CalibrationError);
    EXPECT_THROW(makeRectifiedCalibration({640, 480}, 500, 0.0), CalibrationError);
    EXPECT_THROW(makeRectifiedCalibration({0, 480}, 500, 0.1), CalibrationError);
    EXPECT_THROW(makeRectifiedCalibration({640, 480}, 500, 0.1, 700.0), CalibrationError);
    const StereoCalibration c = makeRectifiedCalibration({640, 480}, 500, 0.1);
    EXPECT_EQ(c.rectified.cx_px, 319.5);
    EXPECT_EQ(c.rectified.cy_px, 239.5);
}

} // namespace
} // namespace stereod
