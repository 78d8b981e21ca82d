#pragma once
// Stereo sync: pairs the frames of two free-running cameras by capture time.
//
// The pairing rules (StereoSync; tested in tests/capture/stereo_sync_test.cpp). Stamps are
// CLOCK_MONOTONIC capture times; max_skew is SyncSettings::max_skew_ns.
//  1. Each side's frames must come in increasing stamp order. A frame not newer than the
//     previous frame of its side is dropped (out_of_order).
//  2. Stale on arrival: a frame whose stamp is more than max_skew before the newest frame
//     the other side has already given up (paired or dropped) can never be paired, since
//     every frame still to come from the other side is newer still. It is dropped at once
//     (stale) instead of holding its buffer.
//  3. With frames waiting on both sides, the oldest of each, l and r:
//     - r - l > max_skew: l is stale (every right frame to come is later than r), dropped;
//     - l - r > max_skew: r is stale, dropped;
//     - otherwise they are partners, unless a frame queued behind one of them is strictly
//       closer to the other (then the one it displaces is dropped as stale: its only
//       possible partner prefers another frame). Ties go to the older frame.
//     A pair is made as soon as both frames are there; the sync does not wait for a
//     possibly closer frame not yet arrived. With max_skew below half the frame period (the
//     configuration checks it) no later frame can be closer.
//  4. A side holding max_pending frames while the other side delivers nothing drops its
//     oldest (overflow): it bounds the camera buffers the sync holds when one camera is
//     silent, so the other keeps streaming.
// Every drop is counted per side and per reason. Nothing is paired across a gap larger
// than max_skew, so a camera that comes back after an outage never pairs with old frames.
//
// Clock offset: for every frame leaving the sync through pairing or a stale drop, both
// neighbours in the other stream are known (the newest frame it gave up and its oldest
// waiting frame), so the sync records the signed distance right - left to the nearest one.
// When most of a recent window of these distances share one sign and their median exceeds
// max_skew / 2, the cameras run with a persistent offset (or are not synchronized at all)
// and SyncStats says so with the estimate. The estimate is the median distance: from
// timestamps alone an offset is only known modulo the frame period.
//
// Skew statistics (mean, p99, max of |right - left| of the recent pairs) come from a
// fixed window; nothing here allocates after construction.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <thread>

#include "base/rolling_window.hpp"
#include "capture/captured_frame.hpp"
#include "capture/frame.hpp"
#include "capture/frame_source.hpp"
#include "capture/spsc_ring.hpp"

namespace stereod {

enum class StereoSide : int { Left = 0, Right = 1 };

struct SyncSettings {
    int64_t max_skew_ns = 5'000'000; // partners at most this far apart in capture time
    // Frames held per side waiting for a partner (1 to 8). Must exceed the number of
    // frames one camera can be delivered ahead of the other, or pairs are lost.
    std::size_t max_pending = 4;
};

// Why frames of one side were dropped without a partner.
struct SideDrops {
    uint64_t stale = 0;        // rules 2 and 3: no partner possible any more
    uint64_t overflow = 0;     // rule 4: the other side was silent
    uint64_t out_of_order = 0; // rule 1: stamp not newer than the previous frame's

    uint64_t total() const noexcept { return stale + overflow + out_of_order; }
};

struct SyncStats {
    uint64_t pairs = 0;
    SideDrops drops[2]; // indexed by StereoSide
    // |right - left| of the recent pairs (the last kSkewWindowPairs), in ms.
    double skew_mean_ms = 0.0;
    double skew_p99_ms = 0.0;
    double skew_max_ms = 0.0;
    // Signed mean right - left of the recent pairs, in ms.
    double skew_signed_mean_ms = 0.0;
    // A persistent offset between the cameras' clocks (see the header comment).
    bool offset_detected = false;
    double offset_estimate_ms = 0.0; // right minus left, modulo the frame period
    std::size_t offset_samples = 0;  // distances the estimate is made of

    uint64_t unpaired() const noexcept { return drops[0].total() + drops[1].total(); }
};

// Copies the sync's figures into a source's status: pairs, the frames left unpaired, the
// skew over the recent pairs and the clock offset (the warning about it is the source's).
void addSyncFigures(const SyncStats& sync, SourceStatus& out) noexcept;

// The source's warning about a clock offset the sync detected, when it did: "<apart> are
// X ms apart (right minus left, over N <samples>; max_skew Y ms): <cause>".
void addClockOffsetWarning(const SyncStats& sync, int64_t max_skew_ns, const char* apart,
                           const char* samples, const char* cause, SourceStatus& out);

// The pure pairing logic (rules above). Thread-bound: one thread adds frames and takes
// pairs. Dropped frames are released (their buffers given back) inside add()/takePair().
class StereoSync {
  public:
    static constexpr std::size_t kMaxPending = 8;
    static constexpr std::size_t kOffsetWindow = 64; // distances in the offset estimate
    // Distances needed before an offset is reported.
    static constexpr std::size_t kOffsetMinSamples = 16;

    // Throws std::invalid_argument for max_skew_ns <= 0 or max_pending outside 1..8.
    explicit StereoSync(SyncSettings settings);

    // Offers a frame of one side (an empty handle is ignored). The frame is queued, or
    // dropped and counted when it can never be paired (rules 1, 2, 4).
    void add(StereoSide side, FrameHandle frame);

    // The next pair, or nothing until more frames arrive. Call until it gives nothing
    // after each add(). Pair indices count from 0.
    std::optional<StereoPair> takePair();

    // Drops everything waiting (counted as stale) and forgets the newest stamps, for a
    // restart of both cameras. The counters and statistics stay.
    void clear();

    // Counters and statistics now. Does not allocate.
    SyncStats stats() const noexcept;

    std::size_t pending(StereoSide side) const noexcept
    {
        return queues_[static_cast<int>(side)].size;
    }
    const SyncSettings& settings() const noexcept { return settings_; }

  private:
    struct Queue {
        std::array<FrameHandle, kMaxPending> frames;
        std::size_t head = 0;
        std::size_t size = 0;

        Frame& at(std::size_t i) { return *frames[(head + i) % kMaxPending]; }
        const Frame& at(std::size_t i) const { return *frames[(head + i) % kMaxPending]; }
        void push(FrameHandle frame);
        FrameHandle pop();
    };

    // Drops the oldest frame of `side` for `reason` (stale or overflow), noting its
    // distance to the other stream when both neighbours are known.
    void dropFront(int side, uint64_t SideDrops::*reason);
    // Notes the signed right - left distance of a frame of `side` with stamp `stamp_ns`
    // to the nearer of the other stream's newest given-up frame and oldest waiting frame.
    void noteNeighbourDistance(int side, int64_t stamp_ns);
    void noteDistance(int64_t right_minus_left_ns) noexcept;

    SyncSettings settings_;
    Queue queues_[2];
    // Newest stamp seen (queued or not) and newest stamp given up, per side; INT64_MIN
    // while there is none.
    int64_t newest_seen_ns_[2];
    int64_t newest_done_ns_[2];
    uint64_t pairs_ = 0;
    SideDrops drops_[2];

    RollingWindow<kSkewWindowPairs> skew_; // signed right - left of recent pairs
    std::array<int64_t, kOffsetWindow> distance_ns_{};
    std::size_t distance_next_ = 0;
    std::size_t distance_count_ = 0;
};

// The threaded sync: each camera's capture thread pushes its frames into its side's inbox
// (a CapturedRing, drop-oldest) and bumps the wake counter (lock-free: V4l2Camera::start()
// takes both), and one sync thread pairs them with a StereoSync and pushes the pairs into
// the PairRing (drop-oldest). The sync thread is the PairRing's only producer.
//
// Thread-safety: each inbox has one producer at a time (its camera's capture thread, or
// offer() for that side); start()/stop() from the controlling thread; stats() from any
// thread.
class StereoSyncThread {
  public:
    // `inbox_capacity`: frames queued per side between a capture thread and the sync
    // thread before the oldest is dropped (counted as overflow).
    explicit StereoSyncThread(SyncSettings settings, std::size_t inbox_capacity = 4);
    ~StereoSyncThread();

    StereoSyncThread(const StereoSyncThread&) = delete;
    StereoSyncThread& operator=(const StereoSyncThread&) = delete;

    // Starts the sync thread, which pushes pairs into `ring` (borrowed until stop()).
    // Throws std::system_error when the thread cannot start.
    void start(PairRing& ring);
    // Stops and joins the sync thread; frames still waiting are released. Idempotent.
    void stop() noexcept;

    // Where a camera delivers (V4l2Camera::start(inbox(side), &wake())).
    CapturedRing& inbox(StereoSide side) noexcept { return inbox_[static_cast<int>(side)]; }
    std::atomic<uint32_t>& wake() noexcept { return epoch_; }

    // Hands a frame over as a camera would: push into the side's inbox and wake the sync
    // thread. Never blocks, never allocates.
    void offer(StereoSide side, FrameHandle frame);

    // The sync's counters and statistics as of its last change, plus the frames dropped
    // from full inboxes (overflow). Any thread.
    SyncStats stats() const noexcept;

  private:
    void run() noexcept;
    void publishStats() noexcept;

    StereoSync sync_; // sync thread only (while running)
    CapturedRing inbox_[2];
    std::atomic<uint32_t> epoch_{0}; // bumped by every push and by stop(); waited on
    std::atomic<bool> stop_requested_{false};
    PairRing* ring_ = nullptr;
    std::thread thread_;

    // The stats published by the sync thread: a seqlock (odd while writing), so that a
    // reader gets a consistent copy without blocking the writer.
    mutable std::atomic<uint32_t> stats_seq_{0};
    std::atomic<uint64_t> published_[16]{};
};

} // namespace stereod
