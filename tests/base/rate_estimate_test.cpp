// The rate of recent events behind every `fps`: the figure from given event times, the
// window sliding past its N events, 0 before two, a span that does not advance, a restart,
// and a reader on another thread (also under ThreadSanitizer).
#include <cstdint>
#include <thread>

#include <gtest/gtest.h>

#include "base/rate_estimate.hpp"

namespace stereod {
namespace {

constexpr int64_t kMs = 1'000'000;

TEST(RateEstimate, CountsIntervalsOverTheSpan)
{
    RateEstimate<4> rate;
    rate.add(0);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 0.0); // one event: no interval yet
    rate.add(100 * kMs);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 10.0); // one interval of 0.1 s
    rate.add(150 * kMs);
    // Two intervals over 0.15 s: the mean interval, not the newest one.
    EXPECT_NEAR(rate.perSecond(), 2.0 / 0.15, 1e-9);
}

TEST(RateEstimate, OnlyTheLastNEventsCount)
{
    // A camera at 10 fps that then delivers at 50 fps: once four events at the new pace
    // are held, the slow ones no longer count.
    RateEstimate<4> rate;
    int64_t t = 0;
    for (int i = 0; i < 4; ++i, t += 100 * kMs)
        rate.add(t);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 10.0);
    t -= 100 * kMs;
    t += 20 * kMs;
    rate.add(t); // the window: 100, 200, 300, 320 ms
    EXPECT_NEAR(rate.perSecond(), 3.0 / 0.22, 1e-9);
    for (int i = 0; i < 3; ++i) {
        t += 20 * kMs;
        rate.add(t);
    }
    EXPECT_NEAR(rate.perSecond(), 50.0, 1e-9);
    // And rolling over many times the ring's size changes nothing.
    for (int i = 0; i < 1001; ++i) {
        t += 40 * kMs;
        rate.add(t);
    }
    EXPECT_NEAR(rate.perSecond(), 25.0, 1e-9);
}

TEST(RateEstimate, ASpanThatDoesNotAdvanceKeepsTheFigure)
{
    RateEstimate<4> rate;
    rate.add(5);
    rate.add(5);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 0.0); // two events at one instant: no rate yet
    rate.add(5 + 200 * kMs);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 10.0);
    // A stamp behind the oldest held (a clock read out of order): the figure stays.
    RateEstimate<2> pair;
    pair.add(100 * kMs);
    pair.add(200 * kMs);
    EXPECT_DOUBLE_EQ(pair.perSecond(), 10.0);
    pair.add(150 * kMs);
    EXPECT_DOUBLE_EQ(pair.perSecond(), 10.0);
}

TEST(RateEstimate, ARestartForgetsTheEventsButNotTheFigure)
{
    RateEstimate<8> rate;
    for (int64_t t = 0; t <= 400 * kMs; t += 100 * kMs)
        rate.add(t);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 10.0);
    // A replay started again: events before it must not stretch the span of the new ones.
    rate.restart();
    rate.add(10'000 * kMs);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 10.0); // one event since: the old figure stays
    rate.add(10'050 * kMs);
    EXPECT_DOUBLE_EQ(rate.perSecond(), 20.0);
}

TEST(RateEstimate, AReaderOnAnotherThreadSeesOnlyWholeFigures)
{
    // The writer delivers at 100 or 50 per second in turns of N events; every figure a
    // reader sees lies between the two (never torn, never from half-written times).
    RateEstimate<8> rate;
    std::thread writer([&rate] {
        int64_t t = 0;
        for (int i = 0; i < 200000; ++i) {
            t += (i / 8) % 2 == 0 ? 10 * kMs : 20 * kMs;
            rate.add(t);
        }
    });
    for (int i = 0; i < 20000; ++i) {
        const double figure = rate.perSecond();
        if (figure == 0.0)
            continue; // before the second event
        ASSERT_GE(figure, 50.0 - 1e-9);
        ASSERT_LE(figure, 100.0 + 1e-9);
    }
    writer.join();
    EXPECT_GE(rate.perSecond(), 50.0 - 1e-9);
    EXPECT_LE(rate.perSecond(), 100.0 + 1e-9);
}

} // namespace
} // namespace stereod
