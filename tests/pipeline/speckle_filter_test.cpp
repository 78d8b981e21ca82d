// census-sgm's speckle filter against OpenCV's cv::filterSpeckles, the rule it follows:
// on census-sgm's own unfiltered disparities of real scenes (where speckles come from),
// for several region sizes and disparity steps, on one band and split into bands as the
// matcher's threads split it. OpenCV removes regions of at most maxSpeckleSize pixels,
// ours of fewer than max_size: the same regions for max_size = maxSpeckleSize + 1.

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "pipeline/sgm/census_sgm.hpp"
#include "pipeline/sgm/speckle_filter.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod::sgm {
namespace {

constexpr int16_t kNone = -32768;

// census-sgm's disparities of a real pair in 1/16 px, no speckle removal and no median.
cv::Mat unfilteredDisparities(const std::string& left_path, const std::string& right_path,
                              int num_disparities)
{
    const cv::Mat left = cv::imread(left_path, cv::IMREAD_GRAYSCALE);
    const cv::Mat right = cv::imread(right_path, cv::IMREAD_GRAYSCALE);
    if (left.empty() || right.empty())
        throw std::runtime_error("cannot read " + left_path + " or " + right_path);
    CensusSgmSettings s;
    s.width = left.cols;
    s.height = left.rows;
    s.num_disparities = num_disparities;
    s.speckle_window_px = 0;
    s.median = false;
    CensusSgm matcher(s);
    const size_t area = left.total();
    std::vector<float> disparity(area);
    std::vector<uint8_t> confidence(area), range_limit(area);
    matcher.compute(left.data, left.step, right.data, right.step,
                    CensusSgmOutput{disparity.data(), confidence.data(), range_limit.data()});
    cv::Mat fixed(left.size(), CV_16SC1);
    for (size_t i = 0; i < area; ++i)
        fixed.at<int16_t>(static_cast<int>(i)) =
            std::isfinite(disparity[i]) ? static_cast<int16_t>(std::lround(disparity[i] * 16))
                                        : kNone;
    return fixed;
}

// Our filter, its three phases over `bands` bands of rows as CensusSgm::compute runs them.
cv::Mat filtered(const cv::Mat& disparity, int max_step, int max_size, int bands)
{
    cv::Mat out = disparity.clone();
    SpeckleFilter filter(out.cols, out.rows);
    auto* data = out.ptr<int16_t>();
    std::vector<int> starts(static_cast<size_t>(bands) + 1);
    for (int b = 0; b <= bands; ++b)
        starts[static_cast<size_t>(b)] = out.rows * b / bands;
    for (int b = 0; b < bands; ++b)
        filter.labelBand(data, kNone, max_step, starts[static_cast<size_t>(b)],
                         starts[static_cast<size_t>(b) + 1]);
    filter.joinBands(data, max_step, starts.data(), bands);
    for (int b = 0; b < bands; ++b)
        filter.removeBand(data, kNone, max_size, starts[static_cast<size_t>(b)],
                          starts[static_cast<size_t>(b) + 1]);
    return out;
}

struct Pair {
    const char* name;
    std::string left, right;
    int num_disparities;
};

TEST(SpeckleFilterTest, RemovesTheRegionsOpenCvRemovesOnRealDisparities)
{
    const std::string data = test::sharedDataDir() + "/";
    const Pair pairs[] = {
        {"tsukuba", data + "middlebury/tsukuba/im3.png", data + "middlebury/tsukuba/im4.png", 64},
        {"kitti", data + "kitti2012/000070/image_0/000070_10.png",
         data + "kitti2012/000070/image_1/000070_10.png", 128},
    };
    for (const Pair& pair : pairs) {
        const cv::Mat raw = unfilteredDisparities(pair.left, pair.right, pair.num_disparities);
        for (int max_step : {0, 16, 48})
            for (int max_size : {2, 50, 200, 1000}) {
                cv::Mat expected = raw.clone();
                cv::filterSpeckles(expected, kNone, max_size - 1, max_step);
                const int removed = cv::countNonZero(raw != expected);
                // Real speckles to remove, and real regions to keep.
                if (max_size >= 50) {
                    EXPECT_GT(removed, 100) << pair.name;
                }
                if (max_step > 0) { // at step 0 a sub-pixel region is a few pixels
                    EXPECT_GT(cv::countNonZero(expected != kNone),
                              static_cast<int>(raw.total() / 4))
                        << pair.name;
                }
                for (int bands : {1, 2, 3, 7}) {
                    SCOPED_TRACE(std::string(pair.name) + ", step " + std::to_string(max_step) +
                                 ", size " + std::to_string(max_size) + ", bands " +
                                 std::to_string(bands));
                    const cv::Mat ours = filtered(raw, max_step, max_size, bands);
                    EXPECT_EQ(cv::countNonZero(ours != expected), 0)
                        << removed << " pixels removed by OpenCV";
                }
            }
    }
}

// Noise, where regions meet and part in every shape (U-turns, spirals of joins, regions
// that touch only through the row above): the same pixels as OpenCV's flood fill. Rows of
// widths around the filter's 64-pixel chunks, and sparse noise whose runs cross them.
TEST(SpeckleFilterTest, RemovesWhatOpenCvRemovesFromNoise)
{
    cv::RNG rng(20261127);
    const int widths[] = {131, 1, 63, 64, 65, 200};
    for (int trial = 0; trial < 12; ++trial) {
        cv::Mat raw(97, widths[trial % 6], CV_16SC1);
        // A few levels 0..3 px apart, a quarter of the pixels invalid; or two levels and
        // one pixel in 16 invalid, for long runs.
        const bool sparse = trial >= 6;
        for (int y = 0; y < raw.rows; ++y)
            for (int x = 0; x < raw.cols; ++x)
                raw.at<int16_t>(y, x) =
                    rng.uniform(0, sparse ? 16 : 4) == 0
                        ? kNone
                        : static_cast<int16_t>(16 * rng.uniform(0, sparse ? 2 : 4));
        for (int max_step : {0, 16, 32})
            for (int max_size : {2, 5, 30}) {
                cv::Mat expected = raw.clone();
                cv::filterSpeckles(expected, kNone, max_size - 1, max_step);
                for (int bands : {1, 2, 5}) {
                    SCOPED_TRACE("trial " + std::to_string(trial) + ", step " +
                                 std::to_string(max_step) + ", size " + std::to_string(max_size) +
                                 ", bands " + std::to_string(bands));
                    EXPECT_EQ(
                        cv::countNonZero(filtered(raw, max_step, max_size, bands) != expected), 0);
                }
            }
    }
}

TEST(SpeckleFilterTest, ApplyIsTheThreePhasesOnOneBand)
{
    // A staircase of 4-pixel-wide steps 1 px apart in 1/16 px, an isolated pixel and a
    // 2x2 island that differs by more than the step.
    cv::Mat d(6, 20, CV_16SC1);
    for (int y = 0; y < d.rows; ++y)
        for (int x = 0; x < d.cols; ++x)
            d.at<int16_t>(y, x) = static_cast<int16_t>(x / 4 * 16);
    d.at<int16_t>(0, 19) = 900;
    d(cv::Rect(10, 2, 2, 2)).setTo(600);
    cv::Mat applied = d.clone();
    SpeckleFilter filter(d.cols, d.rows);
    filter.apply(applied.ptr<int16_t>(), kNone, 16, 5);
    EXPECT_EQ(applied.at<int16_t>(0, 19), kNone);
    EXPECT_EQ(applied.at<int16_t>(2, 10), kNone);
    EXPECT_EQ(applied.at<int16_t>(3, 11), kNone);
    EXPECT_EQ(applied.at<int16_t>(5, 19), 4 * 16); // the staircase is one region: kept
    EXPECT_EQ(cv::countNonZero(applied == kNone), 5);
    EXPECT_EQ(cv::countNonZero(applied != filtered(d, 16, 5, 1)), 0);
}

} // namespace
} // namespace stereod::sgm
