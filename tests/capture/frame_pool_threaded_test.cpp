// The frame pool shared by several threads: each buffer has one owner at a time, and all
// come back.

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "capture/frame_pool.hpp"

namespace stereod {
namespace {

TEST(FramePoolThreaded, ConcurrentAcquireAndReleaseGiveEachBufferOneOwner)
{
    constexpr int kThreads = 4;
#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
    constexpr int kRounds = 5'000;
#else
    constexpr int kRounds = 20'000;
#endif
    // Fewer buffers than the threads could hold at once, so exhaustion happens too.
    FramePool pool(5, cv::Size(8, 2));
    std::atomic<uint64_t> shared_owner{0};
    std::atomic<uint64_t> acquired{0};
    std::atomic<uint64_t> empty{0};

    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
        threads.emplace_back([&, t] {
            const auto mark = static_cast<uchar>(t + 1);
            for (int round = 0; round < kRounds; ++round) {
                FrameHandle a = pool.acquire();
                FrameHandle b = pool.acquire();
                for (FrameHandle* frame : {&a, &b}) {
                    if (!*frame) {
                        empty.fetch_add(1, std::memory_order_relaxed);
                        continue;
                    }
                    acquired.fetch_add(1, std::memory_order_relaxed);
                    // Write our mark everywhere, then check nobody else wrote theirs.
                    (*frame)->image.setTo(mark);
                    (*frame)->sequence = static_cast<uint64_t>(round);
                }
                for (FrameHandle* frame : {&a, &b}) {
                    if (*frame && (cv::countNonZero((*frame)->image != mark) != 0 ||
                                   (*frame)->sequence != static_cast<uint64_t>(round)))
                        shared_owner.fetch_add(1, std::memory_order_relaxed);
                }
            }
        });
    }
    for (std::thread& thread : threads)
        thread.join();

    EXPECT_EQ(shared_owner.load(), 0u);
    EXPECT_EQ(pool.inUse(), 0u);
    EXPECT_EQ(acquired.load() + empty.load(), uint64_t{2} * kThreads * kRounds);
    EXPECT_EQ(pool.exhausted(), empty.load());
    EXPECT_GT(acquired.load(), 0u);
}

} // namespace
} // namespace stereod
