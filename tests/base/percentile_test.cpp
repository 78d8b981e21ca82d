// The two percentile rules, and that each figure's rule picks the value its docs promise.
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "base/percentile.hpp"

namespace stereod {
namespace {

TEST(Percentile, LowerLinearIndexIsTheFloorOfTheLinearPosition)
{
    EXPECT_EQ(lowerLinearIndex(0.0, 100), 0u);
    EXPECT_EQ(lowerLinearIndex(100.0, 100), 99u);
    EXPECT_EQ(lowerLinearIndex(50.0, 101), 50u);
    EXPECT_EQ(lowerLinearIndex(99.0, 200), 197u); // floor(0.99 * 199) = 197
    EXPECT_EQ(lowerLinearIndex(5.0, 1), 0u);
}

TEST(Percentile, LowerLinearIndexClampsThePercent)
{
    EXPECT_EQ(lowerLinearIndex(-5.0, 10), 0u);
    EXPECT_EQ(lowerLinearIndex(250.0, 10), 9u);
}

TEST(Percentile, NearestRankIndexIsTheCeilingRankLessOne)
{
    EXPECT_EQ(nearestRankIndex(99, 200), 197u); // ceil(0.99 * 200) = 198th smallest
    EXPECT_EQ(nearestRankIndex(99, 100), 98u);  // exactly 99: no rounding up to 100
    EXPECT_EQ(nearestRankIndex(99, 1), 0u);
    EXPECT_EQ(nearestRankIndex(50, 3), 1u);
    EXPECT_EQ(nearestRankIndex(0, 10), 0u);
    EXPECT_EQ(nearestRankIndex(100, 10), 9u);
}

TEST(Percentile, TheTwoRulesDifferWhereTheDocsSayTheyDo)
{
    // 1..10: the lower-of-linear p50 is the 5th smallest, the nearest-rank p50 also the
    // 5th, but their p99 differ: 9th (floor(0.99 * 9) = 8) against the 10th.
    std::vector<int64_t> values{7, 3, 10, 1, 9, 2, 8, 5, 4, 6};
    EXPECT_EQ(lowerLinearPercentile(values.begin(), values.end(), 50.0), 5);
    EXPECT_EQ(nearestRankPercentile(values.begin(), values.end(), 50), 5);
    EXPECT_EQ(lowerLinearPercentile(values.begin(), values.end(), 99.0), 9);
    EXPECT_EQ(nearestRankPercentile(values.begin(), values.end(), 99), 10);
}

TEST(Percentile, SelectsFromUnsortedValuesWithRepeats)
{
    std::vector<double> values{4.0, 1.0, 4.0, 2.0, 4.0};
    EXPECT_DOUBLE_EQ(selectNth(values.begin(), values.end(), 0), 1.0);
    EXPECT_DOUBLE_EQ(lowerLinearPercentile(values.begin(), values.end(), 100.0), 4.0);
    EXPECT_DOUBLE_EQ(lowerLinearPercentile(values.begin(), values.end(), 25.0), 2.0);
}

} // namespace
} // namespace stereod
