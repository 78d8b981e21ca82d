// `stereoctl check-calibration` as a user runs it on the Baumer rig of shared/data: its
// own calibration views read ok (exit 0); the scenes taken after the rig moved read
// degraded (exit 1) with the figures in JSON; --fix writes a correction that brings other
// scenes back, never over an existing file; a pattern that matches nothing exits 2.
// And on a factory-rectified pair (Middlebury's Aloe with its published geometry as a
// rectified-only calibration) whose right image has turned: checked as it comes, degraded
// by its roll, and --fix writes a full calibration that turns it back.

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/calibration.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ProcessResult;
using test::runProcess;
using test::stereoctlPath;

const std::string kBaumer = test::sharedDataDir() + "/real-rig/baumer/";

// The rig's calibration in our format, imported from its OpenCV stereo_calib files.
std::string importBaumer(test::TempDir& dir)
{
    const std::string out = dir.file("baumer.yaml");
    const ProcessResult run = runProcess({stereoctlPath(), "calibrate", "--from-opencv",
                                          kBaumer + "Checkerboard_Baumer/intrinsics.yml",
                                          kBaumer + "Checkerboard_Baumer/extrinsics.yml", "--size",
                                          "696x524", "--out", out});
    EXPECT_EQ(run.exit_code, 0) << run.err;
    return out;
}

// The scenes' files named "right" come from the calibration's left camera.
std::vector<std::string> checkSamples(const std::string& calib, const std::string& which)
{
    return {stereoctlPath(), "check-calibration",
            "--left",        kBaumer + "samples_baumer/right0" + which + ".png",
            "--right",       kBaumer + "samples_baumer/left0" + which + ".png",
            "--calib",       calib};
}

TEST(StereoctlCheckCalibration, CalibrationViewsAreOk)
{
    test::TempDir dir;
    const std::string calib = importBaumer(dir);
    const ProcessResult run =
        runProcess({stereoctlPath(), "check-calibration", "--left",
                    kBaumer + "Checkerboard_Baumer/left0[1-5].png", "--right",
                    kBaumer + "Checkerboard_Baumer/right0[1-5].png", "--calib", calib});
    EXPECT_EQ(run.exit_code, 0) << run.out << run.err;
    EXPECT_NE(run.out.find("overall, 5 pairs: ok"), std::string::npos) << run.out;
}

TEST(StereoctlCheckCalibration, DriftedRigIsDegradedWithItsFigures)
{
    test::TempDir dir;
    std::vector<std::string> argv = checkSamples(importBaumer(dir), "[1-4]");
    argv.push_back("--json");
    const ProcessResult run = runProcess(argv);
    EXPECT_EQ(run.exit_code, 1) << run.err;
    const auto out = nlohmann::json::parse(run.out);
    EXPECT_EQ(out["state"], "degraded");
    EXPECT_EQ(out["reason"], "row_offset");
    EXPECT_GT(std::abs(out["row_offset_px"].get<double>()), 0.8);
    EXPECT_GT(out["row_offset_p90_px"].get<double>(), 0.9);
    EXPECT_GT(out["matches"].get<int>(), 100);
    // The fitted model: rows apart by about a pixel all over, no roll to speak of.
    EXPECT_GT(out["offset_px"].get<double>(), 0.6);
    EXPECT_GT(out["max_row_error_px"].get<double>(), 0.8);
    EXPECT_LT(out["max_row_error_px"].get<double>(), 1.6);
    EXPECT_LT(std::abs(out["roll_deg"].get<double>()), 0.2);
    ASSERT_EQ(out["pairs"].size(), 4u);
    for (const auto& pair : out["pairs"])
        EXPECT_EQ(pair["state"], "degraded") << pair["left"];
}

TEST(StereoctlCheckCalibration, FixWritesACorrectionThatHoldsOnOtherScenes)
{
    test::TempDir dir;
    const std::string calib = importBaumer(dir);
    const std::string fixed = dir.file("fixed.yaml");
    std::vector<std::string> argv = checkSamples(calib, "[1-3]");
    argv.insert(argv.end(), {"--fix", "--out", fixed, "--json"});
    const ProcessResult run = runProcess(argv);
    EXPECT_EQ(run.exit_code, 1) << run.err; // the verdict is about the checked calibration
    const auto out = nlohmann::json::parse(run.out);
    EXPECT_LT(std::abs(out["fix"]["after"]["row_offset_px"].get<double>()), 0.2);
    EXPECT_GT(std::abs(out["fix"]["before"]["row_offset_px"].get<double>()), 0.8);
    // Depth is untouched: the rectified geometry is the same.
    EXPECT_EQ(loadCalibration(fixed).P2, loadCalibration(calib).P2);

    const ProcessResult others = runProcess(checkSamples(fixed, "[4-8]"));
    EXPECT_EQ(others.exit_code, 0) << others.out << others.err;

    // Never over an existing file.
    const ProcessResult again = runProcess(argv);
    EXPECT_EQ(again.exit_code, 2);
    EXPECT_NE(again.err.find("exists already"), std::string::npos) << again.err;
}

TEST(StereoctlCheckCalibration, RectifiedOnlyCalibrationIsCheckedAndFixed)
{
    test::TempDir dir;
    const std::string samples = test::opencvSamplesDir() + "/";
    const std::string rectified = dir.file("aloe.yaml");
    const ProcessResult made = runProcess({stereoctlPath(), "calibrate", "--rectified",
                                           "--focal-px", "3740", "--baseline-m", "0.16", "--size",
                                           "1282x1110", "--doffs-px", "270", "--out", rectified});
    ASSERT_EQ(made.exit_code, 0) << made.err;
    // The right camera turned by 0.3 deg about the image centre.
    const cv::Mat right = cv::imread(samples + "aloeR.jpg", cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(right.empty());
    cv::Mat turned;
    cv::warpAffine(
        right, turned,
        cv::getRotationMatrix2D({(right.cols - 1) / 2.0f, (right.rows - 1) / 2.0f}, 0.3, 1.0),
        right.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    const std::string turned_path = dir.file("aloeR-turned.png");
    ASSERT_TRUE(cv::imwrite(turned_path, turned));

    const ProcessResult straight =
        runProcess({stereoctlPath(), "check-calibration", "--left", samples + "aloeL.jpg",
                    "--right", samples + "aloeR.jpg", "--calib", rectified});
    EXPECT_EQ(straight.exit_code, 0) << straight.out << straight.err;

    const std::string fixed = dir.file("aloe-fixed.yaml");
    const ProcessResult run = runProcess({stereoctlPath(), "check-calibration", "--left",
                                          samples + "aloeL.jpg", "--right", turned_path, "--calib",
                                          rectified, "--fix", "--out", fixed, "--json"});
    EXPECT_EQ(run.exit_code, 1) << run.err;
    const auto out = nlohmann::json::parse(run.out);
    EXPECT_EQ(out["state"], "degraded");
    EXPECT_EQ(out["reason"], "roll");
    EXPECT_NEAR(out["roll_deg"].get<double>(), 0.3, 0.05);
    EXPECT_EQ(out["fix"]["kind"], "full");
    EXPECT_NEAR(out["fix"]["roll_deg"].get<double>(), 0.3, 0.05);
    EXPECT_EQ(out["fix"]["after"]["state"], "ok");

    const StereoCalibration correction = loadCalibration(fixed);
    EXPECT_EQ(correction.kind, StereoCalibration::Kind::Full);
    EXPECT_DOUBLE_EQ(correction.rectified.focal_px, 3740.0);
    EXPECT_DOUBLE_EQ(correction.rectified.doffs_px, 270.0);
    const ProcessResult again =
        runProcess({stereoctlPath(), "check-calibration", "--left", samples + "aloeL.jpg",
                    "--right", turned_path, "--calib", fixed});
    EXPECT_EQ(again.exit_code, 0) << again.out << again.err;
}

TEST(StereoctlCheckCalibration, PatternMatchingNothingIsABadArgument)
{
    test::TempDir dir;
    const ProcessResult run =
        runProcess({stereoctlPath(), "check-calibration", "--left", dir.file("none*.png"),
                    "--right", dir.file("none*.png"), "--calib", importBaumer(dir)});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("matches no file"), std::string::npos) << run.err;
}

} // namespace
} // namespace stereod
