// The rolling windows: the last N samples, not since start (RollingWindow read across
// threads, RecentValues on one thread).
#include <cstdint>
#include <limits>
#include <thread>

#include <gtest/gtest.h>

#include "base/rolling_window.hpp"

namespace stereod {
namespace {

TEST(RollingWindow, EmptyWindowSummarisesToZero)
{
    const RollingWindow<4> window;
    const RollingSummary summary = window.summary();
    EXPECT_EQ(summary.count, 0u);
    EXPECT_EQ(summary.max_abs_ns, 0);
    EXPECT_EQ(summary.mean_abs_ns, 0.0);
}

TEST(RollingWindow, SummarisesSignedAndAbsoluteValues)
{
    RollingWindow<8> window;
    for (int64_t v : {-3, 1, 2})
        window.add(v);
    const RollingSummary summary = window.summary();
    EXPECT_EQ(summary.count, 3u);
    EXPECT_DOUBLE_EQ(summary.mean_ns, 0.0);
    EXPECT_DOUBLE_EQ(summary.mean_abs_ns, 2.0);
    EXPECT_EQ(summary.max_abs_ns, 3);
    EXPECT_EQ(summary.p99_abs_ns, 3);
}

TEST(RollingWindow, OnlyTheLastNSamplesCount)
{
    RollingWindow<4> window;
    window.add(1'000'000); // pushed out by the four below
    for (int i = 0; i < 4; ++i)
        window.add(10);
    const RollingSummary summary = window.summary();
    EXPECT_EQ(summary.count, 4u);
    EXPECT_EQ(summary.max_abs_ns, 10);
    EXPECT_DOUBLE_EQ(summary.mean_abs_ns, 10.0);
}

TEST(RollingWindow, P99IsTheNearestRank)
{
    RollingWindow<256> window;
    for (int64_t v = 1; v <= 200; ++v)
        window.add(v);
    // ceil(0.99 * 200) = 198: the 198th smallest.
    EXPECT_EQ(window.summary().p99_abs_ns, 198);
}

TEST(RollingWindow, ExtremeStampsSaturateInsteadOfWrapping)
{
    RollingWindow<2> window;
    window.add(std::numeric_limits<int64_t>::min());
    window.add(std::numeric_limits<int64_t>::max());
    const RollingSummary summary = window.summary();
    EXPECT_EQ(summary.max_abs_ns, std::numeric_limits<int64_t>::max());
    EXPECT_GT(summary.mean_abs_ns, 9e18);
}

TEST(RollingWindow, ReaderOnAnotherThreadSeesWholeSamples)
{
    RollingWindow<64> window;
    std::thread writer([&window] {
        for (int i = 0; i < 100000; ++i)
            window.add(i % 2 == 0 ? 5 : -5);
    });
    for (int i = 0; i < 1000; ++i) {
        const RollingSummary summary = window.summary();
        if (summary.count > 0) {
            ASSERT_EQ(summary.max_abs_ns, 5);
        }
    }
    writer.join();
}

TEST(RecentValues, HoldsTheLastNOldestFirst)
{
    RecentValues<int, 3> values;
    EXPECT_EQ(values.size(), 0u);
    for (int v : {1, 2, 3, 4, 5})
        values.add(v);
    ASSERT_EQ(values.size(), 3u);
    EXPECT_EQ(values[0], 3);
    EXPECT_EQ(values[1], 4);
    EXPECT_EQ(values[2], 5);
}

TEST(RecentValues, MeanIsOfTheValuesHeldOnly)
{
    RecentValues<double, 2> values;
    EXPECT_DOUBLE_EQ(mean(values), 0.0);
    values.add(100.0); // pushed out below
    values.add(1.0);
    values.add(3.0);
    EXPECT_DOUBLE_EQ(mean(values), 2.0);
}

} // namespace
} // namespace stereod
