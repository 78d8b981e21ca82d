// `stereoctl depth` as a user runs it: a subprocess on Middlebury tsukuba, its files
// read back and scored against the ground truth, its JSON parsed, its refusals checked.

#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/depth_io.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ProcessResult;
using test::runProcess;
using test::stereoctlPath;

const std::string kTsukuba = test::tsukubaDir();
const std::string kLeft = kTsukuba + "/im3.png";
const std::string kRight = kTsukuba + "/im4.png";
constexpr double kGroundTruthScale = 16.0; // disp3.pgm holds disparity * 16

std::vector<std::string> depthCommand(std::vector<std::string> extra)
{
    std::vector<std::string> argv = {stereoctlPath(), "depth",           kLeft, kRight,
                                     "--rectified",   "--focal-px",      "615", "--baseline-m",
                                     "0.1",           "--max-disparity", "16"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return argv;
}

struct Scores {
    double bad2_percent = 0.0;    // of pixels with ground truth and a reported disparity
    double density_percent = 0.0; // of pixels with ground truth
};

Scores score(const cv::Mat& disparity, const cv::Mat& truth_raw)
{
    std::size_t with_truth = 0, reported = 0, bad = 0;
    for (int y = 0; y < truth_raw.rows; ++y) {
        for (int x = 0; x < truth_raw.cols; ++x) {
            const int raw = truth_raw.at<uint8_t>(y, x);
            if (raw == 0) {
                continue; // unknown
            }
            ++with_truth;
            const float d = disparity.at<float>(y, x);
            if (!std::isfinite(d)) {
                continue;
            }
            ++reported;
            bad += std::abs(d - raw / kGroundTruthScale) > 2.0 ? 1 : 0;
        }
    }
    Scores s;
    s.bad2_percent =
        reported > 0 ? 100.0 * static_cast<double>(bad) / static_cast<double>(reported) : 100.0;
    s.density_percent = 100.0 * static_cast<double>(reported) / static_cast<double>(with_truth);
    return s;
}

TEST(StereoctlDepth, TsukubaDisparityMeetsTheAccuracyBar)
{
    test::TempDir dir;
    const std::string pfm = dir.file("tsukuba.pfm");
    const ProcessResult run = runProcess(depthCommand({"--disparity", pfm}));
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_NE(run.out.find("wrote disparity " + pfm), std::string::npos) << run.out;

    const cv::Mat disparity = readDisparity(pfm);
    const cv::Mat truth = cv::imread(kTsukuba + "/disp3.pgm", cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(truth.empty());
    ASSERT_EQ(truth.type(), CV_8UC1);
    ASSERT_EQ(disparity.size(), truth.size());
    const Scores s = score(disparity, truth);
    // OpenCV SGBM reference on this scene: 4.2 % bad-2, 98.3 % density (data README).
    EXPECT_LT(s.bad2_percent, 6.0);
    EXPECT_GT(s.density_percent, 85.0);
    RecordProperty("bad2_percent", std::to_string(s.bad2_percent));
    RecordProperty("density_percent", std::to_string(s.density_percent));
}

TEST(StereoctlDepth, WritesEveryRequestedFile)
{
    test::TempDir dir;
    const ProcessResult run = runProcess(
        depthCommand({"--depth", dir.file("d.png"), "--cloud", dir.file("c.ply"), "--colormap",
                      dir.file("c.png"), "--disparity", dir.file("d.png.pfm")}));
    ASSERT_EQ(run.exit_code, 0) << run.err;

    const cv::Mat depth_mm = cv::imread(dir.file("d.png"), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(depth_mm.type(), CV_16UC1);
    EXPECT_EQ(depth_mm.size(), cv::Size(384, 288));
    // Z = f*B/d: 615 px * 0.1 m over disparities 5..15 px lies between 4.1 and 12.3 m.
    cv::Mat valid = depth_mm > 0;
    double near_mm = 0.0, far_mm = 0.0;
    cv::minMaxLoc(depth_mm, &near_mm, &far_mm, nullptr, nullptr, valid);
    EXPECT_GE(near_mm, 615 * 0.1 / 16 * 1000 - 1);
    EXPECT_GT(cv::countNonZero(valid), depth_mm.total() / 2);

    const cv::Mat colormap = cv::imread(dir.file("c.png"), cv::IMREAD_UNCHANGED);
    EXPECT_EQ(colormap.type(), CV_8UC3);
    EXPECT_EQ(colormap.size(), cv::Size(384, 288));
    EXPECT_EQ(readDisparity(dir.file("d.png.pfm")).size(), cv::Size(384, 288));

    const ProcessResult head = runProcess({"/usr/bin/head", "-c", "3", dir.file("c.ply")});
    EXPECT_EQ(head.out, "ply");
}

TEST(StereoctlDepth, JsonCarriesReadingTimingsRangeAndMatcher)
{
    const ProcessResult run = runProcess(depthCommand({"--json", "--matcher", "sgbm-3way"}));
    ASSERT_EQ(run.exit_code, 0) << run.err;
    nlohmann::json out = nlohmann::json::parse(run.out); // missing keys read as null
    for (const char* key : {"valid", "distance_m", "stamp_ns", "frame", "valid_fraction",
                            "in_range_fraction", "region_pixels"}) {
        EXPECT_TRUE(out["reading"].contains(key)) << key;
    }
    EXPECT_TRUE(out["reading"]["valid"].get<bool>());
    // The reading is the 5th percentile of the centre region: the lamp and the head, whose
    // true disparities (about 10..14 px) put them between 4.4 and 6.2 m.
    const double distance_m = out["reading"]["distance_m"].get<double>();
    EXPECT_GT(distance_m, 615 * 0.1 / 16.0);
    EXPECT_LT(distance_m, 615 * 0.1 / 9.0);
    for (const char* stage : {"rectify", "match", "depth", "nearest", "cloud", "total"}) {
        ASSERT_TRUE(out["timings_ms"].contains(stage)) << stage;
        EXPECT_GE(out["timings_ms"][stage].get<double>(), 0.0);
    }
    EXPECT_EQ(out["disparity_range"]["num_disparities"], 16);
    EXPECT_EQ(out["disparity_range"]["min_disparity"], 0);
    EXPECT_EQ(out["matcher"], "sgbm-3way");
}

// The planar tuning (man-made scenes) reports more of the pair, the pixels it inferred
// rather than matched (bridged gaps) marked by the lowest confidence, 1.
TEST(StereoctlDepth, PlanarTuningReportsMoreAndMarksWhatItInferred)
{
    test::TempDir dir;
    struct Result {
        int reported = 0, lowest = 0;
    };
    const auto depth = [&](const std::string& name, std::vector<std::string> extra) {
        extra.insert(extra.end(), {"--disparity", dir.file(name + ".pfm"), "--confidence",
                                   dir.file(name + ".png")});
        const ProcessResult run = runProcess(depthCommand(extra));
        EXPECT_EQ(run.exit_code, 0) << name << ": " << run.err;
        const cv::Mat disparity = readDisparity(dir.file(name + ".pfm"));
        const cv::Mat confidence = cv::imread(dir.file(name + ".png"), cv::IMREAD_UNCHANGED);
        Result r;
        for (int y = 0; y < disparity.rows; ++y)
            for (int x = 0; x < disparity.cols; ++x) {
                r.reported += std::isfinite(disparity.at<float>(y, x)) ? 1 : 0;
                r.lowest += confidence.at<uint8_t>(y, x) == 1 ? 1 : 0;
            }
        return r;
    };
    const Result natural = depth("natural", {});
    const Result planar = depth("planar", {"--tuning", "planar"});
    EXPECT_GT(planar.reported, natural.reported);
    EXPECT_GT(planar.lowest, natural.lowest + 100);
}

TEST(StereoctlDepth, RegionWithoutEnoughPixelsIsNoReadingWithExitOne)
{
    // A sliver at the left edge, where no right-image match exists for 16 disparities.
    const ProcessResult run = runProcess(depthCommand({"--roi", "0,0.4,0.02,0.2"}));
    EXPECT_EQ(run.exit_code, 1) << run.out << run.err;
    EXPECT_EQ(run.out.rfind("no reading: ", 0), 0u) << run.out;
}

// A region from the left edge: the distance, and how much of the region cannot see that
// near (the right image holds no match there), in the report and the JSON.
TEST(StereoctlDepth, ARegionAtTheLeftEdgeSaysWhatItCannotSee)
{
    const ProcessResult run = runProcess(depthCommand({"--roi", "0,0.25,0.5,0.5"}));
    EXPECT_EQ(run.exit_code, 0) << run.out << run.err;
    EXPECT_EQ(run.out.rfind("nearest: ", 0), 0u) << run.out;
    EXPECT_NE(run.out.find("  LEFT EDGE: "), std::string::npos) << run.out;
    const ProcessResult json = runProcess(depthCommand({"--roi", "0,0.25,0.5,0.5", "--json"}));
    const nlohmann::json parsed = nlohmann::json::parse(json.out);
    EXPECT_GT(parsed["reading"]["out_of_view_fraction"].get<double>(), 0.0) << json.out;
    // The default region, a quarter in, sees tsukuba's 16 disparities whole.
    const ProcessResult centred = runProcess(depthCommand({}));
    EXPECT_EQ(centred.out.find("LEFT EDGE"), std::string::npos) << centred.out;
}

TEST(StereoctlDepth, BadArgumentsExitTwoWithOneLine)
{
    const std::vector<std::vector<std::string>> cases = {
        {stereoctlPath(), "depth", kLeft, kRight},                // no geometry
        {stereoctlPath(), "depth", kLeft, kRight, "--rectified"}, // no focal length
        {stereoctlPath(), "depth", kLeft},                        // no RIGHT
        depthCommand({"--matcher", "magic"}),
        depthCommand({"--tuning", "flat"}),
        depthCommand({"--max-disparity", "-16"}),
        depthCommand({"--roi", "0.5,0.5,0.9,0.9"}),
        depthCommand({"--calib", "/nonexistent/calib.yaml"}),
        depthCommand({"--no-such-option"}),
    };
    for (const auto& argv : cases) {
        const ProcessResult run = runProcess(argv);
        std::string shown;
        for (const auto& a : argv) {
            shown += a + " ";
        }
        EXPECT_EQ(run.exit_code, 2) << shown << "\n" << run.err;
        EXPECT_EQ(test::lineCount(run.err), 1u) << shown << "\n" << run.err;
        EXPECT_TRUE(run.out.empty()) << shown << "\n" << run.out;
    }
}

TEST(StereoctlDepth, UnreadableImageExitsTwoNamingTheFile)
{
    test::TempDir dir;
    const std::string missing = dir.file("missing.png");
    ProcessResult run = runProcess({stereoctlPath(), "depth", missing, kRight, "--rectified",
                                    "--focal-px", "615", "--baseline-m", "0.1"});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find(missing), std::string::npos) << run.err;

    // A file that exists but is no image.
    const std::string junk = dir.file("junk.png");
    ASSERT_EQ(runProcess({"/bin/cp", "/proc/self/status", junk}).exit_code, 0);
    run = runProcess({stereoctlPath(), "depth", kLeft, junk, "--rectified", "--focal-px", "615",
                      "--baseline-m", "0.1"});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find(junk), std::string::npos) << run.err;
}

TEST(StereoctlDepth, CalibrationForAnotherImageSizeIsRefused)
{
    test::TempDir dir;
    const std::string calib = dir.file("aloe.yaml");
    saveCalibration(makeRectifiedCalibration(cv::Size(1282, 1110), 3740.0, 0.16), calib);
    const ProcessResult run =
        runProcess({stereoctlPath(), "depth", kLeft, kRight, "--calib", calib});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find(kLeft), std::string::npos) << run.err;
}

TEST(StereoctlDepth, PairsOfDifferentSizeAreRefusedNamingBoth)
{
    const std::string aloe = test::opencvSamplesDir() + "/aloeR.jpg";
    const ProcessResult run = runProcess({stereoctlPath(), "depth", kLeft, aloe, "--rectified",
                                          "--focal-px", "615", "--baseline-m", "0.1"});
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find(kLeft), std::string::npos) << run.err;
    EXPECT_NE(run.err.find(aloe), std::string::npos) << run.err;
}

} // namespace
} // namespace stereod
