// Bridging short gaps between agreeing disparities (gap_bridge.hpp): the line between the
// ends, only where the ends agree within 1 px and the run is short enough, rows then
// columns, and a confidence that says the value was inferred.

#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/gap_bridge.hpp"
#include "pipeline/sgm/sgm_kernels.hpp"

namespace stereod::sgm {
namespace {

constexpr int16_t kNone = kNoDisparity;
constexpr uint8_t kMatched = 200; // a matched pixel's confidence, untouched by bridging

struct Image {
    int width, height;
    std::vector<int16_t> disparity;
    std::vector<uint8_t> confidence;
    std::vector<uint8_t> range_limit;

    Image(int w, int h)
        : width(w), height(h), disparity(static_cast<size_t>(w * h), kNone),
          confidence(static_cast<size_t>(w * h), 0), range_limit(static_cast<size_t>(w * h), 0)
    {
    }
    void set(int x, int y, int16_t d)
    {
        disparity[static_cast<size_t>(y * width + x)] = d;
        confidence[static_cast<size_t>(y * width + x)] = kMatched;
    }
    int16_t at(int x, int y) const { return disparity[static_cast<size_t>(y * width + x)]; }
    uint8_t confidenceAt(int x, int y) const
    {
        return confidence[static_cast<size_t>(y * width + x)];
    }
    void bridge(int max_gap)
    {
        bridgeGaps(disparity.data(), confidence.data(), range_limit.data(), width, height, max_gap);
    }
};

TEST(GapBridgeTest, FillsARunBetweenAgreeingEndsWithTheLineBetweenThem)
{
    Image image(12, 1);
    image.set(2, 0, 10 * kSubpixel);     // 10 px
    image.set(7, 0, 10 * kSubpixel + 8); // 10.5 px, four pixels on
    image.bridge(5);
    // 160 + 8 j / 5 for j = 1..4, rounded: 161.6, 163.2, 164.8, 166.4.
    const int16_t expected[] = {162, 163, 165, 166};
    for (int j = 0; j < 4; ++j) {
        EXPECT_EQ(image.at(3 + j, 0), expected[j]) << "x " << 3 + j;
        EXPECT_EQ(image.confidenceAt(3 + j, 0), kInferredConfidence) << "x " << 3 + j;
    }
    EXPECT_EQ(image.confidenceAt(2, 0), kMatched);
    EXPECT_EQ(image.confidenceAt(7, 0), kMatched);
}

TEST(GapBridgeTest, ADescendingLineIsTheMirrorOfTheAscendingOne)
{
    Image image(12, 1);
    image.set(2, 0, 10 * kSubpixel + 8);
    image.set(7, 0, 10 * kSubpixel);
    image.bridge(5);
    const int16_t expected[] = {166, 165, 163, 162};
    for (int j = 0; j < 4; ++j)
        EXPECT_EQ(image.at(3 + j, 0), expected[j]) << "x " << 3 + j;
}

TEST(GapBridgeTest, LeavesARunLongerThanTheLimit)
{
    Image image(12, 1);
    image.set(1, 0, 160);
    image.set(7, 0, 160); // five pixels between
    image.bridge(4);
    for (int x = 2; x < 7; ++x) {
        EXPECT_EQ(image.at(x, 0), kNone) << "x " << x;
        EXPECT_EQ(image.confidenceAt(x, 0), 0) << "x " << x;
    }
    image.bridge(5);
    EXPECT_EQ(image.at(4, 0), 160);
}

TEST(GapBridgeTest, LeavesAGapWhoseEndsDifferByMoreThanOnePixel)
{
    // A depth edge: the ends 1 px and 1/16 px apart.
    Image image(12, 2);
    image.set(1, 0, 160);
    image.set(4, 0, 160 + kSubpixel + 1);
    image.set(1, 1, 160);
    image.set(4, 1, 160 + kSubpixel);
    image.bridge(8);
    EXPECT_EQ(image.at(2, 0), kNone);
    EXPECT_EQ(image.at(3, 0), kNone);
    EXPECT_NE(image.at(2, 1), kNone);
    EXPECT_NE(image.at(3, 1), kNone);
}

TEST(GapBridgeTest, LeavesRunsThatTheImageBorderOpens)
{
    Image image(10, 1);
    image.set(3, 0, 160);
    image.set(6, 0, 160);
    image.bridge(8);
    for (int x : {0, 1, 2, 7, 8, 9})
        EXPECT_EQ(image.at(x, 0), kNone) << "x " << x;
    EXPECT_EQ(image.at(4, 0), 160);
    EXPECT_EQ(image.at(5, 0), 160);
}

TEST(GapBridgeTest, NeverBridgesOverAPixelAtTheRangesNearEnd)
{
    // A surface that may be nearer than the range: a line from around it would read
    // farther than it is.
    Image image(12, 3);
    image.set(1, 1, 160);
    image.set(6, 1, 160);
    image.range_limit[static_cast<size_t>(1 * 12 + 4)] = 1;
    image.set(4, 0, 160); // the column through the flag is bridged neither
    image.set(4, 2, 160);
    image.bridge(8);
    for (int x = 2; x < 6; ++x)
        EXPECT_EQ(image.at(x, 1), kNone) << "x " << x;
    image.range_limit.assign(image.range_limit.size(), 0);
    image.bridge(8);
    EXPECT_EQ(image.at(4, 1), 160);
}

TEST(GapBridgeTest, BridgesColumnsAfterRows)
{
    // A column gap; then a gap that only the rows' bridging closes the ends of.
    Image image(5, 8);
    image.set(0, 1, 320);
    image.set(0, 5, 336); // column 0: rows 2..4 empty
    image.set(2, 0, 160);
    image.set(1, 6, 160); // column 2 row 6 comes from the row 6 bridge below
    image.set(3, 6, 160);
    image.bridge(3);
    EXPECT_EQ(image.at(0, 2), 324);
    EXPECT_EQ(image.at(0, 3), 328);
    EXPECT_EQ(image.at(0, 4), 332);
    EXPECT_EQ(image.at(2, 6), 160);
    // Column 2: rows 1..5 lie between 160 (row 0) and the bridged 160 (row 6); 5 > 3.
    EXPECT_EQ(image.at(2, 3), kNone);
    image.bridge(5);
    EXPECT_EQ(image.at(2, 3), 160);
    EXPECT_EQ(image.confidenceAt(2, 3), kInferredConfidence);
}

TEST(GapBridgeTest, WithAMaskBridgesOnlyGapsLyingWhollyInsideIt)
{
    Image image(16, 1);
    image.set(1, 0, 160);
    image.set(5, 0, 160);
    image.set(9, 0, 160);
    image.set(13, 0, 160);
    std::vector<uint8_t> only(16, 1);
    only[11] = 0; // inside the third gap
    bridgeGaps(image.disparity.data(), image.confidence.data(), image.range_limit.data(), 16, 1, 5,
               only.data());
    EXPECT_EQ(image.at(3, 0), 160);
    EXPECT_EQ(image.at(7, 0), 160);
    EXPECT_EQ(image.at(10, 0), kNone);
    EXPECT_EQ(image.at(12, 0), kNone);
}

TEST(GapBridgeTest, ZeroLimitChangesNothing)
{
    Image image(6, 1);
    image.set(1, 0, 160);
    image.set(3, 0, 160);
    image.bridge(0);
    EXPECT_EQ(image.at(2, 0), kNone);
}

} // namespace
} // namespace stereod::sgm
