// The ring with a real producer and consumer: wake-ups, back-pressure and a stress run
// whose bookkeeping must balance exactly (CI runs this under ThreadSanitizer).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <optional>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "capture/spsc_ring.hpp"

namespace stereod {
namespace {

// Sanitizers slow every atomic down several times; the stress runs stay in seconds.
#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
constexpr uint64_t kStressItems = 50'000;
#else
constexpr uint64_t kStressItems = 200'000;
#endif

// Gives a broken implementation the chance to do what it must not (return early, drop
// an item). A correct one passes however long or short this is.
void giveOtherThreadTime()
{
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
}

TEST(SpscRingThreaded, StopWakesAConsumerBlockedInPop)
{
    SpscRing<int> ring(4);
    std::atomic<bool> returned{false};
    std::optional<int> got;
    std::thread consumer([&] {
        got = ring.pop();
        returned.store(true);
    });
    giveOtherThreadTime();
    EXPECT_FALSE(returned.load()); // nothing queued: pop() must still be waiting
    ring.stop();
    consumer.join();
    EXPECT_TRUE(returned.load());
    EXPECT_FALSE(got.has_value());
}

TEST(SpscRingThreaded, PushWakesAConsumerBlockedInPop)
{
    SpscRing<int> ring(4);
    std::optional<int> got;
    std::thread consumer([&] { got = ring.pop(); });
    giveOtherThreadTime();
    ring.push(42);
    consumer.join();
    ASSERT_TRUE(got.has_value());
    EXPECT_EQ(*got, 42);
}

TEST(SpscRingThreaded, PushWaitWaitsForRoom)
{
    SpscRing<int> ring(2);
    ring.push(0);
    ring.push(1);
    std::atomic<bool> returned{false};
    bool accepted = false;
    std::thread producer([&] {
        accepted = ring.pushWait(2);
        returned.store(true);
    });
    giveOtherThreadTime();
    EXPECT_FALSE(returned.load()); // full ring: still waiting, nothing dropped
    EXPECT_EQ(ring.dropped(), 0u);

    std::optional<int> first = ring.tryPop();
    producer.join();
    ASSERT_TRUE(first.has_value());
    EXPECT_EQ(*first, 0);
    EXPECT_TRUE(accepted);
    for (int expected = 1; expected <= 2; ++expected) {
        std::optional<int> item = ring.tryPop();
        ASSERT_TRUE(item.has_value());
        EXPECT_EQ(*item, expected);
    }
    EXPECT_EQ(ring.dropped(), 0u);
}

TEST(SpscRingThreaded, StopReleasesAProducerBlockedInPushWait)
{
    SpscRing<int> ring(2);
    ring.push(0);
    ring.push(1);
    bool accepted = true;
    std::thread producer([&] { accepted = ring.pushWait(2); });
    giveOtherThreadTime();
    ring.stop();
    producer.join();
    EXPECT_FALSE(accepted);
    EXPECT_EQ(ring.size(), 2u);
    EXPECT_EQ(ring.pushed(), 2u);
}

// An item whose move can be held up on purpose, to freeze the consumer between claiming
// the oldest slot and finishing moving its item out.
struct Gate {
    std::atomic<bool> hold_next_move{false};
    std::atomic<bool> holding{false};
    std::atomic<bool> released{false};
};

struct GatedItem {
    int value = 0;
    Gate* gate = nullptr;

    GatedItem(int v, Gate* g) : value(v), gate(g) {}
    GatedItem(GatedItem&& other) noexcept : value(other.value), gate(other.gate)
    {
        if (gate != nullptr && gate->hold_next_move.exchange(false)) {
            gate->holding.store(true);
            gate->holding.notify_all();
            gate->released.wait(false);
        }
    }
    GatedItem& operator=(GatedItem&&) = delete;
};

TEST(SpscRingThreaded, PushDuringAConsumersMoveDropsNothing)
{
    // Full ring; the consumer claims item 0 and stalls while moving it out. A push now
    // needs exactly that slot: it must wait for it, not throw away items 1..3.
    Gate gate;
    SpscRing<GatedItem> ring(4);
    for (int i = 0; i < 4; ++i)
        ring.push(GatedItem(i, &gate));

    gate.hold_next_move.store(true);
    int popped_value = -1;
    std::thread consumer([&] {
        if (std::optional<GatedItem> item = ring.tryPop())
            popped_value = item->value;
    });
    gate.holding.wait(false);

    std::thread producer([&] { ring.push(GatedItem(4, &gate)); });
    giveOtherThreadTime();
    gate.released.store(true);
    gate.released.notify_all();
    consumer.join();
    producer.join();

    EXPECT_EQ(popped_value, 0);
    EXPECT_EQ(ring.dropped(), 0u);
    for (int expected = 1; expected <= 4; ++expected) {
        std::optional<GatedItem> item = ring.tryPop();
        ASSERT_TRUE(item.has_value());
        EXPECT_EQ(item->value, expected);
    }
}

// Records, per sequence number, who disposed of the item: the consumer (popped) or the
// producer's drop (destroyed while still owning its value). Each array is written by one
// thread only.
struct Ledger {
    explicit Ledger(uint64_t n) : popped(n, 0), dropped(n, 0) {}
    std::vector<uint8_t> popped;
    std::vector<uint8_t> dropped;
};

class TrackedItem {
  public:
    TrackedItem(uint64_t seq, Ledger* ledger) : seq_(seq), ledger_(ledger) {}
    TrackedItem(TrackedItem&& other) noexcept : seq_(other.seq_), ledger_(other.ledger_)
    {
        other.ledger_ = nullptr;
    }
    TrackedItem& operator=(TrackedItem&&) = delete;
    ~TrackedItem()
    {
        if (ledger_ != nullptr)
            ++ledger_->dropped[seq_];
    }

    // The consumer took it: destroying it later is no drop.
    uint64_t take()
    {
        ++ledger_->popped[seq_];
        ledger_ = nullptr;
        return seq_;
    }

  private:
    uint64_t seq_;
    Ledger* ledger_;
};

TEST(SpscRingThreaded, StressDropOldestLosesAndDuplicatesNothing)
{
    Ledger ledger(kStressItems);
    SpscRing<TrackedItem> ring(8);
    std::atomic<bool> order_ok{true};
    uint64_t popped = 0;

    std::thread consumer([&] {
        uint64_t last = 0;
        bool first = true;
        while (std::optional<TrackedItem> item = ring.pop()) {
            const uint64_t seq = item->take();
            if (!first && seq <= last)
                order_ok.store(false);
            first = false;
            last = seq;
            ++popped;
        }
    });
    std::thread producer([&] {
        for (uint64_t seq = 0; seq < kStressItems; ++seq)
            ring.push(TrackedItem(seq, &ledger));
        ring.stop();
    });
    producer.join();
    consumer.join();

    // Anything the consumer did not drain is still accounted for.
    const uint64_t left_in_ring = ring.size();
    while (std::optional<TrackedItem> item = ring.tryPop())
        item->take();

    EXPECT_TRUE(order_ok.load());
    EXPECT_EQ(ring.pushed(), kStressItems);
    EXPECT_EQ(ring.pushed(), popped + ring.dropped() + left_in_ring);

    uint64_t lost = 0;
    uint64_t duplicated = 0;
    uint64_t dropped = 0;
    for (uint64_t seq = 0; seq < kStressItems; ++seq) {
        const int seen = ledger.popped[seq] + ledger.dropped[seq];
        lost += seen == 0 ? 1 : 0;
        duplicated += seen > 1 ? 1 : 0;
        dropped += ledger.dropped[seq];
    }
    EXPECT_EQ(lost, 0u);
    EXPECT_EQ(duplicated, 0u);
    EXPECT_EQ(dropped, ring.dropped()); // every counted drop destroyed its item, once
}

TEST(SpscRingThreaded, StressPushWaitDeliversEverythingInOrder)
{
    SpscRing<uint64_t> ring(8);
    std::atomic<bool> order_ok{true};
    uint64_t popped = 0;

    std::thread consumer([&] {
        uint64_t expected = 0;
        while (std::optional<uint64_t> item = ring.pop()) {
            if (*item != expected)
                order_ok.store(false);
            expected = *item + 1;
            ++popped;
        }
    });
    std::atomic<bool> refused{false};
    std::thread producer([&] {
        for (uint64_t seq = 0; seq < kStressItems; ++seq) {
            if (!ring.pushWait(uint64_t{seq})) {
                refused.store(true);
                break;
            }
        }
        ring.stop();
    });
    producer.join();
    consumer.join();

    EXPECT_FALSE(refused.load());
    EXPECT_TRUE(order_ok.load());
    EXPECT_EQ(popped, kStressItems);
    EXPECT_EQ(ring.dropped(), 0u);
    EXPECT_EQ(ring.pushed(), kStressItems);
    EXPECT_EQ(ring.size(), 0u);
}

} // namespace
} // namespace stereod
