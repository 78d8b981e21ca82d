// Disparity accuracy on real scenes with ground truth, against OpenCV's own StereoSGBM /
// StereoBM run in the same test as the reference; and the nearest-object distance on the
// full-size Middlebury 2006 Aloe against the same statistic over its ground truth.
//
// Metrics (as in shared/data/README.md), over pixels with ground truth (GT > 0) only:
//   bad-2 (reported): of the pixels with a reported disparity, the % off by more than 2 px;
//   density: the % that got a reported disparity.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/matcher.hpp"
#include "pipeline/nearest_object.hpp"
#include "pipeline/stereo_processor.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

const std::string kMiddlebury = test::sharedDataDir() + "/middlebury/";
const std::string kSamples = test::opencvSamplesDir() + "/";

struct Metrics {
    double bad2_percent = 0.0;
    double density_percent = 0.0;
};

struct Scene {
    cv::Mat left; // CV_8UC1
    cv::Mat right;
    cv::Mat gt_px; // CV_32FC1, pixels, 0 = unknown
};

Scene loadScene(const std::string& left, const std::string& right, const std::string& gt,
                double gt_divisor)
{
    Scene s;
    s.left = cv::imread(left, cv::IMREAD_GRAYSCALE);
    s.right = cv::imread(right, cv::IMREAD_GRAYSCALE);
    const cv::Mat raw = cv::imread(gt, cv::IMREAD_GRAYSCALE);
    if (!s.left.empty() && !raw.empty())
        raw.convertTo(s.gt_px, CV_32FC1, 1.0 / gt_divisor);
    return s;
}

// disparity: CV_32FC1, +inf (or NaN) where nothing was reported.
Metrics evaluate(const cv::Mat& disparity, const cv::Mat& gt_px)
{
    long with_gt = 0, reported = 0, bad = 0;
    for (int y = 0; y < gt_px.rows; ++y)
        for (int x = 0; x < gt_px.cols; ++x) {
            const float g = gt_px.at<float>(y, x);
            if (g <= 0.0f)
                continue;
            ++with_gt;
            const float d = disparity.at<float>(y, x);
            if (!std::isfinite(d))
                continue;
            ++reported;
            if (std::abs(d - g) > 2.0f)
                ++bad;
        }
    Metrics m;
    m.bad2_percent = reported ? 100.0 * bad / reported : 100.0;
    m.density_percent = with_gt ? 100.0 * reported / with_gt : 0.0;
    return m;
}

// OpenCV's reference configuration from shared/data/README.md, converted independently
// of the pipeline: fixed point / 16, anything below min_disparity (0) invalid.
cv::Mat referencePixels(const cv::Mat& fixed)
{
    cv::Mat d(fixed.size(), CV_32FC1);
    for (int y = 0; y < fixed.rows; ++y)
        for (int x = 0; x < fixed.cols; ++x) {
            const short v = fixed.at<short>(y, x);
            d.at<float>(y, x) = v < 0 ? INFINITY : v / 16.0f;
        }
    return d;
}

cv::Mat openCvSgbm(const Scene& s, int num_disparities, int mode)
{
    auto sgbm = cv::StereoSGBM::create(0, num_disparities, 5, 200, 800, 1, 0, 10, 100, 2, mode);
    cv::Mat fixed;
    sgbm->compute(s.left, s.right, fixed);
    return referencePixels(fixed);
}

void printRow(const char* scene, const char* matcher, const Metrics& ours, const Metrics& ref)
{
    std::printf("[accuracy] %-8s %-10s ours: bad-2 %5.2f %% density %5.2f %% | "
                "OpenCV: bad-2 %5.2f %% density %5.2f %%\n",
                scene, matcher, ours.bad2_percent, ours.density_percent, ref.bad2_percent,
                ref.density_percent);
}

// Our processor through a rectified-only calibration. f*B = 10 px*m and doffs 0, so that
// min_depth_m picks the disparity range: d_max = 10 / min_depth_m.
DepthResult runOurs(const Scene& s, const ProcessorSettings& settings,
                    const StereoCalibration& calibration, int expected_num_disparities)
{
    StereoProcessor processor(calibration, settings);
    EXPECT_EQ(processor.disparityRange().num_disparities, expected_num_disparities);
    EXPECT_FALSE(processor.disparityRange().capped);
    DepthResult out;
    processor.process(s.left, s.right, 1, 0, out);
    return out;
}

// Tolerances against OpenCV's reference, chosen from measurements on these scenes.
// Ours runs the same OpenCV engines, but with pre_filter_cap 31 where the reference keeps
// OpenCV's default (which SGBM raises to 15); measured, that moves bad-2 by at most
// +0.13 points (venus) and density by at most -0.25 points (aloe). The slack leaves about
// four times that. Measured on tsukuba, it catches a wrong fixed-point scale (bad-2 near
// 100 %) and StereoBM's speckle range given in pixels instead of 1/16 px (density -4.1
// points); the uniqueness and left-right settings move these scenes by tenths only, so
// that they reach OpenCV is checked in processor_test instead.
constexpr double kBad2Slack = 0.5;    // percentage points worse than OpenCV at most
constexpr double kDensitySlack = 2.0; // percentage points lower than OpenCV at most

void compareSgbm(const char* name, const Scene& s, double min_depth_m, int num_disparities,
                 double max_bad2, double min_density)
{
    ASSERT_FALSE(s.left.empty() || s.right.empty() || s.gt_px.empty()) << name;
    ProcessorSettings settings;
    settings.matcher = matcherDefaults(MatcherKind::Sgbm, SgbmMode::Sgbm);
    settings.matcher.min_depth_m = min_depth_m;
    settings.compute_cloud = false;
    const StereoCalibration calibration = makeRectifiedCalibration(s.left.size(), 100.0, 0.1);
    const DepthResult out = runOurs(s, settings, calibration, num_disparities);

    const Metrics ours = evaluate(out.disparity, s.gt_px);
    const Metrics ref =
        evaluate(openCvSgbm(s, num_disparities, cv::StereoSGBM::MODE_SGBM), s.gt_px);
    printRow(name, "sgbm", ours, ref);
    EXPECT_LE(ours.bad2_percent, ref.bad2_percent + kBad2Slack) << name;
    EXPECT_GE(ours.density_percent, ref.density_percent - kDensitySlack) << name;
    EXPECT_LT(ours.bad2_percent, max_bad2) << name;
    EXPECT_GT(ours.density_percent, min_density) << name;
}

TEST(Accuracy, TsukubaSgbm)
{
    const Scene s = loadScene(kMiddlebury + "tsukuba/im3.png", kMiddlebury + "tsukuba/im4.png",
                              kMiddlebury + "tsukuba/disp3.pgm", 16.0);
    // README: OpenCV SGBM 4.2 % bad-2 at 98.3 % density.
    compareSgbm("tsukuba", s, 0.7, 16, 6.0, 90.0);
}

TEST(Accuracy, VenusSgbm)
{
    const Scene s = loadScene(kMiddlebury + "venus/im2.png", kMiddlebury + "venus/im6.png",
                              kMiddlebury + "venus/disp2.pgm", 8.0);
    // README: OpenCV SGBM 1.4 % bad-2 at 92.0 % density.
    compareSgbm("venus", s, 0.35, 32, 3.0, 85.0);
}

TEST(Accuracy, TsukubaBm)
{
    const Scene s = loadScene(kMiddlebury + "tsukuba/im3.png", kMiddlebury + "tsukuba/im4.png",
                              kMiddlebury + "tsukuba/disp3.pgm", 16.0);
    ASSERT_FALSE(s.left.empty() || s.gt_px.empty());
    ProcessorSettings settings;
    settings.matcher = matcherDefaults(MatcherKind::Bm);
    settings.matcher.block_size = 9;
    settings.matcher.min_depth_m = 0.7;
    settings.compute_cloud = false;
    const StereoCalibration calibration = makeRectifiedCalibration(s.left.size(), 100.0, 0.1);
    const DepthResult out = runOurs(s, settings, calibration, 16);

    // OpenCV's StereoBM with the same parameters; its speckle range is in 1/16 px.
    auto bm = cv::StereoBM::create(16, 9);
    bm->setUniquenessRatio(10);
    bm->setSpeckleWindowSize(100);
    bm->setSpeckleRange(2 * 16);
    bm->setDisp12MaxDiff(1);
    cv::Mat fixed;
    bm->compute(s.left, s.right, fixed);
    const Metrics ours = evaluate(out.disparity, s.gt_px);
    const Metrics ref = evaluate(referencePixels(fixed), s.gt_px);
    printRow("tsukuba", "bm", ours, ref);
    EXPECT_LE(ours.bad2_percent, ref.bad2_percent + kBad2Slack);
    EXPECT_GE(ours.density_percent, ref.density_percent - kDensitySlack);
    // Block matching (9x9) reports fewer pixels than SGBM; these bounds still reject a
    // matcher that is misconfigured (wrong range, wrong speckle units, no LR check).
    // Measured: 3.6 % bad-2 at 90.3 % density.
    EXPECT_LT(ours.bad2_percent, 6.0);
    EXPECT_GT(ours.density_percent, 80.0);
}

// The Middlebury 2006 full-size calibration: focal 3740 px, baseline 160 mm, doffs 270 px.
constexpr double kAloeFocalPx = 3740.0;
constexpr double kAloeBaselineM = 0.160;
constexpr double kAloeDoffsPx = 270.0;

// The same statistic as NearestObjectFinder, over the ground truth: the percentile (by
// sorting, independently of nth_element) of the in-range GT depths in the region.
double groundTruthNearest(const cv::Mat& gt_px, const NearestSettings& n,
                          const RectifiedGeometry& g)
{
    const cv::Rect r = regionPixels(n.roi, gt_px.size());
    std::vector<double> depths;
    for (int y = r.y; y < r.y + r.height; ++y)
        for (int x = r.x; x < r.x + r.width; ++x) {
            const float d = gt_px.at<float>(y, x);
            if (d <= 0.0f)
                continue;
            const double z = g.depthFromDisparity(d);
            if (z >= n.min_depth_m && z <= n.max_depth_m)
                depths.push_back(z);
        }
    if (depths.empty())
        return 0.0;
    std::sort(depths.begin(), depths.end());
    return depths[percentileIndex(n.percentile, depths.size())];
}

// The full-size Aloe SGBM_3WAY run is the heaviest case in the suite: it is computed once
// and every check on it lives in this one test (ctest runs each test in its own process).
TEST(Accuracy, AloeFullSizeSgbm3WayAndNearestDistance)
{
    const Scene s =
        loadScene(kSamples + "aloeL.jpg", kSamples + "aloeR.jpg", kSamples + "aloeGT.png", 1.0);
    ASSERT_FALSE(s.left.empty() || s.right.empty() || s.gt_px.empty())
        << "Aloe not found under " << kSamples << " (Debian package opencv-doc)";
    ASSERT_EQ(s.left.size(), cv::Size(1282, 1110));

    const StereoCalibration calibration = makeRectifiedCalibration(
        s.left.size(), kAloeFocalPx, kAloeBaselineM, std::nullopt, std::nullopt, kAloeDoffsPx);
    ProcessorSettings settings;
    settings.matcher = matcherDefaults(MatcherKind::Sgbm, SgbmMode::ThreeWay);
    // f*B / 1.15 m - doffs = 250.3 px: the range rounds up to 256 disparities.
    settings.matcher.min_depth_m = 1.15;
    settings.nearest.min_depth_m = 0.5;
    settings.nearest.max_depth_m = 10.0;
    StereoProcessor processor(calibration, settings);
    ASSERT_EQ(processor.disparityRange().num_disparities, 256);
    EXPECT_EQ(processor.matcherName(), "sgbm-3way");
    DepthResult out;
    processor.process(s.left, s.right, 123456789, 7, out);

    // Disparity accuracy against OpenCV's reference (README: 3.4 % bad-2, 68.8 % density).
    const Metrics ours = evaluate(out.disparity, s.gt_px);
    const Metrics ref = evaluate(openCvSgbm(s, 256, cv::StereoSGBM::MODE_SGBM_3WAY), s.gt_px);
    printRow("aloe", "sgbm-3way", ours, ref);
    EXPECT_LE(ours.bad2_percent, ref.bad2_percent + kBad2Slack);
    EXPECT_GE(ours.density_percent, ref.density_percent - kDensitySlack);
    EXPECT_LT(ours.bad2_percent, 6.0);
    EXPECT_GT(ours.density_percent, 60.0);

    // The left-most 255 columns cannot see their whole disparity range: never guessed.
    for (int y = 0; y < out.disparity.rows; y += 37)
        for (int x = 0; x < 255; ++x)
            ASSERT_TRUE(std::isinf(out.disparity.at<float>(y, x))) << x << "," << y;

    // The reading of the default region, against the same statistic over ground truth.
    const Reading& r = out.reading;
    ASSERT_TRUE(r.valid) << reasonText(r.reason);
    EXPECT_EQ(r.reason, NoReadingReason::None);
    EXPECT_EQ(r.stamp_ns, 123456789);
    EXPECT_EQ(r.frame, 7u);
    const double truth = groundTruthNearest(s.gt_px, settings.nearest, calibration.rectified);
    std::printf("[accuracy] aloe nearest (default region, 5th percentile): ours %.4f m, "
                "ground truth %.4f m, valid %.1f %%\n",
                r.distance_m, truth, 100.0 * r.valid_fraction);
    ASSERT_GT(truth, 0.0);
    EXPECT_NEAR(r.distance_m, truth, 0.03 * truth);
    EXPECT_GT(r.valid_fraction, settings.nearest.min_valid_fraction);

    NearestObjectFinder finder;
    // Another region and percentile: the lower-right quarter, the median.
    NearestSettings median = settings.nearest;
    median.roi = {0.5, 0.5, 0.45, 0.45};
    median.percentile = 50.0;
    const Reading m = finder.find(out.depth_m, median, 1, 1);
    const double median_truth = groundTruthNearest(s.gt_px, median, calibration.rectified);
    ASSERT_TRUE(m.valid) << reasonText(m.reason);
    EXPECT_NEAR(m.distance_m, median_truth, 0.03 * median_truth);

    // A depth range that excludes the whole scene (Aloe lies within 1.2..2.3 m).
    NearestSettings far = settings.nearest;
    far.min_depth_m = 5.0;
    far.max_depth_m = 20.0;
    const Reading f = finder.find(out.depth_m, far, 1, 1);
    EXPECT_FALSE(f.valid);
    EXPECT_EQ(f.reason, NoReadingReason::NothingInRange);
    EXPECT_GT(f.valid_fraction, far.min_valid_fraction);
    EXPECT_EQ(f.in_range_fraction, 0.0);

    // A region inside the columns the matcher cannot match: nothing valid at all.
    NearestSettings blind = settings.nearest;
    blind.roi = {0.0, 0.1, 0.15, 0.8};
    const Reading b = finder.find(out.depth_m, blind, 1, 1);
    EXPECT_FALSE(b.valid);
    EXPECT_EQ(b.reason, NoReadingReason::TooFewValidPixels);
    EXPECT_EQ(b.valid_fraction, 0.0);
    EXPECT_GT(b.region_pixels, 0u);
}

} // namespace
} // namespace stereod
