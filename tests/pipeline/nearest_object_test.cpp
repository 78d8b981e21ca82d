// The nearest-object statistic and its refusals, on depth maps whose answer is known.

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "pipeline/nearest_object.hpp"

namespace stereod {
namespace {

NearestSettings wholeImage()
{
    NearestSettings s;
    s.roi = {0.0, 0.0, 1.0, 1.0};
    s.min_depth_m = 0.1;
    s.max_depth_m = 20.0;
    s.percentile = 5.0;
    s.min_valid_fraction = 0.10;
    s.min_pixels = 50;
    return s;
}

TEST(NearestObject, RegionPixelsScaleWithTheImage)
{
    EXPECT_EQ(regionPixels({0.25, 0.25, 0.5, 0.5}, {640, 480}), cv::Rect(160, 120, 320, 240));
    EXPECT_EQ(regionPixels({0.0, 0.0, 1.0, 1.0}, {1282, 1110}), cv::Rect(0, 0, 1282, 1110));
    // Clipped to the image, never outside it.
    EXPECT_EQ(regionPixels({0.9, 0.9, 0.2, 0.2}, {100, 100}), cv::Rect(90, 90, 10, 10));
}

// The demo's rig (focal 515.4 px, baseline 83.16 mm, 640x480) at the default range, 192
// disparities with the extended range: the default region starts at column 160, which
// holds disparities up to 156 in the right image.
TEST(NearestObject, TheRegionsLeftColumnsNearTheImageEdgeSeeLessNear)
{
    RectifiedGeometry rig;
    rig.image_size = {640, 480};
    rig.focal_px = 515.4;
    rig.baseline_m = 0.08316;
    const cv::Rect region = regionPixels({0.25, 0.25, 0.5, 0.5}, {640, 480});

    const LeftEdgeView view = leftEdgeView(region, 191, rig);
    EXPECT_EQ(view.first_column, 160);
    EXPECT_EQ(view.columns, 320);
    EXPECT_EQ(view.short_columns, 35); // columns 160..194 cannot see disparity 191
    EXPECT_NEAR(view.nearest_seen_m, 515.4 * 0.08316 / 156, 1e-9);

    // The full-resolution range alone (96 disparities) is seen from column 99 on.
    EXPECT_EQ(leftEdgeView(region, 95, rig).short_columns, 0);
    // A region from the edge sees nothing at its first columns, every column short.
    const LeftEdgeView edge = leftEdgeView(cv::Rect(2, 0, 20, 10), 191, rig);
    EXPECT_EQ(edge.short_columns, 20);
    EXPECT_TRUE(std::isinf(edge.nearest_seen_m));
}

TEST(NearestObject, PercentileIndex)
{
    EXPECT_EQ(percentileIndex(0.0, 100), 0u);
    EXPECT_EQ(percentileIndex(100.0, 100), 99u);
    EXPECT_EQ(percentileIndex(50.0, 101), 50u);
    EXPECT_EQ(percentileIndex(5.0, 1), 0u);
}

TEST(NearestObject, ReportsThePercentileOfInRangeDepths)
{
    // 100 x 100 image: depths 1.00, 1.01, ... 100 distinct values per row, same per column.
    cv::Mat depth(100, 100, CV_32FC1);
    for (int y = 0; y < depth.rows; ++y)
        for (int x = 0; x < depth.cols; ++x)
            depth.at<float>(y, x) = 1.0f + 0.01f * static_cast<float>(x);
    NearestObjectFinder finder(depth.total());
    const Reading r = finder.find(depth, wholeImage(), 42, 9);
    ASSERT_TRUE(r.valid);
    EXPECT_EQ(r.reason, NoReadingReason::None);
    // 10000 values, 100 of each; the 5th percentile is index floor(0.05 * 9999) = 499,
    // in the block of x = 4.
    EXPECT_FLOAT_EQ(static_cast<float>(r.distance_m), 1.04f);
    EXPECT_EQ(r.stamp_ns, 42);
    EXPECT_EQ(r.frame, 9u);
    EXPECT_EQ(r.region_pixels, 10000u);
    EXPECT_DOUBLE_EQ(r.valid_fraction, 1.0);
    EXPECT_DOUBLE_EQ(r.in_range_fraction, 1.0);
    EXPECT_DOUBLE_EQ(r.min_valid_fraction, 0.10);
}

// The percentile of the in-range depths, then of those with the inferred ones when that
// is nearer: what measure() reports, computed the plain way (sorted copies).
double plainPercentile(const cv::Mat& depth, const cv::Mat& inferred, const NearestSettings& s)
{
    std::vector<float> in_range, with_inferred;
    for (int y = 0; y < depth.rows; ++y)
        for (int x = 0; x < depth.cols; ++x) {
            const float z = depth.at<float>(y, x);
            if (z > 0.0f && std::isfinite(z)) {
                if (z >= s.min_depth_m && z <= s.max_depth_m)
                    in_range.push_back(z);
                continue;
            }
            const float i = inferred.at<float>(y, x);
            if (i > 0.0f && std::isfinite(i) && i >= s.min_depth_m && i <= s.max_depth_m)
                with_inferred.push_back(i);
        }
    const auto percentile = [&](std::vector<float> v) {
        std::sort(v.begin(), v.end());
        return static_cast<double>(v[percentileIndex(s.percentile, v.size())]);
    };
    double p = in_range.empty() ? 0.0 : percentile(in_range);
    with_inferred.insert(with_inferred.end(), in_range.begin(), in_range.end());
    if (!with_inferred.empty()) {
        const double q = percentile(with_inferred);
        if (p == 0.0 || q < p)
            p = q;
    }
    return p;
}

// One finder over frames whose nearest depths come and go: the same frame after frame,
// a scene that moves nearer or farther at once, inferred depths nearer and farther than
// the measured ones, none in range. Its percentile (which each frame looks for first
// among the depths near the last one's) is the plain one every time.
TEST(NearestObject, ThePercentileIsThePlainOneWhateverTheFramesBefore)
{
    const NearestSettings s = wholeImage();
    NearestObjectFinder finder;
    cv::RNG random(5);
    const struct {
        double nearest_m, farthest_m, inferred_share, inferred_from_m;
    } frames[] = {{1.0, 3.0, 0.0, 0.0}, {1.0, 3.0, 0.0, 0.0},   {1.0, 3.0, 0.1, 0.5},
                  {4.0, 9.0, 0.1, 0.5}, {4.0, 9.0, 0.1, 6.0},   {0.3, 0.5, 0.05, 0.2},
                  {0.3, 0.5, 0.0, 0.0}, {25.0, 30.0, 0.2, 2.0}, {25.0, 30.0, 0.0, 0.0},
                  {2.0, 2.0, 0.3, 1.0}, {1.2, 8.0, 0.02, 1.1}};
    for (const auto& f : frames) {
        cv::Mat depth(60, 80, CV_32FC1), inferred(60, 80, CV_32FC1, cv::Scalar(0.0f));
        random.fill(depth, cv::RNG::UNIFORM, f.nearest_m, f.farthest_m + 1e-6);
        for (int y = 0; y < depth.rows; ++y)
            for (int x = 0; x < depth.cols; ++x)
                if (random.uniform(0.0, 1.0) < f.inferred_share) {
                    depth.at<float>(y, x) = 0.0f;
                    inferred.at<float>(y, x) = static_cast<float>(
                        random.uniform(f.inferred_from_m, f.inferred_from_m + 3.0));
                }
        const RegionMeasurement m = finder.measure(depth, cv::Mat(), cv::Mat(), inferred, s);
        EXPECT_EQ(m.percentile_depth_m, plainPercentile(depth, inferred, s))
            << "depths " << f.nearest_m << " to " << f.farthest_m << " m";
    }
}

TEST(NearestObject, AFewWrongNearPixelsDoNotMoveTheReading)
{
    cv::Mat depth(100, 100, CV_32FC1, cv::Scalar(3.0));
    // 1 % of the region claims an object at 0.2 m: below the 5th percentile.
    for (int i = 0; i < 100; ++i)
        depth.at<float>(i, i) = 0.2f;
    NearestObjectFinder finder;
    const Reading r = finder.find(depth, wholeImage(), 0, 0);
    ASSERT_TRUE(r.valid);
    EXPECT_FLOAT_EQ(static_cast<float>(r.distance_m), 3.0f);
}

TEST(NearestObject, TooFewValidPixels)
{
    cv::Mat depth(100, 100, CV_32FC1, cv::Scalar(0.0));
    // 5 % valid, with NaN and +inf counted as invalid too.
    depth.rowRange(0, 5).setTo(2.0);
    depth.at<float>(50, 50) = std::numeric_limits<float>::quiet_NaN();
    depth.at<float>(60, 60) = std::numeric_limits<float>::infinity();
    NearestObjectFinder finder;
    const Reading r = finder.find(depth, wholeImage(), 0, 0);
    EXPECT_FALSE(r.valid);
    EXPECT_EQ(r.reason, NoReadingReason::TooFewValidPixels);
    EXPECT_DOUBLE_EQ(r.valid_fraction, 0.05);
}

// What swapped cameras gave on Venus: most of the region beyond the range or invalid, a
// sliver of 4 % "in range" at 0.98 m, far more than min_pixels. Not a reading.
TEST(NearestObject, ASliverInRangeIsNoReading)
{
    cv::Mat depth(100, 100, CV_32FC1, cv::Scalar(0.0));
    depth.rowRange(0, 40).setTo(25.0);  // valid, beyond max_depth_m
    depth.rowRange(40, 44).setTo(0.98); // 400 px in range: 4 %
    NearestObjectFinder finder;
    NearestSettings settings = wholeImage();
    const Reading r = finder.find(depth, settings, 0, 0);
    EXPECT_FALSE(r.valid);
    EXPECT_EQ(r.reason, NoReadingReason::NothingInRange);
    EXPECT_DOUBLE_EQ(r.in_range_fraction, 0.04);
    // The same with 6 % in range is a reading: the rule is the fraction, not the count.
    depth.rowRange(44, 46).setTo(0.98);
    const Reading six = finder.find(depth, settings, 0, 0);
    EXPECT_TRUE(six.valid);
    settings.min_in_range_fraction = 0.0;
    depth.rowRange(44, 46).setTo(0.0);
    EXPECT_TRUE(finder.find(depth, settings, 0, 0).valid);
}

TEST(NearestObject, NothingInRange)
{
    cv::Mat depth(100, 100, CV_32FC1, cv::Scalar(25.0)); // all beyond max_depth_m
    depth.at<float>(0, 0) = 2.0f;                        // in range, but one pixel only
    NearestObjectFinder finder;
    const Reading r = finder.find(depth, wholeImage(), 0, 0);
    EXPECT_FALSE(r.valid);
    EXPECT_EQ(r.reason, NoReadingReason::NothingInRange);
    EXPECT_DOUBLE_EQ(r.valid_fraction, 1.0);
    EXPECT_DOUBLE_EQ(r.in_range_fraction, 1e-4);
}

TEST(NearestObject, OnlyTheRegionCounts)
{
    cv::Mat depth(100, 100, CV_32FC1, cv::Scalar(0.0));
    depth(cv::Rect(25, 25, 50, 50)).setTo(4.0); // the default region, full
    depth.at<float>(0, 0) = 0.5f;               // outside it
    NearestObjectFinder finder;
    NearestSettings s = wholeImage();
    s.roi = RegionOfInterest{};
    const Reading r = finder.find(depth, s, 0, 0);
    ASSERT_TRUE(r.valid);
    EXPECT_FLOAT_EQ(static_cast<float>(r.distance_m), 4.0f);
    EXPECT_EQ(r.region_pixels, 2500u);
}

TEST(NearestObject, ValidatesSettings)
{
    EXPECT_NO_THROW(validateNearestSettings(NearestSettings{}));
    NearestSettings s;
    s.roi.width = 0.0;
    EXPECT_THROW(validateNearestSettings(s), std::invalid_argument);
    s = NearestSettings{};
    s.roi.x = 0.8; // 0.8 + 0.5 > 1
    EXPECT_THROW(validateNearestSettings(s), std::invalid_argument);
    s = NearestSettings{};
    s.max_depth_m = s.min_depth_m;
    EXPECT_THROW(validateNearestSettings(s), std::invalid_argument);
    s = NearestSettings{};
    s.percentile = 101.0;
    EXPECT_THROW(validateNearestSettings(s), std::invalid_argument);
    s = NearestSettings{};
    s.min_pixels = 0;
    try {
        validateNearestSettings(s);
        FAIL();
    } catch (const std::invalid_argument& e) {
        EXPECT_EQ(std::string(e.what()), "min_pixels: must be >= 1, got 0");
    }
}

} // namespace
} // namespace stereod
