// The bookkeeping of live calibration on OpenCV's 13 real chessboard pairs (640x480, 9x6
// inner corners): how each board is measured (position, size, turn), which views are
// refused as near-duplicates, which cells of the image and which tilts and distances the
// views cover; and the fast corner search against the full-size one.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/calibration_coverage.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

const std::string kSamples = test::opencvSamplesDir() + "/";
const cv::Size kBoard(9, 6);
const cv::Size kImage(640, 480);
const std::vector<int> kSampleIndices = {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14};

cv::Mat sample(const char* side, int index)
{
    char name[32];
    std::snprintf(name, sizeof name, "%s%02d.jpg", side, index);
    cv::Mat image = cv::imread(kSamples + name, cv::IMREAD_GRAYSCALE);
    if (image.empty())
        throw std::runtime_error("cannot read " + kSamples + name);
    return image;
}

std::vector<cv::Point2f> corners(const cv::Mat& image)
{
    std::vector<cv::Point2f> found;
    if (!findBoardCorners(image, kBoard, found))
        throw std::runtime_error("board not found in a sample image");
    return found;
}

struct SampleView {
    int index = 0;
    std::vector<cv::Point2f> left;
    std::vector<cv::Point2f> right;
};

// The corners of all 13 pairs, searched once for the whole suite.
const std::vector<SampleView>& sampleViews()
{
    static const std::vector<SampleView> views = [] {
        std::vector<SampleView> out;
        for (int i : kSampleIndices)
            out.push_back({i, corners(sample("left", i)), corners(sample("right", i))});
        return out;
    }();
    return views;
}

const SampleView& view(int index)
{
    for (const SampleView& v : sampleViews())
        if (v.index == index)
            return v;
    throw std::out_of_range("no sample view " + std::to_string(index));
}

// An image moved and turned within its plane (border black): the same board seen from a
// camera that moved sideways or rolled.
cv::Mat moved(const cv::Mat& image, double dx_px, double dy_px, double angle_deg = 0.0)
{
    cv::Mat m = cv::getRotationMatrix2D({image.cols / 2.0f, image.rows / 2.0f}, angle_deg, 1.0);
    m.at<double>(0, 2) += dx_px;
    m.at<double>(1, 2) += dy_px;
    cv::Mat out;
    cv::warpAffine(image, out, m, image.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
    return out;
}

double edgeLength(const std::vector<cv::Point2f>& c, int from, int to)
{
    return cv::norm(c[static_cast<size_t>(to)] - c[static_cast<size_t>(from)]);
}

TEST(DescribeBoard, TurnSignsAgreeWithTheFartherSideLookingShorter)
{
    // Independent of the homography: in perspective the farther of two equal board edges
    // looks shorter. Every sample view turned more than 10 degrees one way must show it.
    int checked_yaw = 0, checked_pitch = 0;
    for (const SampleView& v : sampleViews()) {
        const BoardAppearance a = describeBoard(v.left, kBoard, kImage);
        // The board's two outer columns and rows, whichever way the detector listed them;
        // which one is on the image's left/top follows from their positions.
        const int w = kBoard.width, h = kBoard.height;
        double first_col = edgeLength(v.left, 0, (h - 1) * w);
        double last_col = edgeLength(v.left, w - 1, h * w - 1);
        double first_row = edgeLength(v.left, 0, w - 1);
        double last_row = edgeLength(v.left, (h - 1) * w, h * w - 1);
        const cv::Point2f c0 = v.left[0], c_last = v.left[static_cast<size_t>(h * w - 1)];
        // Columns or rows may run across the image (a board held upright): compare the
        // pair of outer edges that lie left and right of each other.
        const bool columns_vertical = std::abs(v.left[static_cast<size_t>((h - 1) * w)].y - c0.y) >
                                      std::abs(v.left[static_cast<size_t>((h - 1) * w)].x - c0.x);
        double left_edge, right_edge, top_edge, bottom_edge;
        if (columns_vertical) {
            const bool first_col_left = c0.x < c_last.x;
            left_edge = first_col_left ? first_col : last_col;
            right_edge = first_col_left ? last_col : first_col;
            const bool first_row_top = c0.y < c_last.y;
            top_edge = first_row_top ? first_row : last_row;
            bottom_edge = first_row_top ? last_row : first_row;
        } else {
            const bool first_row_left = c0.x < c_last.x;
            left_edge = first_row_left ? first_row : last_row;
            right_edge = first_row_left ? last_row : first_row;
            const bool first_col_top = c0.y < c_last.y;
            top_edge = first_col_top ? first_col : last_col;
            bottom_edge = first_col_top ? last_col : first_col;
        }
        if (std::abs(a.yaw_deg) > 10.0) {
            ++checked_yaw;
            EXPECT_EQ(a.yaw_deg > 0.0, right_edge < left_edge)
                << "view " << v.index << " yaw " << a.yaw_deg << ", left edge " << left_edge
                << " px, right edge " << right_edge << " px";
        }
        if (std::abs(a.pitch_deg) > 10.0) {
            ++checked_pitch;
            EXPECT_EQ(a.pitch_deg > 0.0, bottom_edge < top_edge)
                << "view " << v.index << " pitch " << a.pitch_deg << ", top edge " << top_edge
                << " px, bottom edge " << bottom_edge << " px";
        }
    }
    EXPECT_GE(checked_yaw, 8);
    EXPECT_GE(checked_pitch, 6);
}

TEST(DescribeBoard, MeasuresPositionSizeAndRollOfAMovedImage)
{
    const cv::Mat image = sample("left", 1);
    const BoardAppearance a = describeBoard(corners(image), kBoard, kImage);
    const BoardAppearance b =
        describeBoard(corners(moved(image, -64.0, 48.0, 20.0)), kBoard, kImage);
    // The board's centre is rotated about the image centre, then moved.
    const double angle = -20.0 * CV_PI / 180.0; // warpAffine turns counter-clockwise
    const cv::Point2d from(a.centre_frac.x * kImage.width - 320.0,
                           a.centre_frac.y * kImage.height - 240.0);
    const cv::Point2d expected(320.0 + std::cos(angle) * from.x - std::sin(angle) * from.y - 64.0,
                               240.0 + std::sin(angle) * from.x + std::cos(angle) * from.y + 48.0);
    EXPECT_NEAR(b.centre_frac.x * kImage.width, expected.x, 1.0);
    EXPECT_NEAR(b.centre_frac.y * kImage.height, expected.y, 1.0);
    EXPECT_NEAR(b.size_frac, a.size_frac, 0.01 * a.size_frac);
    double roll = a.roll_deg - b.roll_deg; // counter-clockwise in the image: roll falls
    roll -= 180.0 * std::round(roll / 180.0);
    EXPECT_NEAR(roll, 20.0, 1.0);
    EXPECT_THROW(describeBoard(std::vector<cv::Point2f>(53), kBoard, kImage),
                 std::invalid_argument);
}

TEST(CalibrationCoverage, RefusesTheSameViewTwiceAndANearlyUnmovedOne)
{
    CalibrationCoverage coverage(kImage, kBoard);
    const SampleView& first = view(1);
    EXPECT_FALSE(coverage.judge(first.left, first.right).duplicate_of);
    coverage.accept(first.left, first.right);

    const ViewJudgement again = coverage.judge(first.left, first.right);
    ASSERT_TRUE(again.duplicate_of);
    EXPECT_EQ(*again.duplicate_of, 0);
    EXPECT_EQ(again.reason.rfind("the same view as accepted view 1 (the board has not moved)", 0),
              0u)
        << again.reason;

    // 6 px sideways in both cameras: the same view for the calibration.
    const ViewJudgement nudged = coverage.judge(corners(moved(sample("left", 1), 6.0, 0.0)),
                                                corners(moved(sample("right", 1), 6.0, 0.0)));
    ASSERT_TRUE(nudged.duplicate_of) << "a view moved by 6 px was taken as new";
    EXPECT_EQ(nudged.reason.rfind("too close to accepted view 1: in the left image the board "
                                  "moved 0.",
                                  0),
              0u)
        << nudged.reason;
    // 100 px sideways, or rolled by 20 degrees: new views.
    EXPECT_FALSE(coverage
                     .judge(corners(moved(sample("left", 1), -100.0, 0.0)),
                            corners(moved(sample("right", 1), -100.0, 0.0)))
                     .duplicate_of);
    EXPECT_FALSE(coverage
                     .judge(corners(moved(sample("left", 1), 0.0, 0.0, 20.0)),
                            corners(moved(sample("right", 1), 0.0, 0.0, 20.0)))
                     .duplicate_of);
}

TEST(CalibrationCoverage, TheThirteenSampleViewsAreDistinctAndCoverWhatTheyReallyCover)
{
    CalibrationCoverage coverage(kImage, kBoard);
    EXPECT_EQ(formatGaps(coverage.gaps()),
              "missing: left image top-left, top, top-right, left, centre, right, bottom-left, "
              "bottom, bottom-right; right image top-left, top, top-right, left, centre, right, "
              "bottom-left, bottom, bottom-right; tilts: right edge nearer, left edge nearer, "
              "bottom edge nearer, top edge nearer; distances: near, far");
    for (const SampleView& v : sampleViews()) {
        const ViewJudgement j = coverage.judge(v.left, v.right);
        EXPECT_FALSE(j.duplicate_of) << "view " << v.index << ": " << j.reason;
        coverage.accept(v.left, v.right);
    }
    EXPECT_EQ(coverage.views().size(), 13u);
    int corners_left = 0, corners_right = 0;
    for (int n : coverage.leftCellCorners())
        corners_left += n;
    for (int n : coverage.rightCellCorners())
        corners_right += n;
    EXPECT_EQ(corners_left, 13 * 54);
    EXPECT_EQ(corners_right, 13 * 54);

    // Checked by eye on the outlines of the 13 boards drawn over the 3x3 grid: in the left
    // image the boards span x 150..605, y 50..430 and reach the left third only with the
    // slivers of a few boards (4 corners top-left, 9 bottom-left); the right camera, 8 cm
    // to the right, sees them 150 px further left, and its right third gets 1, 6 and 3
    // corners. The boards are held at one arm's length: none is far (all span 35 to 51 %
    // of the image), two are near (03, 05), and all four tilts have views of 15 degrees and
    // more.
    const CoverageGaps gaps = coverage.gaps();
    EXPECT_EQ(gaps.left_cells, (std::vector<std::string>{"top-left", "bottom-left"}));
    EXPECT_EQ(gaps.right_cells, (std::vector<std::string>{"top-right", "right", "bottom-right"}));
    EXPECT_TRUE(gaps.tilts.empty());
    EXPECT_EQ(gaps.distances, (std::vector<std::string>{"far"}));
    EXPECT_EQ(coverage.distanceViews()[0], 2);
    EXPECT_EQ(formatGaps(gaps), "missing: left image top-left, bottom-left; right image "
                                "top-right, right, bottom-right; distances: far");
}

TEST(CalibrationCoverage, ATiltedViewFillsItsTiltBucket)
{
    // View 11: the board turned by some 35 degrees, its right side farther (the right edge
    // looks shorter); view 02: its bottom farther.
    CalibrationCoverage coverage(kImage, kBoard);
    coverage.accept(view(11).left, view(11).right);
    EXPECT_EQ(coverage.tiltViews()[1], 1); // left edge nearer
    EXPECT_EQ(coverage.tiltViews()[0] + coverage.tiltViews()[2] + coverage.tiltViews()[3], 0);
    EXPECT_EQ(
        coverage.gaps().tilts,
        (std::vector<std::string>{"right edge nearer", "bottom edge nearer", "top edge nearer"}));
    coverage.accept(view(2).left, view(2).right);
    EXPECT_EQ(coverage.tiltViews()[3], 1); // top edge nearer
    // View 13 is turned about the horizontal axis only (its sides are as long as each
    // other): it fills no bucket of a turn about the vertical axis.
    CalibrationCoverage pitched(kImage, kBoard);
    pitched.accept(view(13).left, view(13).right);
    EXPECT_EQ(
        pitched.gaps().tilts,
        (std::vector<std::string>{"right edge nearer", "left edge nearer", "bottom edge nearer"}));
}

TEST(CalibrationCoverage, RefusesBadArguments)
{
    EXPECT_THROW(CalibrationCoverage({0, 480}, kBoard), std::invalid_argument);
    EXPECT_THROW(CalibrationCoverage(kImage, {1, 6}), std::invalid_argument);
    CoverageOptions inverted;
    inverted.near_size_frac = 0.2;
    EXPECT_THROW(CalibrationCoverage(kImage, kBoard, inverted), std::invalid_argument);
    CalibrationCoverage coverage(kImage, kBoard);
    EXPECT_THROW(coverage.judge(view(1).left, {}), std::invalid_argument);
}

TEST(FindBoardCornersFast, AgreesWithTheFullSizeSearch)
{
    // Three sample images at twice their size: searched at 640 px wide, refined at full
    // size; the full-size search is the reference.
    for (int index : {1, 5, 11}) {
        cv::Mat large;
        cv::resize(sample("left", index), large, {1280, 960}, 0.0, 0.0, cv::INTER_CUBIC);
        std::vector<cv::Point2f> fast, full;
        ASSERT_TRUE(findBoardCornersFast(large, kBoard, fast, 640)) << index;
        ASSERT_TRUE(findBoardCorners(large, kBoard, full)) << index;
        ASSERT_EQ(fast.size(), full.size());
        double worst = 0.0, sum = 0.0;
        for (size_t i = 0; i < fast.size(); ++i) {
            const double d = cv::norm(fast[i] - full[i]);
            worst = std::max(worst, d);
            sum += d;
        }
        std::printf("left%02d at 1280x960: fast search off the full-size one by %.3f px mean, "
                    "%.3f px worst\n",
                    index, sum / static_cast<double>(fast.size()), worst);
        EXPECT_LT(sum / static_cast<double>(fast.size()), 0.05) << index;
        EXPECT_LT(worst, 0.15) << index;
    }
    std::vector<cv::Point2f> none;
    EXPECT_FALSE(findBoardCornersFast(cv::Mat(960, 1280, CV_8UC1, cv::Scalar(128)), kBoard, none));
    EXPECT_TRUE(none.empty());
    EXPECT_THROW(findBoardCornersFast(cv::Mat(10, 10, CV_8UC3), kBoard, none),
                 std::invalid_argument);
}

} // namespace
} // namespace stereod
