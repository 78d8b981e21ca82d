// The ring's contract on one thread: order, drop-oldest, capacity, stop.

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "capture/frame_pool.hpp"
#include "capture/spsc_ring.hpp"

namespace stereod {
namespace {

// Pushes `count` frames of the pool, numbered 0.. in their sequence.
void pushFrames(FramePool& pool, SpscRing<FrameHandle>& ring, uint64_t count)
{
    for (uint64_t seq = 0; seq < count; ++seq) {
        FrameHandle frame = pool.acquire();
        ASSERT_TRUE(frame);
        frame->sequence = seq;
        ring.push(std::move(frame));
    }
}

TEST(SpscRing, CapacityIsRoundedUpToAPowerOfTwoOfAtLeastTwo)
{
    EXPECT_EQ(SpscRing<int>(0).capacity(), 2u);
    EXPECT_EQ(SpscRing<int>(1).capacity(), 2u);
    EXPECT_EQ(SpscRing<int>(2).capacity(), 2u);
    EXPECT_EQ(SpscRing<int>(3).capacity(), 4u);
    EXPECT_EQ(SpscRing<int>(4).capacity(), 4u);
    EXPECT_EQ(SpscRing<int>(5).capacity(), 8u);
    EXPECT_EQ(SpscRing<int>(1000).capacity(), 1024u);
}

TEST(SpscRing, RoundedCapacityIsUsable)
{
    // Asked for 3, got 4: four items fit without a drop.
    SpscRing<int> ring(3);
    for (int i = 0; i < 4; ++i)
        EXPECT_TRUE(ring.push(int{i}));
    EXPECT_EQ(ring.dropped(), 0u);
    EXPECT_EQ(ring.size(), 4u);
}

TEST(SpscRing, DeliversInFifoOrderAcrossWrapArounds)
{
    SpscRing<int> ring(4);
    int next_in = 0;
    int next_out = 0;
    // Uneven batches make the indices wrap many times at different offsets.
    for (int round = 0; round < 50; ++round) {
        const int batch = 1 + round % 4;
        for (int i = 0; i < batch; ++i)
            ASSERT_TRUE(ring.push(int{next_in++}));
        for (int i = 0; i < batch; ++i) {
            std::optional<int> item = ring.tryPop();
            ASSERT_TRUE(item.has_value());
            EXPECT_EQ(*item, next_out++);
        }
        EXPECT_FALSE(ring.tryPop().has_value());
    }
    EXPECT_EQ(ring.pushed(), static_cast<uint64_t>(next_in));
    EXPECT_EQ(ring.dropped(), 0u);
}

TEST(SpscRing, EmptyRingGivesNothing)
{
    SpscRing<int> ring(2);
    EXPECT_FALSE(ring.tryPop().has_value());
    EXPECT_EQ(ring.size(), 0u);
}

TEST(SpscRing, FullRingDropsTheOldestAndCountsIt)
{
    SpscRing<int> ring(4);
    for (int i = 0; i < 4; ++i)
        EXPECT_TRUE(ring.push(int{i}));
    EXPECT_FALSE(ring.push(4)); // drops 0
    EXPECT_FALSE(ring.push(5)); // drops 1
    EXPECT_EQ(ring.dropped(), 2u);
    EXPECT_EQ(ring.pushed(), 6u);
    EXPECT_EQ(ring.size(), 4u);
    for (int expected = 2; expected <= 5; ++expected) {
        std::optional<int> item = ring.tryPop();
        ASSERT_TRUE(item.has_value());
        EXPECT_EQ(*item, expected);
    }
    EXPECT_FALSE(ring.tryPop().has_value());
}

TEST(SpscRing, DroppedFrameGoesBackToItsPool)
{
    FramePool pool(4, cv::Size(8, 4));
    SpscRing<FrameHandle> ring(2);
    pushFrames(pool, ring, 3);
    // Three pushed into two slots: the first was destroyed by the push that dropped it.
    EXPECT_EQ(ring.dropped(), 1u);
    EXPECT_EQ(pool.inUse(), 2u);

    std::optional<FrameHandle> first = ring.tryPop();
    ASSERT_TRUE(first.has_value());
    EXPECT_EQ((*first)->sequence, 1u);
    first.reset();
    EXPECT_EQ(pool.inUse(), 1u);
    std::optional<FrameHandle> second = ring.tryPop();
    ASSERT_TRUE(second.has_value());
    EXPECT_EQ((*second)->sequence, 2u);
    second.reset();
    EXPECT_EQ(pool.inUse(), 0u);
}

TEST(SpscRing, PopNewestTakesTheNewestAndDropsTheOlderOnesBackToTheirPool)
{
    FramePool pool(4, cv::Size(8, 4));
    SpscRing<FrameHandle> ring(4);
    pushFrames(pool, ring, 3);
    std::optional<FrameHandle> newest = ring.popNewest();
    ASSERT_TRUE(newest.has_value());
    EXPECT_EQ((*newest)->sequence, 2u);
    EXPECT_EQ(ring.dropped(), 2u);
    EXPECT_EQ(ring.size(), 0u);
    EXPECT_EQ(pool.inUse(), 1u) << "the two older frames went back to the pool";

    // One waiting: nothing dropped. Stopped and empty: nothing, without waiting.
    ring.push(pool.acquire());
    EXPECT_TRUE(ring.popNewest().has_value());
    EXPECT_EQ(ring.dropped(), 2u);
    ring.stop();
    EXPECT_FALSE(ring.popNewest().has_value());
}

TEST(SpscRing, DestroyingTheRingReleasesWhatItHolds)
{
    FramePool pool(3, cv::Size(8, 4));
    {
        SpscRing<FrameHandle> ring(4);
        ring.push(pool.acquire());
        ring.push(pool.acquire());
        EXPECT_EQ(pool.inUse(), 2u);
    }
    EXPECT_EQ(pool.inUse(), 0u);
}

TEST(SpscRing, PopAfterStopDrainsThenReturnsNothing)
{
    SpscRing<int> ring(4);
    ring.push(10);
    ring.push(11);
    ring.stop();
    EXPECT_TRUE(ring.stopped());
    std::optional<int> a = ring.pop();
    std::optional<int> b = ring.pop();
    ASSERT_TRUE(a.has_value());
    ASSERT_TRUE(b.has_value());
    EXPECT_EQ(*a, 10);
    EXPECT_EQ(*b, 11);
    EXPECT_FALSE(ring.pop().has_value());
    EXPECT_FALSE(ring.pop().has_value());
}

TEST(SpscRing, PushWaitOnAStoppedFullRingGivesUpAndDropsItsItem)
{
    FramePool pool(3, cv::Size(8, 4));
    SpscRing<FrameHandle> ring(2);
    ring.push(pool.acquire());
    ring.push(pool.acquire());
    ring.stop();
    EXPECT_FALSE(ring.pushWait(pool.acquire()));
    EXPECT_EQ(pool.inUse(), 2u); // the refused frame went back to the pool
    EXPECT_EQ(ring.pushed(), 2u);
    EXPECT_EQ(ring.dropped(), 0u); // a refused pushWait is not a ring drop
}

TEST(SpscRing, PushWaitWithRoomDoesNotWait)
{
    SpscRing<int> ring(2);
    EXPECT_TRUE(ring.pushWait(1));
    EXPECT_TRUE(ring.pushWait(2));
    EXPECT_EQ(ring.size(), 2u);
}

TEST(SpscRing, RestartRearmsAStoppedRingAndKeepsItsItems)
{
    SpscRing<int> ring(2);
    ring.push(7);
    ring.stop();
    ring.restart();
    EXPECT_FALSE(ring.stopped());
    std::optional<int> item = ring.pop();
    ASSERT_TRUE(item.has_value());
    EXPECT_EQ(*item, 7);
}

} // namespace
} // namespace stereod
