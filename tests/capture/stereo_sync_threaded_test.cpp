// StereoSyncThread with two producer threads standing in for the cameras and the worker
// popping pairs: pairs correct, every frame paired or counted, buffers all returned, and
// clean under ThreadSanitizer.

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <random>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "capture/frame_pool.hpp"
#include "capture/stereo_sync.hpp"

namespace stereod {
namespace {

constexpr int64_t kMs = 1'000'000;
constexpr int64_t kPeriodNs = 33'333'333;

TEST(StereoSyncThread, PairsFramesFromTwoCaptureThreads)
{
    constexpr int kFrames = 600;
    constexpr int64_t kMaxSkewNs = 4 * kMs;
    FramePool pool(48, cv::Size(8, 4));
    PairRing ring(4);
    StereoSyncThread sync({kMaxSkewNs, 4}, 32);
    sync.start(ring);

    // Each camera produces frame i only once the other has produced i - 1, so neither
    // runs far ahead (as two cameras at one rate), and waits for a free buffer as a
    // driver with all buffers out would (the worker below gives them back).
    std::atomic<int> produced[2]{};
    const auto camera = [&](int side, int64_t offset_ns, unsigned seed) {
        std::mt19937 rng(seed);
        std::normal_distribution<double> jitter_ms(0.0, 0.5);
        for (int i = 0; i < kFrames; ++i) {
            while (produced[1 - side].load(std::memory_order_acquire) < i - 1)
                std::this_thread::yield();
            FrameHandle frame = pool.acquire();
            while (!frame) {
                std::this_thread::yield();
                frame = pool.acquire();
            }
            frame->stamp_ns =
                1000 * kMs + i * kPeriodNs + offset_ns + static_cast<int64_t>(jitter_ms(rng) * 1e6);
            frame->sequence = static_cast<uint64_t>(i);
            frame->image.at<uint8_t>(0, 0) = static_cast<uint8_t>(side);
            sync.offer(static_cast<StereoSide>(side), std::move(frame));
            produced[side].store(i + 1, std::memory_order_release);
        }
    };

    std::vector<StereoPair> kept;
    uint64_t popped = 0;
    uint64_t wrong = 0;
    std::thread worker([&] {
        while (std::optional<StereoPair> pair = ring.pop()) {
            ++popped;
            if (pair->left->sequence != pair->right->sequence ||
                std::llabs(pair->skewNs()) > kMaxSkewNs ||
                pair->left->image.at<uint8_t>(0, 0) != 0 ||
                pair->right->image.at<uint8_t>(0, 0) != 1)
                ++wrong;
        }
    });
    std::thread left(camera, 0, 0, 11u);
    std::thread right(camera, 1, 1 * kMs, 12u);
    left.join();
    right.join();
    // Let the sync thread take the last frames (all but those left waiting for a
    // partner) before stopping it.
    for (;;) {
        const SyncStats now = sync.stats();
        if (2 * now.pairs + now.unpaired() + 4 >= 2 * static_cast<uint64_t>(kFrames))
            break;
        std::this_thread::yield();
    }
    sync.stop();
    ring.stop();
    worker.join();

    const SyncStats stats = sync.stats();
    EXPECT_EQ(wrong, 0u);
    // Nothing is lost on the way: every frame either paired or counted, per side.
    for (int side = 0; side < 2; ++side)
        EXPECT_EQ(stats.pairs + stats.drops[side].total(), static_cast<uint64_t>(kFrames))
            << "side " << side;
    EXPECT_EQ(popped + ring.dropped(), stats.pairs);
    // 0.5 ms jitter against 4 ms max_skew: every instant pairs.
    EXPECT_GE(stats.pairs, static_cast<uint64_t>(kFrames - 2));
    EXPECT_NEAR(stats.skew_signed_mean_ms, 1.0, 0.2);
    EXPECT_EQ(pool.inUse(), 0u);
}

TEST(StereoSyncThread, StopWakesTheIdleThreadAndReturnsWaitingFrames)
{
    FramePool pool(4, cv::Size(4, 2));
    PairRing ring(2);
    StereoSyncThread sync({5 * kMs, 2});
    sync.start(ring);
    FrameHandle frame = pool.acquire();
    ASSERT_TRUE(frame);
    frame->stamp_ns = 100 * kMs;
    sync.offer(StereoSide::Left, std::move(frame));
    // The lone left frame waits in the sync for a partner that never comes.
    while (pool.inUse() != 1 || sync.stats().pairs != 0)
        std::this_thread::yield();
    sync.stop();
    EXPECT_EQ(pool.inUse(), 0u);
    EXPECT_EQ(sync.stats().drops[0].total(), 1u);
    EXPECT_EQ(ring.pushed(), 0u);
    sync.stop(); // idempotent
}

} // namespace
} // namespace stereod
