#include "capture/stereo_sync.hpp"

#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

namespace stereod {

namespace {

constexpr int kLeft = 0;
constexpr int kRight = 1;
constexpr int64_t kNone = std::numeric_limits<int64_t>::min();

int64_t absNs(int64_t value) noexcept
{
    return value < 0 ? -value : value;
}

double toMs(int64_t ns) noexcept
{
    return static_cast<double>(ns) / 1e6;
}

} // namespace

void addSyncFigures(const SyncStats& sync, SourceStatus& out) noexcept
{
    out.pairs = sync.pairs;
    out.unpaired_dropped = sync.unpaired();
    out.skew_mean_ms = sync.skew_mean_ms;
    out.skew_p99_ms = sync.skew_p99_ms;
    out.skew_max_ms = sync.skew_max_ms;
    out.clock_offset_detected = sync.offset_detected;
    out.clock_offset_ms = sync.offset_estimate_ms;
}

void addClockOffsetWarning(const SyncStats& sync, int64_t max_skew_ns, const char* apart,
                           const char* samples, const char* cause, SourceStatus& out)
{
    if (!sync.offset_detected)
        return;
    char text[256];
    std::snprintf(text, sizeof text,
                  "%s are %.2f ms apart (right minus left, over %zu %s; max_skew %.2f ms): %s",
                  apart, sync.offset_estimate_ms, sync.offset_samples, samples,
                  static_cast<double>(max_skew_ns) / 1e6, cause);
    out.warnings.push_back(text);
}

void StereoSync::Queue::push(FrameHandle frame)
{
    frames[(head + size) % kMaxPending] = std::move(frame);
    ++size;
}

FrameHandle StereoSync::Queue::pop()
{
    FrameHandle frame = std::move(frames[head]);
    head = (head + 1) % kMaxPending;
    --size;
    return frame;
}

StereoSync::StereoSync(SyncSettings settings) : settings_(settings)
{
    if (settings_.max_skew_ns <= 0)
        throw std::invalid_argument("stereo sync: max_skew_ns must be positive, got " +
                                    std::to_string(settings_.max_skew_ns));
    if (settings_.max_pending < 1 || settings_.max_pending > kMaxPending)
        throw std::invalid_argument("stereo sync: max_pending must be 1 to " +
                                    std::to_string(kMaxPending) + ", got " +
                                    std::to_string(settings_.max_pending));
    for (int side = 0; side < 2; ++side) {
        newest_seen_ns_[side] = kNone;
        newest_done_ns_[side] = kNone;
    }
}

void StereoSync::add(StereoSide which, FrameHandle frame)
{
    if (!frame)
        return;
    const int side = static_cast<int>(which);
    const int other = 1 - side;
    const int64_t stamp_ns = frame->stamp_ns;

    // Rule 1.
    if (newest_seen_ns_[side] != kNone && stamp_ns <= newest_seen_ns_[side]) {
        ++drops_[side].out_of_order;
        return;
    }
    newest_seen_ns_[side] = stamp_ns;

    // Rule 2. Its neighbours in the other stream: the newest given up frame, and the
    // oldest waiting one if any.
    if (newest_done_ns_[other] != kNone &&
        stamp_ns < newest_done_ns_[other] - settings_.max_skew_ns) {
        noteNeighbourDistance(side, stamp_ns);
        newest_done_ns_[side] = stamp_ns;
        ++drops_[side].stale;
        return;
    }

    // Rule 4: room for the new frame.
    Queue& queue = queues_[side];
    if (queue.size == settings_.max_pending)
        dropFront(side, &SideDrops::overflow);
    queue.push(std::move(frame));
}

std::optional<StereoPair> StereoSync::takePair()
{
    Queue& left = queues_[kLeft];
    Queue& right = queues_[kRight];
    while (left.size > 0 && right.size > 0) {
        const int64_t l_ns = left.at(0).stamp_ns;
        const int64_t r_ns = right.at(0).stamp_ns;
        const int64_t skew_ns = r_ns - l_ns;
        if (skew_ns > settings_.max_skew_ns) {
            dropFront(kLeft, &SideDrops::stale);
            continue;
        }
        if (-skew_ns > settings_.max_skew_ns) {
            dropFront(kRight, &SideDrops::stale);
            continue;
        }
        // A closer partner queued behind either front displaces that front.
        if (left.size > 1 && absNs(r_ns - left.at(1).stamp_ns) < absNs(skew_ns)) {
            dropFront(kLeft, &SideDrops::stale);
            continue;
        }
        if (right.size > 1 && absNs(right.at(1).stamp_ns - l_ns) < absNs(skew_ns)) {
            dropFront(kRight, &SideDrops::stale);
            continue;
        }

        noteDistance(skew_ns);
        skew_.add(skew_ns);
        newest_done_ns_[kLeft] = l_ns;
        newest_done_ns_[kRight] = r_ns;

        StereoPair pair;
        pair.left = left.pop();
        pair.right = right.pop();
        pair.index = pairs_++;
        return pair;
    }
    return std::nullopt;
}

void StereoSync::clear()
{
    for (int side = 0; side < 2; ++side) {
        while (queues_[side].size > 0) {
            queues_[side].pop();
            ++drops_[side].stale;
        }
        newest_seen_ns_[side] = kNone;
        newest_done_ns_[side] = kNone;
    }
}

void StereoSync::dropFront(int side, uint64_t SideDrops::*reason)
{
    const int64_t stamp_ns = queues_[side].at(0).stamp_ns;
    if (reason == &SideDrops::stale)
        noteNeighbourDistance(side, stamp_ns);
    newest_done_ns_[side] = stamp_ns;
    ++(drops_[side].*reason);
    queues_[side].pop();
}

void StereoSync::noteNeighbourDistance(int side, int64_t stamp_ns)
{
    const int other = 1 - side;
    int64_t best_ns = kNone;
    const auto consider = [&](int64_t other_ns) {
        if (other_ns == kNone)
            return;
        if (best_ns == kNone || absNs(other_ns - stamp_ns) < absNs(best_ns - stamp_ns))
            best_ns = other_ns;
    };
    consider(newest_done_ns_[other]);
    if (queues_[other].size > 0)
        consider(queues_[other].at(0).stamp_ns);
    // Without a frame of the other stream on each side of this one, the nearest
    // neighbour is unknown (the other camera may be silent); no distance then.
    const bool before = newest_done_ns_[other] != kNone && newest_done_ns_[other] <= stamp_ns;
    const bool after = queues_[other].size > 0 && queues_[other].at(0).stamp_ns >= stamp_ns;
    if (best_ns == kNone || !before || !after)
        return;
    noteDistance(side == kRight ? stamp_ns - best_ns : best_ns - stamp_ns);
}

void StereoSync::noteDistance(int64_t right_minus_left_ns) noexcept
{
    distance_ns_[distance_next_] = right_minus_left_ns;
    distance_next_ = (distance_next_ + 1) % kOffsetWindow;
    distance_count_ = std::min(distance_count_ + 1, kOffsetWindow);
}

SyncStats StereoSync::stats() const noexcept
{
    SyncStats out;
    out.pairs = pairs_;
    out.drops[kLeft] = drops_[kLeft];
    out.drops[kRight] = drops_[kRight];

    const RollingSummary skew = skew_.summary();
    out.skew_mean_ms = skew.mean_abs_ns / 1e6;
    out.skew_signed_mean_ms = skew.mean_ns / 1e6;
    out.skew_max_ms = toMs(skew.max_abs_ns);
    out.skew_p99_ms = toMs(skew.p99_abs_ns);

    out.offset_samples = distance_count_;
    if (distance_count_ > 0) {
        std::array<int64_t, kOffsetWindow> sorted{};
        std::copy_n(distance_ns_.begin(), distance_count_, sorted.begin());
        auto* mid = sorted.begin() + static_cast<std::ptrdiff_t>(distance_count_ / 2);
        std::nth_element(sorted.begin(), mid,
                         sorted.begin() + static_cast<std::ptrdiff_t>(distance_count_));
        const int64_t median_ns = *mid;
        std::size_t same_sign = 0;
        for (std::size_t i = 0; i < distance_count_; ++i) {
            if ((distance_ns_[i] > 0 && median_ns > 0) || (distance_ns_[i] < 0 && median_ns < 0))
                ++same_sign;
        }
        out.offset_estimate_ms = toMs(median_ns);
        // Most of them on one side, and far enough from zero to matter for pairing.
        out.offset_detected = distance_count_ >= kOffsetMinSamples &&
                              same_sign * 10 >= distance_count_ * 9 &&
                              2 * absNs(median_ns) > settings_.max_skew_ns;
    }
    return out;
}

// ---------------------------------------------------------------------------------------
// The threaded sync

namespace {

// The published fields, in the order of StereoSyncThread::published_.
enum PublishedField : std::size_t {
    kPairs,
    kLeftStale,
    kLeftOverflow,
    kLeftOutOfOrder,
    kRightStale,
    kRightOverflow,
    kRightOutOfOrder,
    kSkewMean,
    kSkewP99,
    kSkewMax,
    kSkewSignedMean,
    kOffsetDetected,
    kOffsetEstimate,
    kOffsetSamples,
    kFieldCount,
};

} // namespace

StereoSyncThread::StereoSyncThread(SyncSettings settings, std::size_t inbox_capacity)
    : sync_(settings), inbox_{CapturedRing(inbox_capacity), CapturedRing(inbox_capacity)}
{
    static_assert(kFieldCount <= sizeof(published_) / sizeof(published_[0]));
}

StereoSyncThread::~StereoSyncThread()
{
    stop();
}

void StereoSyncThread::start(PairRing& ring)
{
    if (thread_.joinable())
        return;
    ring_ = &ring;
    stop_requested_.store(false, std::memory_order_release);
    thread_ = std::thread([this] { run(); });
}

void StereoSyncThread::stop() noexcept
{
    if (!thread_.joinable())
        return;
    stop_requested_.store(true, std::memory_order_release);
    epoch_.fetch_add(1, std::memory_order_release);
    epoch_.notify_all();
    thread_.join();
    ring_ = nullptr;
    // Whatever is still waiting goes back to its camera, counted as dropped.
    for (int side = kLeft; side <= kRight; ++side) {
        while (std::optional<CapturedFrame> captured = inbox_[side].tryPop())
            sync_.add(static_cast<StereoSide>(side), std::move(captured->frame));
    }
    sync_.clear();
    publishStats();
}

void StereoSyncThread::offer(StereoSide side, FrameHandle frame)
{
    if (!frame)
        return;
    inbox_[static_cast<int>(side)].push(
        CapturedFrame{std::move(frame), static_cast<uint32_t>(side)});
    epoch_.fetch_add(1, std::memory_order_release);
    epoch_.notify_one();
}

void StereoSyncThread::run() noexcept
{
    for (;;) {
        const uint32_t seen = epoch_.load(std::memory_order_acquire);
        if (stop_requested_.load(std::memory_order_acquire))
            return;
        bool changed = false;
        // The inboxes are drained one frame of each side at a time, so that a burst on
        // one side does not overflow the sync while the other side's frames wait.
        for (;;) {
            bool took = false;
            for (int side = kLeft; side <= kRight; ++side) {
                if (std::optional<CapturedFrame> captured = inbox_[side].tryPop()) {
                    sync_.add(static_cast<StereoSide>(side), std::move(captured->frame));
                    took = true;
                }
            }
            if (!took)
                break;
            while (std::optional<StereoPair> pair = sync_.takePair())
                ring_->push(std::move(*pair));
            changed = true;
        }
        if (changed)
            publishStats();
        epoch_.wait(seen, std::memory_order_acquire);
    }
}

void StereoSyncThread::publishStats() noexcept
{
    const SyncStats stats = sync_.stats();
    const auto put = [this](std::size_t field, uint64_t value) {
        // Release: a reader that sees this value also sees the odd sequence before it.
        published_[field].store(value, std::memory_order_release);
    };
    const auto putReal = [&](std::size_t field, double value) {
        put(field, std::bit_cast<uint64_t>(value));
    };
    const uint32_t seq = stats_seq_.load(std::memory_order_relaxed);
    stats_seq_.store(seq + 1, std::memory_order_relaxed);
    put(kPairs, stats.pairs);
    put(kLeftStale, stats.drops[kLeft].stale);
    put(kLeftOverflow, stats.drops[kLeft].overflow);
    put(kLeftOutOfOrder, stats.drops[kLeft].out_of_order);
    put(kRightStale, stats.drops[kRight].stale);
    put(kRightOverflow, stats.drops[kRight].overflow);
    put(kRightOutOfOrder, stats.drops[kRight].out_of_order);
    putReal(kSkewMean, stats.skew_mean_ms);
    putReal(kSkewP99, stats.skew_p99_ms);
    putReal(kSkewMax, stats.skew_max_ms);
    putReal(kSkewSignedMean, stats.skew_signed_mean_ms);
    put(kOffsetDetected, stats.offset_detected ? 1 : 0);
    putReal(kOffsetEstimate, stats.offset_estimate_ms);
    put(kOffsetSamples, stats.offset_samples);
    stats_seq_.store(seq + 2, std::memory_order_release);
}

SyncStats StereoSyncThread::stats() const noexcept
{
    SyncStats out;
    const auto get = [this](std::size_t field) {
        // Acquire: the sequence check below cannot move before these loads.
        return published_[field].load(std::memory_order_acquire);
    };
    const auto getReal = [&](std::size_t field) { return std::bit_cast<double>(get(field)); };
    for (;;) {
        const uint32_t before = stats_seq_.load(std::memory_order_acquire);
        if ((before & 1u) != 0) {
            std::this_thread::yield();
            continue;
        }
        out.pairs = get(kPairs);
        out.drops[kLeft] = {get(kLeftStale), get(kLeftOverflow), get(kLeftOutOfOrder)};
        out.drops[kRight] = {get(kRightStale), get(kRightOverflow), get(kRightOutOfOrder)};
        out.skew_mean_ms = getReal(kSkewMean);
        out.skew_p99_ms = getReal(kSkewP99);
        out.skew_max_ms = getReal(kSkewMax);
        out.skew_signed_mean_ms = getReal(kSkewSignedMean);
        out.offset_detected = get(kOffsetDetected) != 0;
        out.offset_estimate_ms = getReal(kOffsetEstimate);
        out.offset_samples = static_cast<std::size_t>(get(kOffsetSamples));
        if (stats_seq_.load(std::memory_order_relaxed) == before)
            break;
    }
    // Frames the capture threads dropped before the sync saw them were overflow too.
    out.drops[kLeft].overflow += inbox_[kLeft].dropped();
    out.drops[kRight].overflow += inbox_[kRight].dropped();
    return out;
}

} // namespace stereod
