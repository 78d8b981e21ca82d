// The hand-off from the worker to the I/O thread: a triple buffer and an eventfd. The
// reader must always get a complete result, the newest published or a newer one, never
// one the writer is filling.

#include <atomic>
#include <cstdint>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <poll.h>

#include "daemon/publisher.hpp"

namespace stereod {
namespace {

bool readable(int fd)
{
    pollfd descriptor{fd, POLLIN, 0};
    return ::poll(&descriptor, 1, 0) == 1 && (descriptor.revents & POLLIN) != 0;
}

// Fills a slot so that every part of it says `n`: a torn slot has parts that disagree.
void fill(PublishedFrame& slot, uint64_t n)
{
    slot.depth_mm.create(48, 64, CV_16UC1);
    slot.depth_mm.setTo(static_cast<uint16_t>(n & 0xFFFF));
    slot.result.frame = n;
    slot.result.stamp_ns = static_cast<int64_t>(n) * 1000;
    slot.result.reading.frame = n;
    slot.reason_message.format("frame %llu", static_cast<unsigned long long>(n));
}

// Empty when the slot is whole, else what disagrees.
std::string checkWhole(const PublishedFrame& slot)
{
    const uint64_t n = slot.sequence;
    if (slot.result.frame != n || slot.result.reading.frame != n ||
        slot.result.stamp_ns != static_cast<int64_t>(n) * 1000)
        return "metadata of " + std::to_string(slot.result.frame) + " in slot " + std::to_string(n);
    if (slot.reason_message.view() != "frame " + std::to_string(n))
        return "message \"" + std::string(slot.reason_message.view()) + "\" in slot " +
               std::to_string(n);
    const auto expected = static_cast<uint16_t>(n & 0xFFFF);
    for (int row = 0; row < slot.depth_mm.rows; ++row) {
        for (int col = 0; col < slot.depth_mm.cols; ++col) {
            if (slot.depth_mm.at<uint16_t>(row, col) != expected)
                return "pixel of another frame in slot " + std::to_string(n);
        }
    }
    return {};
}

TEST(Publisher, NothingBeforeTheFirstPublish)
{
    Publisher publisher;
    EXPECT_EQ(publisher.latest(), nullptr);
    EXPECT_EQ(publisher.publishedCount(), 0u);
    EXPECT_FALSE(readable(publisher.eventFd()));
}

TEST(Publisher, ReaderGetsTheNewestAndKeepsItUntilItAsksAgain)
{
    Publisher publisher;
    fill(publisher.writeSlot(), 1);
    publisher.publish();
    EXPECT_TRUE(readable(publisher.eventFd()));
    publisher.clearEvent();
    EXPECT_FALSE(readable(publisher.eventFd()));

    const PublishedFrame* first = publisher.latest();
    ASSERT_NE(first, nullptr);
    EXPECT_EQ(first->sequence, 1u);
    EXPECT_EQ(checkWhole(*first), "");
    EXPECT_GT(first->published_ns, 0);

    // Two more results before the reader looks again: it gets the newest, and the slot it
    // held was not written meanwhile.
    fill(publisher.writeSlot(), 2);
    publisher.publish();
    EXPECT_EQ(first->sequence, 1u);
    EXPECT_EQ(checkWhole(*first), "");
    fill(publisher.writeSlot(), 3);
    publisher.publish();
    EXPECT_EQ(checkWhole(*first), "");

    const PublishedFrame* newest = publisher.latest();
    ASSERT_NE(newest, nullptr);
    EXPECT_EQ(newest->sequence, 3u);
    EXPECT_EQ(checkWhole(*newest), "");
    // Nothing new: the same result again.
    EXPECT_EQ(publisher.latest(), newest);
    EXPECT_EQ(publisher.publishedCount(), 3u);
}

TEST(Publisher, WriterNeverGetsTheReadersSlot)
{
    Publisher publisher;
    for (uint64_t n = 1; n <= 50; ++n) {
        fill(publisher.writeSlot(), n);
        publisher.publish();
        const PublishedFrame* held = publisher.latest();
        ASSERT_NE(held, nullptr);
        EXPECT_NE(&publisher.writeSlot(), held) << n;
    }
}

TEST(Publisher, ConcurrentReaderSeesWholeNewestOrNewerResults)
{
    constexpr uint64_t kResults = 20000;
    Publisher publisher;
    std::atomic<bool> writer_done{false};

    std::thread writer([&] {
        for (uint64_t n = 1; n <= kResults; ++n) {
            fill(publisher.writeSlot(), n);
            publisher.publish();
        }
        writer_done.store(true, std::memory_order_release);
    });

    uint64_t last_seen = 0;
    uint64_t distinct = 0;
    std::string first_problem;
    while (last_seen < kResults) {
        if ((distinct & 7) == 0) {
            // Now and then wait on the eventfd like the I/O thread does.
            pollfd descriptor{publisher.eventFd(), POLLIN, 0};
            ::poll(&descriptor, 1, 1);
            publisher.clearEvent();
        }
        const uint64_t published_before = publisher.publishedCount();
        const PublishedFrame* frame = publisher.latest();
        if (frame == nullptr) {
            ASSERT_EQ(published_before, 0u);
            continue;
        }
        ASSERT_GE(frame->sequence, published_before)
            << "an older result than one already published";
        ASSERT_GE(frame->sequence, last_seen) << "results went backwards";
        if (frame->sequence != last_seen) {
            ++distinct;
            if (const std::string problem = checkWhole(*frame);
                !problem.empty() && first_problem.empty())
                first_problem = problem;
            last_seen = frame->sequence;
        }
    }
    writer.join();
    EXPECT_TRUE(writer_done.load());
    EXPECT_EQ(first_problem, "");
    EXPECT_EQ(last_seen, kResults);
    EXPECT_GT(distinct, 1u);
}

TEST(FixedText, CutsLongTextsAndFormats)
{
    FixedText text;
    EXPECT_TRUE(text.empty());
    text.assign(std::string(1000, 'a'));
    EXPECT_EQ(text.view().size(), FixedText::kCapacity);
    text.format("%d ms apart, %.1f ms allowed", 12, 5.0);
    EXPECT_EQ(text.view(), "12 ms apart, 5.0 ms allowed");
    text.format("%s", std::string(600, 'b').c_str());
    EXPECT_EQ(text.view().size(), FixedText::kCapacity);
    text.clear();
    EXPECT_TRUE(text.empty());
}

} // namespace
} // namespace stereod
