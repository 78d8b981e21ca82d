// The frame pool on one thread: a fixed set of buffers that come back when handles die.

#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "capture/frame_pool.hpp"

namespace stereod {
namespace {

TEST(FramePool, BuffersHaveTheRequestedSizeAndType)
{
    FramePool pool(2, cv::Size(64, 48));
    EXPECT_EQ(pool.capacity(), 2u);
    EXPECT_EQ(pool.frameSize(), cv::Size(64, 48));
    FrameHandle frame = pool.acquire();
    ASSERT_TRUE(frame);
    EXPECT_EQ(frame->image.size(), cv::Size(64, 48));
    EXPECT_EQ(frame->image.type(), CV_8UC1);
    EXPECT_TRUE(frame->image.isContinuous());
    EXPECT_EQ(frame->owner, &pool);
}

TEST(FramePool, AcquireUntilExhaustedThenEmptyHandlesAreCounted)
{
    FramePool pool(3, cv::Size(16, 8));
    std::vector<FrameHandle> held;
    for (int i = 0; i < 3; ++i) {
        held.push_back(pool.acquire());
        ASSERT_TRUE(held.back());
    }
    EXPECT_EQ(pool.inUse(), 3u);
    EXPECT_EQ(pool.exhausted(), 0u);

    EXPECT_FALSE(pool.acquire());
    EXPECT_FALSE(pool.acquire());
    EXPECT_EQ(pool.exhausted(), 2u);

    // Three distinct buffers.
    EXPECT_NE(held[0]->image.data, held[1]->image.data);
    EXPECT_NE(held[1]->image.data, held[2]->image.data);
    EXPECT_NE(held[0]->image.data, held[2]->image.data);
}

TEST(FramePool, BufferComesBackWhenItsHandleDies)
{
    FramePool pool(2, cv::Size(16, 8));
    FrameHandle a = pool.acquire();
    FrameHandle b = pool.acquire();
    ASSERT_TRUE(a);
    ASSERT_TRUE(b);
    const uchar* a_pixels = a->image.data;
    a.reset();
    EXPECT_EQ(pool.inUse(), 1u);

    FrameHandle again = pool.acquire();
    ASSERT_TRUE(again);
    EXPECT_EQ(again->image.data, a_pixels); // the same buffer, no new allocation
    EXPECT_EQ(pool.inUse(), 2u);
}

TEST(FramePool, AcquiredFrameHasItsMetadataCleared)
{
    FramePool pool(1, cv::Size(4, 4));
    {
        FrameHandle frame = pool.acquire();
        ASSERT_TRUE(frame);
        frame->stamp_ns = 123;
        frame->source_stamp_ns = 456;
        frame->sequence = 789;
    }
    FrameHandle frame = pool.acquire();
    ASSERT_TRUE(frame);
    EXPECT_EQ(frame->stamp_ns, 0);
    EXPECT_EQ(frame->source_stamp_ns, 0);
    EXPECT_EQ(frame->sequence, 0u);
}

TEST(FramePool, MovingAHandleKeepsOneOwner)
{
    FramePool pool(1, cv::Size(4, 4));
    FrameHandle a = pool.acquire();
    FrameHandle b = std::move(a);
    EXPECT_FALSE(a);
    EXPECT_EQ(pool.inUse(), 1u);
    b.reset();
    EXPECT_EQ(pool.inUse(), 0u);
}

TEST(FramePool, StereoPairGivesBothFramesBack)
{
    FramePool pool(2, cv::Size(4, 4));
    {
        StereoPair pair;
        pair.left = pool.acquire();
        pair.right = pool.acquire();
        pair.left->stamp_ns = 1'000;
        pair.right->stamp_ns = 1'250;
        EXPECT_EQ(pair.stampNs(), 1'000);
        EXPECT_EQ(pair.skewNs(), 250);
        EXPECT_EQ(pool.inUse(), 2u);
    }
    EXPECT_EQ(pool.inUse(), 0u);
}

} // namespace
} // namespace stereod
