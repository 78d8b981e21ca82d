// The pairing rules of StereoSync (capture/stereo_sync.hpp) with synthetic timestamps:
// jitter, skew, drops, bursts, a silent camera, and a persistent clock offset.

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "capture/frame_pool.hpp"
#include "capture/stereo_sync.hpp"

namespace stereod {
namespace {

constexpr int64_t kMs = 1'000'000;
constexpr int64_t kPeriodNs = 33'333'333; // 30 fps

// Frames with chosen stamps from a small pool; the pool checks that every dropped frame
// went back.
class SyncTest : public ::testing::Test {
  protected:
    FrameHandle frame(int64_t stamp_ns, uint64_t sequence = 0)
    {
        FrameHandle handle = pool_.acquire();
        EXPECT_TRUE(handle) << "test pool exhausted: the sync holds frames it should drop";
        if (handle) {
            handle->stamp_ns = stamp_ns;
            handle->sequence = sequence;
        }
        return handle;
    }

    // Adds and collects the pairs it completes as (left stamp, right stamp).
    void add(StereoSync& sync, StereoSide side, int64_t stamp_ns)
    {
        sync.add(side, frame(stamp_ns));
        while (auto pair = sync.takePair()) {
            EXPECT_EQ(pair->index, pairs_.size());
            pairs_.push_back({pair->left->stamp_ns, pair->right->stamp_ns});
        }
    }

    struct Stamps {
        int64_t left_ns;
        int64_t right_ns;
    };
    FramePool pool_{24, cv::Size(4, 2)};
    std::vector<Stamps> pairs_;
};

TEST_F(SyncTest, PairsFramesWithinMaxSkewInEitherArrivalOrder)
{
    StereoSync sync({5 * kMs, 2});
    add(sync, StereoSide::Left, 100 * kMs);
    EXPECT_TRUE(pairs_.empty());
    add(sync, StereoSide::Right, 102 * kMs);
    add(sync, StereoSide::Right, 135 * kMs); // right first this time
    add(sync, StereoSide::Left, 131 * kMs);
    ASSERT_EQ(pairs_.size(), 2u);
    EXPECT_EQ(pairs_[0].left_ns, 100 * kMs);
    EXPECT_EQ(pairs_[0].right_ns, 102 * kMs);
    EXPECT_EQ(pairs_[1].left_ns, 131 * kMs);
    EXPECT_EQ(pairs_[1].right_ns, 135 * kMs);
    const SyncStats stats = sync.stats();
    EXPECT_EQ(stats.pairs, 2u);
    EXPECT_EQ(stats.unpaired(), 0u);
    EXPECT_DOUBLE_EQ(stats.skew_mean_ms, 3.0);
    EXPECT_DOUBLE_EQ(stats.skew_max_ms, 4.0);
    EXPECT_DOUBLE_EQ(stats.skew_signed_mean_ms, 3.0);
    EXPECT_EQ(pool_.inUse(), 0u);
}

TEST_F(SyncTest, SkewAtTheLimitPairsAndJustBeyondItDoesNot)
{
    StereoSync sync({5 * kMs, 2});
    add(sync, StereoSide::Left, 100 * kMs);
    add(sync, StereoSide::Right, 105 * kMs);
    ASSERT_EQ(pairs_.size(), 1u);
    add(sync, StereoSide::Left, 200 * kMs);
    add(sync, StereoSide::Right, 205 * kMs + 1);
    EXPECT_EQ(pairs_.size(), 1u);
    // The left frame is stale (every later right frame is later still); the right one
    // waits for a partner.
    EXPECT_EQ(sync.stats().drops[0].stale, 1u);
    EXPECT_EQ(sync.pending(StereoSide::Left), 0u);
    EXPECT_EQ(sync.pending(StereoSide::Right), 1u);
}

TEST_F(SyncTest, LateFrameOfAnUsedInstantIsRefused)
{
    StereoSync sync({5 * kMs, 2});
    add(sync, StereoSide::Left, 100 * kMs);
    add(sync, StereoSide::Right, 101 * kMs);
    add(sync, StereoSide::Left, 133 * kMs);
    add(sync, StereoSide::Right, 134 * kMs);
    ASSERT_EQ(pairs_.size(), 2u);
    // A right frame from before the last pair arrives late: not newer than its stream's
    // newest, so it is refused (rule 1) and never pairs with the left frame at 133.
    add(sync, StereoSide::Right, 110 * kMs);
    EXPECT_EQ(sync.stats().drops[1].out_of_order, 1u);
    EXPECT_EQ(sync.pending(StereoSide::Right), 0u);
    EXPECT_EQ(pairs_.size(), 2u);
    EXPECT_EQ(pool_.inUse(), 0u);
}

TEST_F(SyncTest, FrameFarBehindTheOtherSidesGivenUpFramesIsRefusedOnArrival)
{
    StereoSync sync({5 * kMs, 2});
    add(sync, StereoSide::Left, 100 * kMs);
    add(sync, StereoSide::Right, 101 * kMs);
    ASSERT_EQ(pairs_.size(), 1u);
    // The left camera lags; the right one goes on and gives up 200 ms for want of a
    // partner (overflow of its two waiting places).
    add(sync, StereoSide::Right, 200 * kMs);
    add(sync, StereoSide::Right, 233 * kMs);
    add(sync, StereoSide::Right, 266 * kMs);
    EXPECT_EQ(sync.stats().drops[1].overflow, 1u);
    // Its frame of 190 ms finally arrives: every right frame still to come is at 233 ms
    // or later, so it can never pair, and it is dropped without being queued (rule 2).
    add(sync, StereoSide::Left, 190 * kMs);
    EXPECT_EQ(sync.stats().drops[0].stale, 1u);
    EXPECT_EQ(sync.pending(StereoSide::Left), 0u);
    // A left frame at 230 ms is not refused on arrival; it pairs with 233.
    add(sync, StereoSide::Left, 230 * kMs);
    ASSERT_EQ(pairs_.size(), 2u);
    EXPECT_EQ(pairs_[1].left_ns, 230 * kMs);
    EXPECT_EQ(pairs_[1].right_ns, 233 * kMs);
}

TEST_F(SyncTest, WaitingFrameBecomesStaleWhenTheOtherSideMovesPast)
{
    StereoSync sync({5 * kMs, 2});
    add(sync, StereoSide::Left, 120 * kMs); // waits for a right frame near 120 ms
    EXPECT_EQ(sync.pending(StereoSide::Left), 1u);
    add(sync, StereoSide::Right, 133 * kMs); // the right camera skipped 120 ms
    EXPECT_EQ(sync.pending(StereoSide::Left), 0u);
    EXPECT_EQ(sync.pending(StereoSide::Right), 1u);
    EXPECT_EQ(sync.stats().drops[0].stale, 1u);
    add(sync, StereoSide::Left, 134 * kMs);
    ASSERT_EQ(pairs_.size(), 1u);
    EXPECT_EQ(pairs_[0].right_ns, 133 * kMs);
}

TEST_F(SyncTest, CloserPartnerQueuedBehindTheFrontWins)
{
    // A wide max_skew (above half the frame period) where two right frames are both in
    // reach of one left frame: the closer one is taken.
    StereoSync sync({20 * kMs, 3});
    add(sync, StereoSide::Right, 100 * kMs);
    add(sync, StereoSide::Right, 130 * kMs);
    add(sync, StereoSide::Left, 118 * kMs);
    ASSERT_EQ(pairs_.size(), 1u);
    EXPECT_EQ(pairs_[0].left_ns, 118 * kMs);
    EXPECT_EQ(pairs_[0].right_ns, 130 * kMs);
    EXPECT_EQ(sync.stats().drops[1].stale, 1u);
}

TEST_F(SyncTest, SilentCameraBoundsTheFramesHeldAndNoOldPartnerIsUsedOnReturn)
{
    StereoSync sync({5 * kMs, 2});
    for (int i = 0; i < 3; ++i) {
        add(sync, StereoSide::Left, i * kPeriodNs);
        add(sync, StereoSide::Right, i * kPeriodNs + 1 * kMs);
    }
    ASSERT_EQ(pairs_.size(), 3u);
    // The right camera goes away for 30 frames: the left side holds at most 2 frames.
    for (int i = 3; i < 33; ++i) {
        add(sync, StereoSide::Left, i * kPeriodNs);
        EXPECT_LE(sync.pending(StereoSide::Left), 2u);
    }
    EXPECT_EQ(sync.stats().drops[0].overflow, 28u);
    EXPECT_EQ(pool_.inUse(), 2u);
    // It comes back: its first frame pairs with the left frame of the same instant,
    // never with the old ones still queued.
    add(sync, StereoSide::Left, 33 * kPeriodNs);
    add(sync, StereoSide::Right, 33 * kPeriodNs + 2 * kMs);
    ASSERT_EQ(pairs_.size(), 4u);
    EXPECT_EQ(pairs_[3].left_ns, 33 * kPeriodNs);
    EXPECT_EQ(pairs_[3].right_ns, 33 * kPeriodNs + 2 * kMs);
    const SyncStats stats = sync.stats();
    EXPECT_EQ(stats.drops[0].overflow + stats.drops[0].stale, 30u);
    EXPECT_EQ(stats.drops[1].total(), 0u);
    EXPECT_EQ(pool_.inUse(), 0u);
}

// Two 30 fps cameras with Gaussian jitter, random drops on either side and occasional
// bursts (a frame delivered late with the next): every pair within max_skew, made of the
// frames taken at the same instant, and every frame either paired or counted.
TEST_F(SyncTest, JitterDropsAndBurstsPairTheRightFramesAndCountTheRest)
{
    constexpr int kFrames = 3000;
    constexpr int64_t kMaxSkewNs = 4 * kMs;
    StereoSync sync({kMaxSkewNs, 2});
    std::mt19937 rng(7);
    std::normal_distribution<double> jitter_ms(0.0, 0.7);
    std::uniform_real_distribution<double> chance(0.0, 1.0);

    struct Arrival {
        StereoSide side;
        int64_t stamp_ns;
        uint64_t sequence;
    };
    std::vector<Arrival> arrivals;
    int delivered[2] = {0, 0};
    for (int i = 0; i < kFrames; ++i) {
        const int64_t base_ns = 1'000 * kMs + i * kPeriodNs;
        Arrival frames[2];
        int count = 0;
        for (int side = 0; side < 2; ++side) {
            if (chance(rng) < 0.05)
                continue; // dropped by the camera
            const auto stamp = base_ns + static_cast<int64_t>(jitter_ms(rng) * 1e6);
            frames[count++] = {static_cast<StereoSide>(side), stamp, static_cast<uint64_t>(i)};
            ++delivered[side];
        }
        // Either camera may deliver first.
        if (count == 2 && chance(rng) < 0.5)
            std::swap(frames[0], frames[1]);
        for (int k = 0; k < count; ++k)
            arrivals.push_back(frames[k]);
    }
    // Bursts: now and then a left frame is delivered after the next right frame.
    for (std::size_t i = 0; i + 2 < arrivals.size(); i += 97) {
        if (arrivals[i].side == StereoSide::Left && arrivals[i + 1].side == StereoSide::Right &&
            arrivals[i + 2].side == StereoSide::Right)
            std::swap(arrivals[i], arrivals[i + 2]);
    }

    uint64_t expected_pairs = 0;
    std::vector<bool> both(kFrames, false);
    {
        std::vector<int> seen(kFrames, 0);
        for (const Arrival& a : arrivals)
            seen[a.sequence] |= 1 << static_cast<int>(a.side);
        for (int i = 0; i < kFrames; ++i) {
            both[i] = seen[i] == 3;
            expected_pairs += both[i] ? 1 : 0;
        }
    }

    std::vector<std::pair<uint64_t, uint64_t>> sequences;
    for (const Arrival& a : arrivals) {
        FrameHandle f = frame(a.stamp_ns, a.sequence);
        sync.add(a.side, std::move(f));
        while (auto pair = sync.takePair()) {
            EXPECT_LE(std::llabs(pair->skewNs()), kMaxSkewNs);
            sequences.push_back({pair->left->sequence, pair->right->sequence});
        }
    }

    std::size_t mismatched = 0;
    for (const auto& [left, right] : sequences)
        mismatched += left != right ? 1 : 0;
    EXPECT_EQ(mismatched, 0u) << "frames of different instants paired";
    const SyncStats stats = sync.stats();
    // Jitter of 0.7 ms against 4 ms max_skew: every instant with both frames pairs,
    // except where a burst reordered the left frame after a newer right frame.
    EXPECT_GE(static_cast<double>(sequences.size()), 0.98 * static_cast<double>(expected_pairs));
    EXPECT_LE(sequences.size(), expected_pairs);
    EXPECT_EQ(stats.pairs, sequences.size());
    for (int side = 0; side < 2; ++side) {
        EXPECT_EQ(stats.pairs + stats.drops[side].total() +
                      sync.pending(static_cast<StereoSide>(side)),
                  static_cast<uint64_t>(delivered[side]))
            << "side " << side << ": a frame neither paired nor counted";
    }
    EXPECT_NEAR(stats.skew_mean_ms, 0.79, 0.15); // E|N(0, 0.7 sqrt 2)| = 0.79 ms
    EXPECT_LT(stats.skew_p99_ms, 3.5);
    EXPECT_LE(stats.skew_max_ms, 4.0);
    EXPECT_FALSE(stats.offset_detected) << "estimate " << stats.offset_estimate_ms << " ms";
}

// The right camera's clock (or shutter) runs 3 ms behind: every pair forms, all skewed
// the same way. The sync reports the offset rather than absorbing it.
TEST_F(SyncTest, ConsistentSkewWithinMaxSkewIsReportedAsAnOffset)
{
    StereoSync sync({5 * kMs, 2});
    std::mt19937 rng(3);
    std::normal_distribution<double> jitter_ms(0.0, 0.3);
    for (int i = 0; i < 200; ++i) {
        const int64_t base_ns = i * kPeriodNs;
        add(sync, StereoSide::Left, base_ns + static_cast<int64_t>(jitter_ms(rng) * 1e6));
        add(sync, StereoSide::Right,
            base_ns + 3 * kMs + static_cast<int64_t>(jitter_ms(rng) * 1e6));
    }
    const SyncStats stats = sync.stats();
    EXPECT_EQ(stats.pairs, 200u);
    EXPECT_TRUE(stats.offset_detected);
    EXPECT_NEAR(stats.offset_estimate_ms, 3.0, 0.3);
    EXPECT_NEAR(stats.skew_signed_mean_ms, 3.0, 0.2);
}

// 12 ms apart with max_skew 5 ms: no pair at all, and the offset is still measured from
// the dropped frames' nearest neighbours.
TEST_F(SyncTest, OffsetBeyondMaxSkewGivesNoPairsAndIsEstimated)
{
    StereoSync sync({5 * kMs, 2});
    for (int i = 0; i < 100; ++i) {
        add(sync, StereoSide::Left, i * kPeriodNs);
        add(sync, StereoSide::Right, i * kPeriodNs - 12 * kMs);
    }
    const SyncStats stats = sync.stats();
    EXPECT_EQ(stats.pairs, 0u);
    EXPECT_GE(stats.unpaired(), 196u);
    EXPECT_TRUE(stats.offset_detected);
    EXPECT_NEAR(stats.offset_estimate_ms, -12.0, 0.01);
    EXPECT_LE(pool_.inUse(), 4u);
}

TEST_F(SyncTest, OutOfOrderFramesAndClearAreCountedAndReleased)
{
    StereoSync sync({5 * kMs, 2});
    add(sync, StereoSide::Left, 100 * kMs);
    add(sync, StereoSide::Left, 100 * kMs); // same stamp again
    add(sync, StereoSide::Left, 50 * kMs);
    EXPECT_EQ(sync.stats().drops[0].out_of_order, 2u);
    EXPECT_EQ(pool_.inUse(), 1u);
    sync.clear();
    EXPECT_EQ(pool_.inUse(), 0u);
    EXPECT_EQ(sync.stats().drops[0].stale, 1u);
    // After clear() the streams start afresh: an earlier stamp is accepted again.
    add(sync, StereoSide::Left, 50 * kMs);
    add(sync, StereoSide::Right, 51 * kMs);
    EXPECT_EQ(pairs_.size(), 1u);
}

TEST(StereoSyncSettings, RefusesNonsense)
{
    EXPECT_THROW(StereoSync({0, 2}), std::invalid_argument);
    EXPECT_THROW(StereoSync({5 * kMs, 0}), std::invalid_argument);
    EXPECT_THROW(StereoSync({5 * kMs, StereoSync::kMaxPending + 1}), std::invalid_argument);
}

} // namespace
} // namespace stereod
