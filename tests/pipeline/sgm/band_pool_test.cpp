// The band threads: every band of every run exactly once, runs that leave threads out,
// and a pool that stops while its threads sleep or spin.
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/band_pool.hpp"

namespace stereod::sgm {
namespace {

TEST(BandPoolTest, RunsEveryBandOfEveryRunOnce)
{
    constexpr int kThreads = 4;
    BandPool pool(kThreads);
    EXPECT_EQ(pool.threads(), kThreads);
    // Plain ints, each written by one band: run() must order them (a race shows in TSan).
    std::vector<int> calls(kThreads, 0);
    for (int run = 0; run < 2000; ++run) {
        const int bands = 1 + run % kThreads;
        pool.run(bands, [&](int band) { ++calls[static_cast<size_t>(band)]; });
        // Every band this run asked for has returned, and no other ran.
        for (int band = 0; band < kThreads; ++band) {
            int expected = 0;
            for (int r = 0; r <= run; ++r)
                expected += band < 1 + r % kThreads ? 1 : 0;
            ASSERT_EQ(calls[static_cast<size_t>(band)], expected)
                << "run " << run << " band " << band;
        }
    }
}

TEST(BandPoolTest, WakesThreadsThatHaveGoneToSleep)
{
    BandPool pool(2);
    int sum = 0;
    for (int run = 0; run < 5; ++run) {
        // Longer than the spin: the thread sleeps and must be woken.
        std::this_thread::sleep_for(BandPool::kSpin * 5);
        int parts[2] = {0, 0};
        pool.run(2, [&](int band) { parts[band] = band + 1; });
        sum += parts[0] + parts[1];
    }
    EXPECT_EQ(sum, 15);
}

TEST(BandPoolTest, RestsAfterAFrameAndWakesForTheNext)
{
    BandPool pool(3);
    std::vector<int> calls(3, 0);
    for (int frame = 0; frame < 50; ++frame) {
        for (int run = 0; run < 4; ++run)
            pool.run(3, [&](int band) { ++calls[static_cast<size_t>(band)]; });
        pool.rest();
        if (frame % 10 == 0) // let them fall asleep now and then
            std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    EXPECT_EQ(calls, (std::vector<int>{200, 200, 200}));
}

TEST(BandPoolTest, StopsWhetherItsThreadsSpinOrSleep)
{
    for (int wait_us : {0, 1000}) {
        BandPool pool(3);
        std::atomic<int> count{0};
        pool.run(3, [&](int) { count.fetch_add(1); });
        std::this_thread::sleep_for(std::chrono::microseconds(wait_us));
        EXPECT_EQ(count.load(), 3);
    } // the destructor joins the threads
}

TEST(BandPoolTest, RefusesAThreadCountOutsideOneTo64)
{
    EXPECT_THROW(BandPool(0), std::invalid_argument);
    EXPECT_THROW(BandPool(65), std::invalid_argument);
    BandPool one(1);
    int called = 0;
    one.run(1, [&](int band) { called += band + 1; });
    EXPECT_EQ(called, 1);
}

} // namespace
} // namespace stereod::sgm
