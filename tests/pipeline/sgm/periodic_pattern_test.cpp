// Finding the rows that run through a pattern repeating along them (periodic_pattern.hpp):
// regular strong edges are a pattern, irregular, weak or too widely spaced ones are not,
// and a mark spreads a few rows up and down.

#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/periodic_pattern.hpp"

namespace stereod::sgm {
namespace {

constexpr int kWidth = 320;
constexpr int kHeight = 20;

// A grey image with vertical bands: [from, to) of each band in `dark` at level `low`,
// the rest at `high`.
std::vector<uint8_t> bands(const std::vector<std::pair<int, int>>& dark, uint8_t low, uint8_t high)
{
    std::vector<uint8_t> image(kWidth * kHeight, high);
    for (int y = 0; y < kHeight; ++y)
        for (const auto& [from, to] : dark)
            for (int x = from; x < to; ++x)
                image[static_cast<size_t>(y * kWidth + x)] = low;
    return image;
}

// Dark bands `period` apart, half a period wide, from x0 for `count` periods.
std::vector<std::pair<int, int>> stripes(int x0, int period, int count)
{
    std::vector<std::pair<int, int>> dark;
    for (int i = 0; i < count; ++i)
        dark.emplace_back(x0 + i * period, x0 + i * period + period / 2);
    return dark;
}

std::vector<uint8_t> mark(const std::vector<uint8_t>& image, int max_period)
{
    std::vector<uint8_t> raw(image.size(), 7);
    std::vector<int> scratch(2 * kWidth);
    markPeriodicRows(image.data(), kWidth, kWidth, 0, kHeight, 6, max_period, scratch.data(),
                     raw.data());
    return raw;
}

int marked(const std::vector<uint8_t>& raw, int y, int from, int to)
{
    int count = 0;
    for (int x = from; x < to; ++x)
        count += raw[static_cast<size_t>(y * kWidth + x)];
    return count;
}

TEST(PeriodicPatternTest, MarksStripesFromAPeriodBeforeToAPeriodAfter)
{
    // Stripes of period 24 over 100..244: edges every 24 px of each polarity.
    const std::vector<uint8_t> raw = mark(bands(stripes(100, 24, 6), 30, 220), 64);
    for (int y = 0; y < kHeight; ++y) {
        EXPECT_EQ(marked(raw, y, 100, 240), 140) << "row " << y;
        // The falling edges' period before the first, the rising ones' after the last.
        EXPECT_EQ(marked(raw, y, 76, 100), 24) << "row " << y;
        EXPECT_EQ(marked(raw, y, 232, 257), 25) << "row " << y;
        EXPECT_EQ(marked(raw, y, 0, 60), 0) << "row " << y;
        EXPECT_EQ(marked(raw, y, 290, kWidth), 0) << "row " << y;
    }
}

TEST(PeriodicPatternTest, LeavesIrregularWeakAndFarApartEdgesAlone)
{
    // Dark bands at spacings 16, 40, 12, 50: no three of one polarity evenly spaced.
    const std::vector<std::pair<int, int>> irregular{
        {20, 28}, {36, 44}, {76, 84}, {88, 96}, {138, 146}};
    EXPECT_EQ(marked(mark(bands(irregular, 30, 220), 128), 5, 0, kWidth), 0);
    // Regular, but a step of 30 grey levels: texture, not a pattern that misleads.
    EXPECT_EQ(marked(mark(bands(stripes(100, 24, 6), 100, 130), 64), 5, 0, kWidth), 0);
    // Regular and strong, but 48 px apart where the range spans 32: no ambiguity.
    EXPECT_EQ(marked(mark(bands(stripes(20, 48, 6), 30, 220), 32), 5, 0, kWidth), 0);
}

TEST(PeriodicPatternTest, AMarkSpreadsItsReachOfRowsUpAndDown)
{
    std::vector<uint8_t> raw(kWidth * kHeight, 0);
    raw[static_cast<size_t>(10 * kWidth + 50)] = 1;
    std::vector<uint8_t> mask(raw.size(), 9);
    spreadPeriodicRows(raw.data(), kWidth, kHeight, 0, kHeight, mask.data());
    for (int y = 0; y < kHeight; ++y) {
        const bool reached = y >= 10 - kPeriodicRowReach && y <= 10 + kPeriodicRowReach;
        EXPECT_EQ(mask[static_cast<size_t>(y * kWidth + 50)], reached ? 1 : 0) << "row " << y;
        EXPECT_EQ(mask[static_cast<size_t>(y * kWidth + 51)], 0) << "row " << y;
    }
}

} // namespace
} // namespace stereod::sgm
