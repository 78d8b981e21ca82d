// The band threads: every band of every run exactly once, runs that leave threads out,
// runs announced while its threads fall asleep, and a pool that stops while its threads
// sleep or spin.
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
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

// A run announced while a thread is on its way to sleep (after rest(), after its spin)
// must still reach it. The caller waits between runs for times spread from nothing to
// past the spin, so that announcements land at every step of falling asleep; a lost one
// leaves run() waiting for ever, which the watchdog reports.
TEST(BandPoolTest, NoRunIsLostWhileThreadsFallAsleep)
{
    constexpr long kRuns = 30000;
    BandPool pool(2);
    std::atomic<long> done{0};
    std::atomic<bool> finished{false};
    std::thread watchdog([&] {
        long last = -1;
        auto since = std::chrono::steady_clock::now();
        while (!finished.load()) {
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
            const long now = done.load();
            if (now != last) {
                last = now;
                since = std::chrono::steady_clock::now();
            } else if (std::chrono::steady_clock::now() - since > std::chrono::seconds(10)) {
                std::fprintf(stderr, "BandPoolTest: run %ld of %ld never returned\n", now, kRuns);
                std::abort();
            }
        }
    });
    long calls = 0;
    using Clock = std::chrono::steady_clock;
    const long spin_ns = std::chrono::nanoseconds(BandPool::kSpin).count();
    for (long run = 0; run < kRuns; ++run) {
        long parts[2] = {0, 0};
        pool.run(2, [&](int band) { parts[band] = 1; });
        calls += parts[0] + parts[1];
        if (run % 3 != 0)
            pool.rest();
        // 0 to 1.5 spins, busy, in steps that do not repeat with the rests.
        const auto until =
            Clock::now() + std::chrono::nanoseconds((run * 7919) % (spin_ns * 3 / 2));
        while (Clock::now() < until) {
        }
        done.fetch_add(1);
    }
    finished.store(true);
    watchdog.join();
    EXPECT_EQ(calls, 2 * kRuns);
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
