// `stereoctl calibrate` in its chessboard form, as a user runs it: OpenCV's 13 real sample
// pairs (9x6 inner corners) by glob, the JSON read and held to the calibration issue's
// targets, the files it wrote read back; its refusals (exit 2, one clear line). Then the
// imports (--from-ros, --from-opencv) and `export-ros`.

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "pipeline/calibration.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ProcessResult;
using test::runProcess;
using test::stereoctlPath;

const std::string kSamples = test::opencvSamplesDir() + "/";
// left01.jpg ... left14.jpg; not left.jpg, which the same directory also holds.
const std::string kLeftGlob = kSamples + "left[0-9][0-9].jpg";
const std::string kRightGlob = kSamples + "right[0-9][0-9].jpg";

std::vector<std::string> calibrateCommand(const std::string& left, const std::string& right,
                                          const std::string& board, const std::string& out)
{
    return {stereoctlPath(), "calibrate", "--left",     left,    "--right", right,
            "--board",       board,       "--square-m", "0.025", "--out",   out};
}

int countOf(const std::string& text, const std::string& part)
{
    int n = 0;
    for (std::size_t at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) {
        ++n;
    }
    return n;
}

TEST(StereoctlCalibrateChessboard, CalibratesTheThirteenSamplePairsWithinTheTargets)
{
    test::TempDir dir;
    const std::string out = dir.file("rig.yaml");
    const std::string preview = dir.file("preview.png");
    std::vector<std::string> argv = calibrateCommand(kLeftGlob, kRightGlob, "9x6", out);
    argv.insert(argv.end(), {"--preview", preview, "--json"});
    const ProcessResult run = runProcess(argv);
    ASSERT_EQ(run.exit_code, 0) << run.err;

    // A progress line per pair on stderr; stdout is the JSON alone.
    EXPECT_EQ(countOf(run.err, "corners: pair "), 13) << run.err;
    EXPECT_NE(run.err.find("corners: pair 13/13 left14.jpg right14.jpg ... found"),
              std::string::npos)
        << run.err;
    const nlohmann::json report = nlohmann::json::parse(run.out);
    for (const char* key : {"rms_px", "epipolar_error_px", "pairs_used", "pairs_rejected",
                            "baseline_m", "pairs", "files"}) {
        EXPECT_TRUE(report.contains(key)) << key;
    }
    EXPECT_EQ(report["pairs_used"], 13);
    EXPECT_TRUE(report["pairs_rejected"].empty()) << report["pairs_rejected"].dump();
    EXPECT_LE(report["rms_px"].get<double>(), 0.30);
    EXPECT_LE(report["epipolar_error_px"].get<double>(), 0.15);
    // 25 mm squares assumed; the sample's rig is a few centimetres wide.
    EXPECT_GT(report["baseline_m"].get<double>(), 0.05);
    EXPECT_LT(report["baseline_m"].get<double>(), 0.12);
    ASSERT_EQ(report["pairs"].size(), 13u);
    EXPECT_EQ(report["pairs"][0]["left"], kSamples + "left01.jpg");
    EXPECT_EQ(report["pairs"][12]["right"], kSamples + "right14.jpg");

    // The file is the calibration the JSON describes.
    const StereoCalibration loaded = loadCalibration(out);
    EXPECT_EQ(loaded.kind, StereoCalibration::Kind::Full);
    EXPECT_EQ(loaded.rms_px, report["rms_px"].get<double>());
    EXPECT_EQ(loaded.epipolar_error_px, report["epipolar_error_px"].get<double>());
    EXPECT_DOUBLE_EQ(loaded.rectified.baseline_m, report["baseline_m"].get<double>());

    const cv::Mat picture = cv::imread(preview);
    EXPECT_EQ(picture.size(), cv::Size(1280, 480));
}

TEST(StereoctlCalibrateChessboard, PrintsThePerPairTableAndASummary)
{
    test::TempDir dir;
    const std::string out = dir.file("rig.yaml");
    // Six pairs are enough to calibrate; plain output this time, and every raw pixel kept.
    std::vector<std::string> argv =
        calibrateCommand(kSamples + "left0[1-6].jpg", kSamples + "right0[1-6].jpg", "9x6", out);
    argv.insert(argv.end(), {"--alpha", "1"});
    const ProcessResult run = runProcess(argv);
    ASSERT_EQ(run.exit_code, 0) << run.err;
    // Zoomed out: black borders around the rectified images, outside the valid region.
    EXPECT_LT(loadCalibration(out).valid_roi_left.area(), 0.9 * 640 * 480);
    EXPECT_NE(run.out.find("RMS left  RMS right  epipolar (rows)"), std::string::npos) << run.out;
    EXPECT_EQ(countOf(run.out, ".jpg  L/R"), 6) << run.out;
    EXPECT_NE(run.out.find("6 of 6 pairs used"), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("wrote calibration " + out), std::string::npos) << run.out;
}

// The glob a user types in opencv-doc's folder, 'left*.jpg', also catches left.jpg
// (612x459, no board): that pair is reported and skipped, the other 13 calibrate.
TEST(StereoctlCalibrateChessboard, SkipsAPairWithoutTheBoardThatTheGlobCaught)
{
    test::TempDir dir;
    const std::string out = dir.file("rig.yaml");
    const ProcessResult run =
        runProcess(calibrateCommand(kSamples + "left*.jpg", kSamples + "right*.jpg", "9x6", out));
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.err.find("corners: pair 1/14 left.jpg right.jpg ... not found"),
              std::string::npos)
        << run.err;
    EXPECT_NE(run.out.find("no: board not found in either image"), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("13 of 14 pairs used"), std::string::npos) << run.out;
    EXPECT_EQ(loadCalibration(out).rectified.image_size, (ImageSize{640, 480}));
}

TEST(StereoctlCalibrateChessboard, RefusesABoardSizeFoundNowhere)
{
    test::TempDir dir;
    const std::string out = dir.file("rig.yaml");
    const ProcessResult run = runProcess(
        calibrateCommand(kSamples + "left0[1-2].jpg", kSamples + "right0[1-2].jpg", "10x7", out));
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("the 10x7 board was found in none of the 4 images"), std::string::npos)
        << run.err;
    EXPECT_NE(run.err.find("INNER corners"), std::string::npos) << run.err;
    EXPECT_TRUE(run.out.empty()) << run.out;
    EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(StereoctlCalibrateChessboard, RefusesBadArgumentsInOneLine)
{
    test::TempDir dir;
    const std::string out = dir.file("rig.yaml");
    struct Case {
        std::vector<std::string> argv;
        std::string says;
    };
    const std::vector<Case> cases = {
        {calibrateCommand(kSamples + "left0[1-3].jpg", kSamples + "right0[1-2].jpg", "9x6", out),
         "--left matches 3 files but --right matches 2"},
        {calibrateCommand(kSamples + "nothing*.png", kRightGlob, "9x6", out),
         "--left '" + kSamples + "nothing*.png' matches no file"},
        {calibrateCommand(kLeftGlob, kRightGlob, "9by6", out), "--board: expected COLSxROWS"},
    };
    for (const Case& c : cases) {
        const ProcessResult run = runProcess(c.argv);
        EXPECT_EQ(run.exit_code, 2) << c.says;
        EXPECT_NE(run.err.find(c.says), std::string::npos) << run.err;
        EXPECT_EQ(test::lineCount(run.err), 1u) << run.err;
    }
}

TEST(StereoctlCalibrationFiles, ExportsARosPairAndImportsItBack)
{
    test::TempDir dir;
    const std::string ours = dir.file("rig.yaml");
    ASSERT_EQ(runProcess({stereoctlPath(), "calibrate", "--rectified", "--focal-px", "425",
                          "--baseline-m", "0.12", "--size", "752x480", "--out", ours})
                  .exit_code,
              0);
    const std::string left = dir.file("left.yaml"), right = dir.file("right.yaml");
    const ProcessResult exported =
        runProcess({stereoctlPath(), "export-ros", "--calib", ours, "--left", left, "--right",
                    right, "--camera-name", "front"});
    ASSERT_EQ(exported.exit_code, 0) << exported.err;
    EXPECT_NE(exported.out.find("wrote ROS camera_info " + left), std::string::npos);

    const std::string back = dir.file("back.yaml");
    const ProcessResult imported =
        runProcess({stereoctlPath(), "calibrate", "--from-ros", left, right, "--out", back});
    ASSERT_EQ(imported.exit_code, 0) << imported.err;
    const StereoCalibration c = loadCalibration(back);
    EXPECT_EQ(c.kind, StereoCalibration::Kind::Full);
    EXPECT_DOUBLE_EQ(c.rectified.focal_px, 425.0);
    EXPECT_DOUBLE_EQ(c.rectified.baseline_m, 0.12);
    EXPECT_EQ(c.rectified.image_size, (ImageSize{752, 480}));

    // The pair the wrong way round: refused, naming the file.
    const ProcessResult swapped = runProcess(
        {stereoctlPath(), "calibrate", "--from-ros", right, left, "--out", dir.file("x.yaml")});
    EXPECT_EQ(swapped.exit_code, 2);
    EXPECT_NE(swapped.err.find(right + ": projection_matrix:"), std::string::npos) << swapped.err;
}

TEST(StereoctlCalibrationFiles, ImportsOpenCvStereoCalibFilesInMetres)
{
    // A rectified rig as the stereo_calib sample writes it with -s 1: T in squares of
    // 25 mm (baseline 4 squares = 0.1 m), P2 and Q in the same unit.
    test::TempDir dir;
    const std::string intrinsics = dir.file("intrinsics.yml");
    const std::string extrinsics = dir.file("extrinsics.yml");
    const cv::Matx33d k(500, 0, 319.5, 0, 500, 239.5, 0, 0, 1);
    cv::FileStorage fs(intrinsics, cv::FileStorage::WRITE);
    fs << "M1" << cv::Mat(k) << "D1" << cv::Mat::zeros(1, 5, CV_64F) << "M2" << cv::Mat(k) << "D2"
       << cv::Mat::zeros(1, 5, CV_64F);
    fs.release();
    fs.open(extrinsics, cv::FileStorage::WRITE);
    fs << "R" << cv::Mat(cv::Matx33d::eye()) << "T" << cv::Mat(cv::Vec3d(-4, 0, 0)) << "R1"
       << cv::Mat(cv::Matx33d::eye()) << "R2" << cv::Mat(cv::Matx33d::eye()) << "P1"
       << cv::Mat(cv::Matx34d(500, 0, 319.5, 0, 0, 500, 239.5, 0, 0, 0, 1, 0)) << "P2"
       << cv::Mat(cv::Matx34d(500, 0, 319.5, -2000, 0, 500, 239.5, 0, 0, 0, 1, 0)) << "Q"
       << cv::Mat(cv::Matx44d(1, 0, 0, -319.5, 0, 1, 0, -239.5, 0, 0, 0, 500, 0, 0, 0.25, 0));
    fs.release();

    const std::string out = dir.file("rig.yaml");
    const ProcessResult run =
        runProcess({stereoctlPath(), "calibrate", "--from-opencv", intrinsics, extrinsics, "--size",
                    "640x480", "--unit-m", "0.025", "--out", out});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const StereoCalibration c = loadCalibration(out);
    EXPECT_DOUBLE_EQ(c.rectified.baseline_m, 0.1);
    EXPECT_DOUBLE_EQ(c.T[0], -0.1);

    const ProcessResult unsized = runProcess(
        {stereoctlPath(), "calibrate", "--from-opencv", intrinsics, extrinsics, "--out", out});
    EXPECT_EQ(unsized.exit_code, 2);
    EXPECT_NE(unsized.err.find("--from-opencv requires --size"), std::string::npos) << unsized.err;
}

} // namespace
} // namespace stereod
