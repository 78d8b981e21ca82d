// The processor chain on a real pair (Middlebury tsukuba): disparity range, bad frames,
// buffer reuse, depth and cloud geometry, live settings.

#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "base/settings_error.hpp"
#include "pipeline/census_sgm_matcher.hpp"
#include "pipeline/matcher.hpp"
#include "pipeline/matcher_defaults.hpp"
#include "pipeline/stereo_processor.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

const std::string kTsukuba = test::sharedDataDir() + "/middlebury/tsukuba/";

RectifiedGeometry geometry(double focal_px, double baseline_m, double doffs_px)
{
    RectifiedGeometry g;
    g.image_size = {640, 480};
    g.focal_px = focal_px;
    g.baseline_m = baseline_m;
    g.doffs_px = doffs_px;
    return g;
}

DisparityRange rangeFor(double min_depth_m, const RectifiedGeometry& g, int cap = 256)
{
    MatcherSettings s;
    s.min_depth_m = min_depth_m;
    s.max_num_disparities = cap;
    return chooseDisparityRange(s, g);
}

TEST(DisparityRange, DerivedFromTheClosestDepth)
{
    // f*B = 84 px*m: 0.5 m is 168 px; disparities 0..168 need 169, rounded up to 176.
    const RectifiedGeometry g = geometry(700.0, 0.12, 0.0);
    const DisparityRange r = rangeFor(0.5, g);
    EXPECT_EQ(r.min_disparity, 0);
    EXPECT_EQ(r.num_disparities, 176);
    EXPECT_FALSE(r.capped);
    EXPECT_NEAR(r.range_closest_depth_m, 84.0 / 175.0, 1e-12);
    EXPECT_LE(r.range_closest_depth_m, 0.5);
    // census-sgm's extended range: the coarse level's 176 half-resolution disparities reach
    // twice as far, 0..350.
    EXPECT_TRUE(r.extended);
    EXPECT_EQ(r.last_disparity_px, 350);
    EXPECT_NEAR(r.closest_depth_m, 84.0 / 350.0, 1e-12);
}

TEST(DisparityRange, OnlyCensusSgmHasTheExtendedRange)
{
    const RectifiedGeometry g = geometry(700.0, 0.12, 0.0);
    MatcherSettings s = matcherDefaults(MatcherKind::Sgbm, SgbmMode::ThreeWay);
    s.min_depth_m = 0.5;
    DisparityRange r = chooseDisparityRange(s, g);
    EXPECT_FALSE(r.extended);
    EXPECT_EQ(r.last_disparity_px, 175);
    EXPECT_NEAR(r.closest_depth_m, r.range_closest_depth_m, 1e-12);
    s = matcherDefaults(MatcherKind::CensusSgm);
    s.min_depth_m = 0.5;
    s.extended_range = false;
    r = chooseDisparityRange(s, g);
    EXPECT_FALSE(r.extended);
    EXPECT_NEAR(r.closest_depth_m, 84.0 / 175.0, 1e-12);
}

// The cap keeps min_depth_m out of sight only when the extended range does not reach it.
TEST(DisparityRange, NotCappedWhenTheExtendedRangeReaches)
{
    const RectifiedGeometry g = geometry(700.0, 0.12, 0.0);
    const DisparityRange r = rangeFor(0.3, g); // wants 281: 256 searched, 510 measured
    EXPECT_EQ(r.num_disparities, 256);
    EXPECT_GT(r.range_closest_depth_m, 0.3);
    EXPECT_LE(r.closest_depth_m, 0.3);
    EXPECT_FALSE(r.capped);
}

TEST(DisparityRange, ExactMultipleBoundaries)
{
    const RectifiedGeometry g = geometry(100.0, 0.1, 0.0);   // f*B = 10
    EXPECT_EQ(rangeFor(10.0 / 15.0, g).num_disparities, 16); // d_max 15: 0..15
    EXPECT_EQ(rangeFor(10.0 / 16.0, g).num_disparities, 32); // d_max 16 needs a 17th
    EXPECT_EQ(rangeFor(100.0, g).num_disparities, 16);       // far: never below 16
}

TEST(DisparityRange, SubtractsDoffs)
{
    // Middlebury 2006 full size: f*B = 598.4, doffs 270; 1.15 m is 250.3 px.
    const DisparityRange r = rangeFor(1.15, geometry(3740.0, 0.16, 270.0));
    EXPECT_EQ(r.num_disparities, 256);
    EXPECT_FALSE(r.capped);
    EXPECT_NEAR(r.range_closest_depth_m, 598.4 / (255.0 + 270.0), 1e-12);
    EXPECT_NEAR(r.closest_depth_m, 598.4 / (510.0 + 270.0), 1e-12);
}

TEST(DisparityRange, CappedAtMaxNumDisparities)
{
    const RectifiedGeometry g = geometry(700.0, 0.12, 0.0);
    const DisparityRange r = rangeFor(0.1, g, 128); // wants 841 disparities
    EXPECT_EQ(r.num_disparities, 128);
    EXPECT_TRUE(r.capped);
    EXPECT_NEAR(r.range_closest_depth_m, 84.0 / 127.0, 1e-12);
    EXPECT_NEAR(r.closest_depth_m, 84.0 / 254.0, 1e-12);
    EXPECT_GT(r.closest_depth_m, 0.1);
}

TEST(DisparityRange, FixedNumberAndMinDisparity)
{
    MatcherSettings s;
    s.num_disparities = 64;
    s.min_disparity = 8;
    const DisparityRange r = chooseDisparityRange(s, geometry(700.0, 0.12, 0.0));
    EXPECT_EQ(r.num_disparities, 64);
    EXPECT_EQ(r.min_disparity, 8);
    EXPECT_FALSE(r.capped);
    EXPECT_NEAR(r.range_closest_depth_m, 84.0 / 71.0, 1e-12);
    // The coarse level searches 4..67 at half size: 8..134.
    EXPECT_NEAR(r.closest_depth_m, 84.0 / 134.0, 1e-12);
}

TEST(MatcherSettings, RejectsWhatOpenCvCannotRun)
{
    const auto message = [](const MatcherSettings& s) -> std::string {
        try {
            validateMatcherSettings(s);
        } catch (const std::invalid_argument& e) {
            return e.what();
        }
        return "";
    };
    EXPECT_EQ(message(MatcherSettings{}), "");
    // OpenCV's SGBM: its own limits
    const MatcherSettings opencv = matcherDefaults(MatcherKind::Sgbm);
    EXPECT_EQ(message(opencv), "");
    MatcherSettings s = opencv;
    s.block_size = 4;
    EXPECT_EQ(message(s), "block_size: must be odd, got 4");
    s = opencv;
    s.kind = MatcherKind::Bm;
    s.block_size = 3;
    EXPECT_EQ(message(s), "block_size: must be within 5..255, got 3");
    s = opencv;
    s.block_size = 33;
    EXPECT_EQ(message(s), "block_size: must be within 1..31, got 33");
    s = opencv;
    s.num_disparities = 20;
    EXPECT_EQ(message(s), "num_disparities: must be unset (derived from min_depth_m) or a "
                          "positive multiple of 16, got 20");
    s = opencv;
    s.p1 = 900; // p2 defaults to 800
    EXPECT_EQ(message(s), "p2: must be greater than p1 (800 <= 900)");
    s = opencv;
    s.min_depth_m = 0.0;
    EXPECT_EQ(message(s).rfind("min_depth_m: ", 0), 0u) << message(s);
    s = opencv;
    s.pre_filter_cap = 0;
    EXPECT_EQ(message(s), "pre_filter_cap: must be within 1..63, got 0");

    // census-sgm: its own limits, named by field.
    MatcherSettings census;
    census.kind = MatcherKind::CensusSgm;
    EXPECT_EQ(message(census), "");
    s = census;
    s.paths = 4;
    EXPECT_EQ(message(s), "paths: must be 3 or 5, got 4");
    s = census;
    s.p2 = 250; // with a 7x5 census (34 bits) the 8-bit path costs would overflow
    EXPECT_EQ(message(s).rfind("p2: census cost", 0), 0u) << message(s);
    s = census;
    s.num_disparities = 512;
    s.max_num_disparities = 512;
    EXPECT_NE(message(s).find("at most 256"), std::string::npos);
}

class Processor : public ::testing::Test {
  protected:
    void SetUp() override
    {
        left_colour_ = cv::imread(kTsukuba + "im3.png", cv::IMREAD_COLOR);
        right_colour_ = cv::imread(kTsukuba + "im4.png", cv::IMREAD_COLOR);
        ASSERT_FALSE(left_colour_.empty() || right_colour_.empty()) << kTsukuba;
        cv::cvtColor(left_colour_, left_, cv::COLOR_BGR2GRAY);
        cv::cvtColor(right_colour_, right_, cv::COLOR_BGR2GRAY);
        // f*B = 10 px*m with doffs 5: tsukuba's disparities 5..15 are 0.5 .. 1 m.
        calibration_ =
            makeRectifiedCalibration(left_.size(), 100.0, 0.1, std::nullopt, std::nullopt, 5.0);
        settings_.matcher.min_depth_m = 0.7; // 14.3 - 5: 16 disparities
        settings_.nearest.min_depth_m = 0.1;
        settings_.nearest.max_depth_m = 5.0;
    }

    cv::Mat left_colour_, right_colour_, left_, right_;
    StereoCalibration calibration_;
    ProcessorSettings settings_;
};

TEST_F(Processor, ProducesAReadingWithStampAndTimings)
{
    StereoProcessor p(calibration_, settings_);
    EXPECT_EQ(p.disparityRange().num_disparities, 16);
    EXPECT_EQ(p.matcherName(), "census-sgm"); // the default
    ProcessorSettings planar = settings_;
    planar.matcher.tuning = MatcherTuning::Planar;
    EXPECT_EQ(StereoProcessor(calibration_, planar).matcherName(), "census-sgm (planar)");
    DepthResult out;
    p.process(left_, right_, 1000, 3, out);
    ASSERT_TRUE(out.reading.valid) << reasonText(out.reading.reason);
    EXPECT_EQ(out.reading.stamp_ns, 1000);
    EXPECT_EQ(out.reading.frame, 3u);
    EXPECT_EQ(out.stamp_ns, 1000);
    EXPECT_EQ(out.frame, 3u);
    // The central region of tsukuba holds the lamp and the head, 8..14 px: 0.53..0.77 m.
    EXPECT_GT(out.reading.distance_m, 0.5);
    EXPECT_LT(out.reading.distance_m, 0.8);
    EXPECT_GT(out.timings.match_ms, 0.0);
    EXPECT_GE(out.timings.totalMs(), out.timings.match_ms);
}

// p2_gradient_scale unset: the tuning decides (natural adapts P2 at 3 grey levels, planar
// does not); a number sets it; 0 (the configuration's `off`) turns adaptation off, and on
// a real pair the depth differs from the automatic one.
// A region from the image's left edge: its first columns hold no match in the right image
// as near as the distance (at column x, disparities up to x less the margin). The reading
// keeps its number and says how much of the region that is; the default region, a quarter
// in, sees tsukuba's range whole.
TEST_F(Processor, AReadingSaysHowMuchOfItsRegionCannotSeeThatNear)
{
    ProcessorSettings edge = settings_;
    edge.nearest.roi = {0.0, 0.25, 0.5, 0.5};
    StereoProcessor p(calibration_, edge);
    DepthResult out;
    p.process(left_, right_, 1, 0, out);
    ASSERT_TRUE(out.reading.valid) << reasonText(out.reading.reason);
    // f*B = 10 px*m, doffs 5: the distance's disparity, and the columns short of it.
    const double disparity = 10.0 / out.reading.distance_m - 5.0;
    const int short_columns = static_cast<int>(std::ceil(disparity)) + kLeftEdgeMarginPx;
    const cv::Rect region = regionPixels(edge.nearest.roi, left_.size());
    EXPECT_NEAR(out.reading.out_of_view_fraction, static_cast<double>(short_columns) / region.width,
                1e-9);

    StereoProcessor centred(calibration_, settings_);
    centred.process(left_, right_, 2, 0, out);
    ASSERT_TRUE(out.reading.valid) << reasonText(out.reading.reason);
    EXPECT_EQ(out.reading.out_of_view_fraction, 0.0);
}

TEST_F(Processor, GradientScaleUnsetIsTheTuningsAndZeroTurnsAdaptationOff)
{
    const DisparityRange range{0, 16};
    MatcherSettings unset;
    EXPECT_EQ(censusSgmSettings(unset, range).p2_gradient_scale, 3);
    MatcherSettings planar;
    planar.tuning = MatcherTuning::Planar;
    EXPECT_EQ(censusSgmSettings(planar, range).p2_gradient_scale, 0);
    MatcherSettings set;
    set.p2_gradient_scale = 7;
    EXPECT_EQ(censusSgmSettings(set, range).p2_gradient_scale, 7);
    MatcherSettings off;
    off.p2_gradient_scale = 0;
    EXPECT_EQ(censusSgmSettings(off, range).p2_gradient_scale, 0);
    // Off changes nothing else the core gets.
    sgm::CensusSgmSettings expected = censusSgmSettings(unset, range);
    expected.p2_gradient_scale = 0;
    const sgm::CensusSgmSettings core_off = censusSgmSettings(off, range);
    EXPECT_EQ(std::memcmp(&expected, &core_off, sizeof expected), 0);

    DepthResult automatic_out;
    StereoProcessor(calibration_, settings_).process(left_, right_, 0, 0, automatic_out);
    ProcessorSettings no_adaptation = settings_;
    no_adaptation.matcher.p2_gradient_scale = 0;
    DepthResult off_out;
    StereoProcessor(calibration_, no_adaptation).process(left_, right_, 0, 0, off_out);
    cv::Mat differs;
    cv::compare(automatic_out.disparity, off_out.disparity, differs, cv::CMP_NE);
    EXPECT_GT(cv::countNonZero(differs), 100);
}

// effectiveMatcherSettings: every automatic setting gets its matcher's (tuning's) value,
// what is set stays, and census-sgm's own settings stay unset for OpenCV's matchers.
TEST(MatcherDefaults, EachMatcherAndTuningHasItsValues)
{
    const MatcherSettings natural = effectiveMatcherSettings({});
    EXPECT_EQ(natural.uniqueness_ratio, sgm::kNaturalSceneSettings.uniqueness_percent);
    EXPECT_EQ(natural.census_width, sgm::kNaturalSceneSettings.census_width);
    EXPECT_EQ(natural.paths, sgm::kNaturalSceneSettings.paths);
    EXPECT_EQ(natural.p1, sgm::kNaturalSceneSettings.p1);
    EXPECT_EQ(natural.threads, automaticMatcherThreads());
    EXPECT_FALSE(natural.num_disparities); // the calibration decides it
    for (const MatcherTuning tuning : {MatcherTuning::Planar, MatcherTuning::Patterns}) {
        MatcherSettings s;
        s.tuning = tuning;
        const MatcherSettings e = effectiveMatcherSettings(s);
        EXPECT_EQ(e.speckle_window_px, censusSgmTuning(tuning).speckle_window_px);
        EXPECT_EQ(e.p2_gradient_scale, censusSgmTuning(tuning).p2_gradient_scale);
    }
    for (const MatcherAlgorithm& algorithm : kMatcherAlgorithms) {
        if (algorithm.kind == MatcherKind::CensusSgm)
            continue;
        MatcherSettings s = matcherDefaults(algorithm.kind, algorithm.mode);
        s.block_size = 7;
        s.lr_max_diff_px = 3;
        const MatcherSettings e = effectiveMatcherSettings(s);
        EXPECT_EQ(e.uniqueness_ratio, 10) << algorithm.name;
        EXPECT_EQ(e.speckle_window_px, 100) << algorithm.name;
        EXPECT_EQ(e.lr_max_diff_px, 3) << algorithm.name;
        EXPECT_EQ(e.p1, 8 * 49) << algorithm.name;
        EXPECT_EQ(e.p2, 32 * 49) << algorithm.name;
        EXPECT_FALSE(e.census_width || e.paths || e.p2_gradient_scale || e.threads)
            << algorithm.name;
    }
}

TEST_F(Processor, LeftColumnsThatCannotBeMatchedAreInvalid)
{
    // OpenCV's matchers leave the whole band invalid.
    settings_.matcher.kind = MatcherKind::Sgbm;
    StereoProcessor p(calibration_, settings_);
    DepthResult out;
    p.process(left_, right_, 0, 0, out);
    for (int y = 0; y < out.disparity.rows; ++y)
        for (int x = 0; x < 15; ++x) {
            ASSERT_TRUE(std::isinf(out.disparity.at<float>(y, x))) << x << "," << y;
            ASSERT_EQ(out.depth_m.at<float>(y, x), 0.0f);
            ASSERT_EQ(out.confidence.at<uint8_t>(y, x), 0);
        }
}

// census-sgm searches what lies inside the image where the edge cuts the range, and keeps a
// disparity only well below the cut (a true match beyond the edge would read too far).
TEST_F(Processor, LeftBandKeepsOnlyDisparitiesWellBelowTheCut)
{
    settings_.matcher.kind = MatcherKind::CensusSgm;
    StereoProcessor p(calibration_, settings_);
    DepthResult out;
    p.process(left_, right_, 0, 0, out);
    int kept = 0;
    for (int y = 0; y < out.disparity.rows; ++y)
        for (int x = 0; x < 15; ++x) {
            const float d = out.disparity.at<float>(y, x);
            if (std::isinf(d)) {
                ASSERT_EQ(out.confidence.at<uint8_t>(y, x), 0);
                continue;
            }
            ++kept;
            ASSERT_LE(d, static_cast<float>(x - 4) + 0.5f) << x << "," << y;
            ASSERT_GT(out.confidence.at<uint8_t>(y, x), 0);
        }
    EXPECT_GT(kept, 0);
}

// The two views of a pair need not share a row stride (the halves of a side-by-side
// frame beside a copy): census-sgm gives the same disparities either way.
TEST_F(Processor, CensusSgmTakesViewsOfDifferentStrides)
{
    const MatcherSettings settings = matcherDefaults(MatcherKind::CensusSgm);
    const DisparityRange range{0, 16, 0.0, false};
    const std::unique_ptr<Matcher> matcher = makeMatcher(settings, range);
    MatchOutput same, mixed;
    const cv::Rect whole(0, 0, left_.cols, left_.rows);
    matcher->compute(left_, right_, whole, same);
    cv::Mat wide(left_.rows, left_.cols + 40, CV_8UC1, cv::Scalar(0));
    left_.copyTo(wide(cv::Rect(0, 0, left_.cols, left_.rows)));
    const cv::Mat left_view = wide(cv::Rect(0, 0, left_.cols, left_.rows));
    ASSERT_NE(left_view.step, right_.step);
    matcher->compute(left_view, right_, whole, mixed);
    EXPECT_EQ(cv::norm(same.disparity_px != mixed.disparity_px, cv::NORM_L1), 0.0);
    EXPECT_EQ(cv::norm(same.confidence, mixed.confidence, cv::NORM_INF), 0.0);
}

TEST_F(Processor, DepthAndCloudFollowTheGeometry)
{
    StereoProcessor p(calibration_, settings_);
    DepthResult out;
    p.process(left_, right_, 0, 0, out);
    const RectifiedGeometry& g = calibration_.rectified;
    size_t valid = 0;
    for (int v = 0; v < out.depth_m.rows; ++v)
        for (int u = 0; u < out.depth_m.cols; ++u) {
            const float d = out.disparity.at<float>(v, u);
            const float z = out.depth_m.at<float>(v, u);
            if (std::isfinite(d)) {
                ASSERT_NEAR(z, 10.0 / (d + 5.0), 1e-6) << u << "," << v;
                ++valid;
            } else {
                ASSERT_EQ(z, 0.0f);
            }
        }
    ASSERT_EQ(out.cloud.size(), valid);
    // Every point projects back to its pixel, with that depth and that grey level, in the
    // pixels' row-major order (the rows are built in stripes on several threads).
    size_t i = 0;
    for (int vi = 0; vi < out.depth_m.rows; ++vi)
        for (int ui = 0; ui < out.depth_m.cols; ++ui) {
            if (!(out.depth_m.at<float>(vi, ui) > 0.0f))
                continue;
            const CloudPoint& pt = out.cloud[i++];
            const double u = pt.x * g.focal_px / pt.z + g.cx_px;
            const double v = pt.y * g.focal_px / pt.z + g.cy_px;
            ASSERT_NEAR(u, ui, 1e-3) << "point " << i - 1;
            ASSERT_NEAR(v, vi, 1e-3) << "point " << i - 1;
            ASSERT_EQ(pt.z, out.depth_m.at<float>(vi, ui));
            ASSERT_EQ(pt.intensity, static_cast<float>(out.left_rectified.at<uint8_t>(vi, ui)));
        }
    EXPECT_EQ(i, out.cloud.size());
}

// output.max_depth_m: the depth image and the cloud leave out what lies beyond the cap; the
// reading, made from the whole depth, is the same with or without it.
TEST_F(Processor, OutputsLeaveOutDepthsBeyondTheCapAndTheReadingStays)
{
    // The default: where one pixel of disparity is a quarter of the depth, f*B / 4 px.
    StereoProcessor automatic(calibration_, settings_);
    EXPECT_DOUBLE_EQ(defaultMaxOutputDepth(calibration_.rectified), 2.5);
    EXPECT_DOUBLE_EQ(automatic.maxOutputDepth(), 2.5);
    ProcessorSettings whole = settings_;
    whole.output.max_depth_m = 100.0;
    ProcessorSettings capped = settings_;
    capped.output.max_depth_m = 0.7; // tsukuba's 0.5 .. 1 m, cut in the middle
    StereoProcessor p_whole(calibration_, whole);
    StereoProcessor p_capped(calibration_, capped);
    EXPECT_DOUBLE_EQ(p_capped.maxOutputDepth(), 0.7);
    DepthResult all, cut;
    p_whole.process(left_, right_, 0, 0, all);
    p_capped.process(left_, right_, 0, 0, cut);

    std::size_t kept = 0, dropped = 0;
    for (int v = 0; v < all.depth_m.rows; ++v)
        for (int u = 0; u < all.depth_m.cols; ++u) {
            const float z = all.depth_m.at<float>(v, u);
            const float c = cut.depth_m.at<float>(v, u);
            if (z > 0.7f) {
                ASSERT_EQ(c, 0.0f) << u << "," << v;
                ++dropped;
            } else {
                ASSERT_EQ(c, z) << u << "," << v;
                kept += z > 0.0f;
            }
        }
    EXPECT_GT(dropped, 10000u);
    EXPECT_GT(kept, 10000u);
    ASSERT_EQ(cut.cloud.size(), kept);
    for (const CloudPoint& point : cut.cloud)
        ASSERT_LE(point.z, 0.7f);
    // The same reading from both.
    EXPECT_EQ(cut.reading.valid, all.reading.valid);
    EXPECT_EQ(cut.reading.distance_m, all.reading.distance_m);
    EXPECT_EQ(cut.reading.valid_fraction, all.reading.valid_fraction);
    EXPECT_EQ(cut.reading.in_range_fraction, all.reading.in_range_fraction);

    // Live: a new cap applies to the next pair; a cap of 0 is refused.
    capped.output.max_depth_m = 0.6;
    p_capped.updateSettings(capped);
    EXPECT_DOUBLE_EQ(p_capped.maxOutputDepth(), 0.6);
    capped.output.max_depth_m = 0.0;
    EXPECT_THROW(p_capped.updateSettings(capped), std::invalid_argument);
    EXPECT_DOUBLE_EQ(p_capped.maxOutputDepth(), 0.6);
}

TEST_F(Processor, NoReallocationAcrossFrames)
{
    StereoProcessor p(calibration_, settings_);
    DepthResult out;
    p.process(left_, right_, 0, 0, out);
    const uint8_t* left_data = out.left_rectified.data;
    const uint8_t* disparity_data = out.disparity.data;
    const uint8_t* depth_data = out.depth_m.data;
    const CloudPoint* cloud_data = out.cloud.data();
    const size_t cloud_capacity = out.cloud.capacity();
    EXPECT_GE(cloud_capacity, left_.total());
    // Another pair (flipped, so that the content differs) of the same size.
    cv::Mat left2, right2;
    cv::flip(right_, left2, 1);
    cv::flip(left_, right2, 1);
    p.process(left2, right2, 1, 1, out);
    EXPECT_EQ(out.left_rectified.data, left_data);
    EXPECT_EQ(out.disparity.data, disparity_data);
    EXPECT_EQ(out.depth_m.data, depth_data);
    EXPECT_EQ(out.cloud.data(), cloud_data);
    EXPECT_EQ(out.cloud.capacity(), cloud_capacity);
}

TEST_F(Processor, BadFramesGiveAReasonNotAnException)
{
    StereoProcessor p(calibration_, settings_);
    DepthResult out;
    p.process(left_, right_, 0, 0, out);
    ASSERT_TRUE(out.reading.valid);
    ASSERT_FALSE(out.cloud.empty());

    const auto expectBad = [&](const cv::Mat& l, const cv::Mat& r, const char* what) {
        p.process(l, r, 77, 5, out);
        EXPECT_FALSE(out.reading.valid) << what;
        EXPECT_EQ(out.reading.reason, NoReadingReason::BadFrame) << what;
        EXPECT_EQ(out.reading.stamp_ns, 77) << what;
        EXPECT_EQ(out.reading.frame, 5u) << what;
        // Nothing of the previous good frame is left to pass for this one.
        EXPECT_TRUE(out.cloud.empty()) << what;
        EXPECT_EQ(cv::countNonZero(out.depth_m), 0) << what;
    };
    expectBad(left_, right_(cv::Rect(0, 0, right_.cols - 1, right_.rows)).clone(), "size mismatch");
    expectBad(left_(cv::Rect(0, 0, 200, 200)).clone(), right_(cv::Rect(0, 0, 200, 200)).clone(),
              "both the wrong size");
    expectBad(cv::Mat(), right_, "empty left");
    expectBad(left_, cv::Mat(), "empty right");
    cv::Mat left16;
    left_.convertTo(left16, CV_16U, 256.0);
    expectBad(left16, right_, "16-bit");
    cv::Mat two_channel(left_.size(), CV_8UC2, cv::Scalar(1, 2));
    expectBad(two_channel, right_, "2 channels");

    // And the next good pair is processed as usual.
    p.process(left_, right_, 78, 6, out);
    EXPECT_TRUE(out.reading.valid);
}

TEST_F(Processor, ColourInputIsConvertedToGrey)
{
    StereoProcessor p(calibration_, settings_);
    DepthResult grey, colour;
    p.process(left_, right_, 0, 0, grey);
    p.process(left_colour_, right_colour_, 0, 0, colour);
    EXPECT_EQ(cv::norm(grey.left_rectified, colour.left_rectified, cv::NORM_INF), 0.0);
    cv::Mat same;
    cv::compare(grey.disparity, colour.disparity, same, cv::CMP_EQ);
    EXPECT_EQ(cv::countNonZero(same), static_cast<int>(grey.disparity.total()));
}

// The colour goes to the outputs and nowhere else: the matcher sees the same grey, the
// rectified colour is the left camera's (a rectified-only calibration copies it), and
// every cloud point gets the colour of its own pixel, in the cloud's order.
TEST_F(Processor, ColourLeftRidesAlongToTheOutputs)
{
    StereoProcessor p(calibration_, settings_);
    DepthResult grey, colour;
    p.process(left_, right_, 0, 0, grey);
    p.process(left_, left_colour_, right_, 0, 0, colour);
    EXPECT_TRUE(grey.left_rectified_colour.empty());
    EXPECT_TRUE(grey.cloud_colour.empty());

    EXPECT_EQ(cv::norm(grey.disparity, colour.disparity, cv::NORM_INF), 0.0);
    EXPECT_EQ(grey.reading.distance_m, colour.reading.distance_m);
    ASSERT_EQ(colour.left_rectified_colour.type(), CV_8UC3);
    EXPECT_EQ(cv::norm(colour.left_rectified_colour, left_colour_, cv::NORM_INF), 0.0);
    ASSERT_EQ(colour.cloud_colour.size(), colour.cloud.size());
    ASSERT_GT(colour.cloud.size(), colour.depth_m.total() / 2);
    size_t i = 0;
    size_t wrong = 0;
    for (int v = 0; v < colour.depth_m.rows; ++v)
        for (int u = 0; u < colour.depth_m.cols; ++u) {
            if (!(colour.depth_m.at<float>(v, u) > 0.0f))
                continue;
            const cv::Vec3b bgr = left_colour_.at<cv::Vec3b>(v, u);
            const CloudColour c = colour.cloud_colour[i++];
            wrong += (c.r != bgr[2] || c.g != bgr[1] || c.b != bgr[0]) ? 1 : 0;
        }
    EXPECT_EQ(i, colour.cloud.size());
    EXPECT_EQ(wrong, 0u);
    // Tsukuba is colourful: the channels differ, so a swap of red and blue would show.
    EXPECT_GT(cv::norm(colour.left_rectified_colour.reshape(1), cv::NORM_L1), 0.0);

    // Buffers kept from frame to frame, as for the grey outputs.
    const uint8_t* colour_data = colour.left_rectified_colour.data;
    const CloudColour* cloud_colour_data = colour.cloud_colour.data();
    p.process(left_, left_colour_, right_, 1, 1, colour);
    EXPECT_EQ(colour.left_rectified_colour.data, colour_data);
    EXPECT_EQ(colour.cloud_colour.data(), cloud_colour_data);

    // A colour image that does not fit the left one is a bad frame, not an exception.
    cv::Mat small;
    cv::resize(left_colour_, small, cv::Size(64, 48));
    p.process(left_, small, right_, 2, 2, colour);
    EXPECT_FALSE(colour.reading.valid);
    EXPECT_TRUE(colour.left_rectified_colour.empty());
    EXPECT_TRUE(colour.cloud_colour.empty());
}

TEST_F(Processor, CloudSkippedWhenNotWanted)
{
    settings_.compute_cloud = false;
    StereoProcessor p(calibration_, settings_);
    DepthResult out;
    p.process(left_, right_, 0, 0, out);
    EXPECT_TRUE(out.reading.valid);
    EXPECT_TRUE(out.cloud.empty());
    EXPECT_EQ(out.cloud.capacity(), 0u); // never built, not built and thrown away
}

// The matcher names its own field; the processor, which holds its settings as `matcher`,
// names it from there: "matcher.paths", the way config/ shows it to the user.
TEST_F(Processor, NamesTheFieldOfItsOwnSettings)
{
    ProcessorSettings bad = settings_;
    bad.matcher.kind = MatcherKind::CensusSgm;
    bad.matcher.paths = 4;
    try {
        validateProcessorSettings(bad, calibration_.rectified);
        FAIL() << "paths 4 accepted";
    } catch (const SettingsError& e) {
        EXPECT_EQ(e.field(), "matcher.paths");
        EXPECT_EQ(std::string(e.what()), "matcher.paths: must be 3 or 5, got 4");
    }
    bad = settings_;
    bad.nearest.min_pixels = 0;
    try {
        validateProcessorSettings(bad, calibration_.rectified);
        FAIL() << "min_pixels 0 accepted";
    } catch (const SettingsError& e) {
        EXPECT_EQ(e.field(), "nearest.min_pixels");
    }
}

TEST_F(Processor, UpdateSettingsAppliesLiveAndRejectsInvalid)
{
    settings_.matcher.kind = MatcherKind::CensusSgm;
    StereoProcessor p(calibration_, settings_);
    ProcessorSettings bad = settings_;
    bad.matcher.paths = 4;
    EXPECT_THROW(p.updateSettings(bad), std::invalid_argument);
    EXPECT_EQ(p.settings().matcher.paths, settings_.matcher.paths);
    EXPECT_EQ(p.matcherName(), "census-sgm");

    ProcessorSettings sgbm = settings_;
    sgbm.matcher.kind = MatcherKind::Sgbm;
    p.updateSettings(sgbm);
    EXPECT_EQ(p.matcherName(), "sgbm");
    bad = sgbm;
    bad.matcher.block_size = 6;
    EXPECT_THROW(p.updateSettings(bad), std::invalid_argument);
    EXPECT_EQ(p.settings().matcher.block_size, settings_.matcher.block_size);
    EXPECT_EQ(p.matcherName(), "sgbm");

    bad = settings_;
    bad.nearest.percentile = -1.0;
    EXPECT_THROW(p.updateSettings(bad), std::invalid_argument);
    EXPECT_EQ(p.settings().nearest.percentile, settings_.nearest.percentile);

    ProcessorSettings bm = settings_;
    bm.matcher.kind = MatcherKind::Bm;
    bm.matcher.block_size = 9;
    bm.matcher.min_depth_m = 0.45; // 22.2 - 5: 32 disparities
    p.updateSettings(bm);
    EXPECT_EQ(p.matcherName(), "bm");
    EXPECT_EQ(p.disparityRange().num_disparities, 32);
    DepthResult out;
    p.process(left_, right_, 0, 0, out);
    EXPECT_TRUE(out.reading.valid) << reasonText(out.reading.reason);
    for (int x = 0; x < 31; ++x)
        EXPECT_TRUE(std::isinf(out.disparity.at<float>(100, x))) << x;

    ProcessorSettings three_way = sgbm;
    three_way.matcher.sgbm_mode = SgbmMode::ThreeWay;
    p.updateSettings(three_way);
    EXPECT_EQ(p.matcherName(), "sgbm-3way");
}

// Each filter, switched off, lets more pixels through: the settings reach OpenCV.
TEST_F(Processor, MatcherSettingsReachOpenCv)
{
    const auto validPixels = [&](const ProcessorSettings& s) {
        StereoProcessor p(calibration_, s);
        DepthResult out;
        p.process(left_, right_, 0, 0, out);
        return cv::countNonZero(out.depth_m);
    };
    ProcessorSettings bm = settings_;
    bm.matcher.kind = MatcherKind::Bm;
    bm.matcher.block_size = 9;
    const int bm_valid = validPixels(bm);

    ProcessorSettings no_lr = bm;
    no_lr.matcher.lr_max_diff_px = -1;
    EXPECT_GT(validPixels(no_lr), bm_valid);

    ProcessorSettings no_speckle = bm;
    no_speckle.matcher.speckle_window_px = 0;
    EXPECT_GT(validPixels(no_speckle), bm_valid);

    // A narrower speckle range cuts the map into more small blobs, which are removed.
    ProcessorSettings tight_speckle = bm;
    tight_speckle.matcher.speckle_range_px = 1;
    EXPECT_LT(validPixels(tight_speckle), bm_valid);

    ProcessorSettings textureless = bm;
    textureless.matcher.texture_threshold = 1000000;
    EXPECT_EQ(validPixels(textureless), 0);

    const int sgbm_valid = validPixels(settings_);
    ProcessorSettings no_uniqueness = settings_;
    no_uniqueness.matcher.uniqueness_ratio = 0;
    EXPECT_GT(validPixels(no_uniqueness), sgbm_valid);
}

TEST_F(Processor, RejectsARangeWiderThanTheImage)
{
    settings_.matcher.num_disparities = 400; // tsukuba is 384 px wide
    settings_.matcher.max_num_disparities = 512;
    EXPECT_THROW(StereoProcessor(calibration_, settings_), std::invalid_argument);
}

TEST_F(Processor, RejectsAnInvalidCalibration)
{
    StereoCalibration broken = calibration_;
    broken.rectified.baseline_m = -0.1;
    EXPECT_THROW(StereoProcessor(broken, settings_), CalibrationError);
}

TEST(FixedPoint, ConvertsSixteenthsAndMarksInvalid)
{
    DisparityRange range;
    range.min_disparity = 0;
    range.num_disparities = 16;
    cv::Mat fixed(1, 20, CV_16SC1, cv::Scalar(-16)); // OpenCV's "invalid" for min 0
    fixed.at<int16_t>(0, 16) = 16 * 12 + 8;          // 12.5 px
    fixed.at<int16_t>(0, 17) = 0;                    // 0 px is a valid disparity
    fixed.at<int16_t>(0, 5) = 16 * 3;                // inside the unmatched columns
    cv::Mat d;
    fixedPointToPixels(fixed, range, d);
    ASSERT_EQ(d.type(), CV_32FC1);
    EXPECT_EQ(d.at<float>(0, 16), 12.5f);
    EXPECT_EQ(d.at<float>(0, 17), 0.0f);
    EXPECT_TRUE(std::isinf(d.at<float>(0, 5)));
    EXPECT_TRUE(std::isinf(d.at<float>(0, 18)));
}

} // namespace
} // namespace stereod
