// What the depth map leaves out, counted in the reading. Surfaces hidden from the right
// camera: which unmeasured runs are shadows, the bound each pixel of one gets, and what
// the bounds do to a reading (never farther); the real Baumer rig's scene where a chair
// hidden behind a block read as the wall behind it; and its scenes whose near surface
// only the coarse level matches, read alike whatever the range.

#include <cmath>
#include <limits>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/calibration_formats.hpp"
#include "pipeline/hidden_surfaces.hpp"
#include "pipeline/matcher.hpp"
#include "pipeline/nearest_object.hpp"
#include "pipeline/stereo_processor.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

constexpr float kNone = std::numeric_limits<float>::infinity();

// One row: `left_px` of disparity `left`, `gap` unmeasured, then `right` to the end.
cv::Mat row(int left_px, float left, int gap, float right, int width = 120)
{
    cv::Mat d(1, width, CV_32FC1, cv::Scalar(right));
    d.colRange(0, left_px).setTo(left);
    d.colRange(left_px, left_px + gap).setTo(kNone);
    return d;
}

TEST(HiddenSurfaces, AShadowAsWideAsItsStepGetsTheRayPastTheEdge)
{
    // Background at 20 px, a near surface at 50 px: its shadow is 30 px wide.
    const cv::Mat d = row(40, 20.0f, 30, 50.0f);
    cv::Mat bound;
    hiddenSurfaceBounds(d, 0, 1, bound);
    for (int x = 0; x < 40; ++x)
        EXPECT_EQ(bound.at<float>(0, x), kNone) << x;
    // The pixel next to the edge (x 69, the edge at 70) can be at most 49 px; 30 px from
    // it, at most 20: the background's.
    for (int x = 40; x < 70; ++x)
        EXPECT_FLOAT_EQ(bound.at<float>(0, x), 50.0f - static_cast<float>(70 - x)) << x;
    for (int x = 70; x < 120; ++x)
        EXPECT_EQ(bound.at<float>(0, x), kNone) << x;
}

TEST(HiddenSurfaces, RunsOfAnotherWidthOrWithoutSurfacesAtBothEndsAreNotShadows)
{
    cv::Mat bound;
    const auto none = [&](const cv::Mat& d) {
        hiddenSurfaceBounds(d, 0, 1, bound);
        return cv::countNonZero(bound != kNone) == 0;
    };
    EXPECT_TRUE(none(row(40, 20.0f, 60, 50.0f))) << "twice as wide as the step";
    EXPECT_TRUE(none(row(40, 20.0f, 8, 50.0f))) << "a quarter of it";
    EXPECT_TRUE(none(row(40, 50.0f, 30, 20.0f))) << "the near surface on the left";
    EXPECT_TRUE(none(row(40, 20.0f, 2, 21.0f))) << "the same surface";
    EXPECT_TRUE(none(row(0, 20.0f, 30, 50.0f))) << "at the image's border";
    // A stray near match (2 px) at the run's end is not a surface.
    cv::Mat stray = row(40, 20.0f, 30, 20.0f);
    stray.colRange(70, 72).setTo(50.0f);
    EXPECT_TRUE(none(stray));
    // Rows outside the range asked are left as they were.
    cv::Mat two;
    cv::vconcat(row(40, 20.0f, 30, 50.0f), row(40, 20.0f, 30, 50.0f), two);
    bound = cv::Mat(2, 120, CV_32FC1, cv::Scalar(-1.0f));
    hiddenSurfaceBounds(two, 1, 2, bound);
    EXPECT_EQ(bound.at<float>(0, 50), -1.0f);
    EXPECT_FLOAT_EQ(bound.at<float>(1, 50), 30.0f);
}

NearestSettings wholeImage()
{
    NearestSettings s;
    s.roi = {0.0, 0.0, 1.0, 1.0};
    s.min_pixels = 10;
    return s;
}

TEST(HiddenSurfaces, BoundsBringAReadingNearerNeverFarther)
{
    // 100 x 100: a wall at 3 m, 6 % of it unmeasured and hidden no nearer than 1 m.
    cv::Mat depth(100, 100, CV_32FC1, cv::Scalar(3.0f));
    cv::Mat hidden(100, 100, CV_32FC1, cv::Scalar(0.0f));
    depth(cv::Rect(0, 0, 60, 10)).setTo(0.0f);
    hidden(cv::Rect(0, 0, 60, 10)).setTo(1.0f);
    NearestObjectFinder finder;
    const Reading without = finder.find(depth, wholeImage(), 0, 0);
    const Reading with =
        finder.find(depth, cv::Mat(), cv::Mat(), hidden, wholeImage(), NearFieldFacts{}, 0, 0);
    ASSERT_TRUE(without.valid && with.valid);
    EXPECT_FLOAT_EQ(without.distance_m, 3.0);
    EXPECT_FLOAT_EQ(with.distance_m, 1.0);
    EXPECT_DOUBLE_EQ(with.inferred_fraction, 0.06);
    EXPECT_DOUBLE_EQ(with.valid_fraction, 0.94) << "a bound is not a measured pixel";

    // An obstacle at 0.5 m on 6 % of the measured pixels; bounds (far ones, 2.5 m, on 30 %)
    // that would move the percentile's index past it must not carry the reading farther.
    cv::Mat near_depth(100, 100, CV_32FC1, cv::Scalar(3.0f));
    near_depth(cv::Rect(0, 0, 60, 7)).setTo(0.5f);
    near_depth(cv::Rect(0, 50, 100, 30)).setTo(0.0f);
    cv::Mat far_bounds(100, 100, CV_32FC1, cv::Scalar(0.0f));
    far_bounds(cv::Rect(0, 50, 100, 30)).setTo(2.5f);
    const Reading obstacle = finder.find(near_depth, cv::Mat(), cv::Mat(), far_bounds, wholeImage(),
                                         NearFieldFacts{}, 0, 0);
    ASSERT_TRUE(obstacle.valid);
    EXPECT_FLOAT_EQ(obstacle.distance_m, 0.5);
}

StereoCalibration baumerCalibration()
{
    const std::string baumer = test::sharedDataDir() + "/real-rig/baumer/";
    return importOpenCvStereoCalib(baumer + "Checkerboard_Baumer/intrinsics.yml",
                                   baumer + "Checkerboard_Baumer/extrinsics.yml", {696, 524});
}

// One of the Baumer rig's scenes (its files named "right" come from the calibration's left
// camera) through the default chain with `num_disparities`.
DepthResult baumerScene(const StereoCalibration& calibration, const char* scene,
                        int num_disparities)
{
    const std::string samples = test::sharedDataDir() + "/real-rig/baumer/samples_baumer/";
    ProcessorSettings settings;
    settings.matcher = matcherDefaults(MatcherKind::CensusSgm);
    if (num_disparities > 0)
        settings.matcher.num_disparities = num_disparities;
    settings.compute_cloud = false;
    StereoProcessor processor(calibration, settings);
    DepthResult out;
    processor.process(cv::imread(samples + "right" + scene + ".png", cv::IMREAD_GRAYSCALE),
                      cv::imread(samples + "left" + scene + ".png", cv::IMREAD_GRAYSCALE), 1, 0,
                      out);
    return out;
}

// The Baumer rig's scene 7 (shared/data/README.md; its files named "right" come from the
// calibration's left camera; its T is in the board's squares, read here as metres): a
// styrofoam block in the region's lower right corner, 0.5 away, hides from the right camera
// the chair left of it. With 256 disparities the block is within the range, but only its
// corner is in the region (1.4 %), fewer than the 5th percentile counts; the chair matches
// nothing; the measured pixels alone are the wall, 3.45 away: a lie. The chair's shadow is
// counted at the nearest it can be.
TEST(HiddenSurfaces, AChairHiddenBehindABlockIsNotReadAsTheWallBehindIt)
{
    const DepthResult out = baumerScene(baumerCalibration(), "07", 256);
    // The measured pixels alone: the wall.
    NearestObjectFinder measured_only;
    const Reading wall = measured_only.find(out.depth_m, out.confidence, out.near_field, cv::Mat(),
                                            NearestSettings{}, NearFieldFacts{}, 1, 0);
    ASSERT_TRUE(wall.valid);
    EXPECT_GT(wall.distance_m, 3.0);
    // With what the depth map leaves out: nearer than the chair can be (behind the block's edge, no
    // nearer than about 1.1) and not nearer than the block.
    ASSERT_TRUE(out.reading.valid) << reasonCode(out.reading.reason);
    EXPECT_LT(out.reading.distance_m, 1.1);
    EXPECT_GT(out.reading.distance_m, 0.45);
    EXPECT_GT(out.reading.inferred_fraction, 0.02);
    std::printf("[inferred] Baumer scene 7, 256 disparities: %.3f with %.1f %% of the region "
                "inferred (the measured pixels alone: %.3f)\n",
                out.reading.distance_m, 100.0 * out.reading.inferred_fraction, wall.distance_m);
}

// Scenes 5 and 6: a near surface at the region's foot (a desk in 6) that the full
// resolution leaves mostly empty and the coarse level matches. With 128 disparities it
// lies beyond the full range and the coarse level's match is in the depth map; with 256
// it lies within it, and the coarse level's match counts only in the reading. Either way
// the reading is the same: with the depth map's pixels alone, scene 6 read 0.81 at 128
// and 1.04 at 256, scene 5 1.25 and 1.35.
TEST(HiddenSurfaces, ANearSurfaceOnlyTheCoarseLevelMatchesReadsAlikeAtEveryRange)
{
    const StereoCalibration calibration = baumerCalibration();
    for (const char* scene : {"05", "06"}) {
        const DepthResult narrow = baumerScene(calibration, scene, 128);
        const DepthResult wide = baumerScene(calibration, scene, 256);
        ASSERT_TRUE(narrow.reading.valid && wide.reading.valid) << scene;
        EXPECT_NEAR(wide.reading.distance_m, narrow.reading.distance_m,
                    0.03 * narrow.reading.distance_m)
            << "scene " << scene;
        std::printf("[inferred] Baumer scene %s: %.3f with 128 disparities, %.3f with 256 "
                    "(%.1f %% of the region inferred)\n",
                    scene, narrow.reading.distance_m, wide.reading.distance_m,
                    100.0 * wide.reading.inferred_fraction);
    }
}

} // namespace
} // namespace stereod
