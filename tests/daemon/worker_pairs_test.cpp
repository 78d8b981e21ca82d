// Which pairs the worker takes while it is behind: the newest waiting, so that a reading
// is about now (the older ones dropped and counted with the ring's drops), or, for a source
// that keeps every pair (a lockstep replay), every pair oldest first.

#include <chrono>
#include <cstdint>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "base/clock.hpp"
#include "capture/frame_pool.hpp"
#include "daemon/publisher.hpp"
#include "daemon/worker.hpp"

namespace stereod {
namespace {

constexpr int kWaiting = 4;

StereoPair makePair(FramePool& pool, uint64_t index)
{
    StereoPair pair;
    pair.index = index;
    pair.left = pool.acquire();
    pair.right = pool.acquire();
    pair.left->image.setTo(static_cast<int>(index));
    pair.right->image.setTo(static_cast<int>(index));
    pair.left->stamp_ns = pair.right->stamp_ns = monotonicNowNs();
    return pair;
}

// Fills a ring with kWaiting pairs before the worker starts (the worker is behind by
// kWaiting - 1 pairs when it takes its first), and returns what it published once it has
// nothing left to take.
struct Taken {
    uint64_t published = 0, last_frame = 0, dropped = 0;
};

Taken takeWaitingPairs(bool every_pair)
{
    FramePool pool(2 * kWaiting + 2, cv::Size(32, 24));
    PairRing ring(kWaiting);
    for (uint64_t index = 0; index < kWaiting; ++index)
        ring.push(makePair(pool, index));
    Publisher publisher;
    Worker worker(ring, publisher, nullptr, 1000.0);
    worker.setTakesEveryPair(every_pair);
    worker.start();
    const uint64_t expected = every_pair ? kWaiting : 1;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (
        (publisher.publishedCount() < expected || ring.size() > 0 || worker.busySinceNs() != 0) &&
        std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    Taken taken;
    taken.published = publisher.publishedCount();
    taken.last_frame = publisher.latest() != nullptr ? publisher.latest()->result.frame : 0;
    taken.dropped = ring.dropped();
    ring.stop();
    worker.join();
    return taken;
}

TEST(WorkerPairs, TakesTheNewestPairWaitingAndCountsTheOlderOnesDropped)
{
    const Taken taken = takeWaitingPairs(false);
    EXPECT_EQ(taken.published, 1u);
    EXPECT_EQ(taken.last_frame, kWaiting - 1u);
    EXPECT_EQ(taken.dropped, kWaiting - 1u);
}

TEST(WorkerPairs, TakesEveryPairOldestFirstForASourceThatKeepsEveryPair)
{
    const Taken taken = takeWaitingPairs(true);
    EXPECT_EQ(taken.published, static_cast<uint64_t>(kWaiting));
    EXPECT_EQ(taken.last_frame, kWaiting - 1u);
    EXPECT_EQ(taken.dropped, 0u);
}

} // namespace
} // namespace stereod
