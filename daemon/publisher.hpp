#pragma once
// The hand-off of results from the worker to the I/O thread: a lock-free triple buffer of
// preallocated slots, and an eventfd that wakes the I/O thread's epoll when a new result
// is there.
//
// Thread contract:
//  - exactly one writer thread (the worker) calls writeSlot() and publish(): it fills the
//    back slot, which no other thread touches, then publish() swaps it with the middle
//    slot and marks that one fresh. The writer never waits for the reader: a result the
//    reader has not taken yet is overwritten by the next one (the reader only ever wants
//    the newest);
//  - exactly one reader thread (the I/O thread) calls latest() and clearEvent(): latest()
//    takes the middle slot when it is fresh, swapping in its own front slot, and returns
//    the front slot, which stays untouched by the writer until the reader's next
//    latest() call. So the reader always sees a complete result, the newest published or
//    newer, never one being written;
//  - eventFd(), publishedCount(), wantRawUntil() and rawWanted() are safe from any thread.
// Memory ordering: the swaps are acq_rel exchanges of one atomic byte, so the writes to a
// slot happen-before the reads of whoever takes that slot next.

#include <array>
#include <atomic>
#include <cstdarg>
#include <cstdint>
#include <string_view>

#include <opencv2/core/mat.hpp>

#include "base/clock.hpp"
#include "base/unique_fd.hpp"
#include "pipeline/stereo_processor.hpp"
#include "pipeline/zones.hpp"

namespace stereod {

// A short text kept in place, so that the worker can set it without allocating. Longer
// texts are cut (on a byte boundary; the JSON writer repairs a cut UTF-8 sequence).
class FixedText {
  public:
    static constexpr std::size_t kCapacity = 255;

    void clear() noexcept { size_ = 0; }
    void assign(std::string_view text) noexcept;
    void format(const char* format, ...) noexcept __attribute__((format(printf, 2, 3)));
    std::string_view view() const noexcept { return {text_.data(), size_}; }
    bool empty() const noexcept { return size_ == 0; }

  private:
    std::array<char, kCapacity + 1> text_{};
    std::size_t size_ = 0;
};

// The worker's counters and rolling means, as of the frame they travel with.
struct PipelineStats {
    uint64_t frames = 0;          // pairs processed since start
    uint64_t bad_frames = 0;      // pairs that gave a bad_frame reading
    uint64_t out_of_sync = 0;     // pairs whose skew exceeded source.max_skew_ms
    double fps = 0.0;             // processed pairs per second over the last frames
    StageTimings stage_mean_ms;   // mean of each stage over the last frames, ms
    double zones_mean_ms = 0.0;   // mean of the keep-out zones' stage (0 without zones)
    double publish_mean_ms = 0.0; // mean of the publish stage (depth to mm, hand-off)
    // From a pair's capture stamp to its result's publication, over the last pairs, ms.
    double latency_p50_ms = 0.0;
    double latency_p99_ms = 0.0;
    DisparityRange range;            // the disparity range in force
    double max_output_depth_m = 0.0; // StereoProcessor::maxOutputDepth(), metres
    // StereoProcessor::matcherName() ("census-sgm (planar)"), kept in place: copied with
    // the stats into every result without allocating.
    FixedText matcher;
};

// A pair as captured, before rectification: copies of the source's frames, made only
// while raw frames are wanted (Publisher::wantRawUntil()). The buffers keep their size
// from frame to frame, so copying allocates only for the first frames of a size.
struct RawPair {
    bool present = false; // false: the pair was not copied (nobody asked for raw frames)
    cv::Mat left;         // CV_8UC1, continuous
    cv::Mat right;        // CV_8UC1, continuous
    // The cameras' colour as captured (CV_8UC3, BGR, continuous), each empty when that
    // camera kept none (Frame::colour).
    cv::Mat left_colour;
    cv::Mat right_colour;
    int64_t left_stamp_ns = 0; // each camera's own capture stamp (Frame::source_stamp_ns)
    int64_t right_stamp_ns = 0;
};

// One processed pair, as the I/O thread needs it. Every buffer keeps its capacity from
// frame to frame, so a slot allocates only for the first frames of a size.
struct PublishedFrame {
    DepthResult result; // the chain's output; result.reading is the reading
    cv::Mat depth_mm;   // CV_16UC1, millimetres, 0 = invalid (u16_mm payload)
    // Whether depth_mm holds this pair's depth. False when it was cleared (a bad frame, a
    // pair out of sync: depth the reading refuses to trust) or never made (uncalibrated).
    // A reading without a distance for want of data in the region (too few valid pixels,
    // nothing in range) keeps its depth: the rest of the picture is good.
    bool depth_valid = false;
    int64_t skew_ns = 0;      // right minus left capture time of the pair
    uint64_t sequence = 0;    // set by publish(): 1 for the first result, then +1
    int64_t published_ns = 0; // CLOCK_MONOTONIC when published, set by publish()
    // CLOCK_REALTIME minus CLOCK_MONOTONIC when published, set by publish(): the one
    // conversion of this pair's stamps to the wall clock (realtimeNs()).
    int64_t realtime_offset_ns = 0;
    // What made the pair a bad frame (its sizes, the error), for the reason's message;
    // empty otherwise. The reading's verdict is in result.facts / result.reading.
    FixedText reason_message;
    PipelineStats stats;
    RawPair raw; // the pair as captured, when raw frames were wanted
    // The keep-out zones of this pair (empty when none are configured); each keeps its
    // name's buffer from frame to frame.
    std::vector<ZoneReading> zones;
    CameraPose camera_pose; // robot.camera_pose in force for this pair

    // A CLOCK_MONOTONIC stamp of this pair (result.stamp_ns, or its right frame's) as the
    // same instant on CLOCK_REALTIME, ns since the Unix epoch: the time base of readings'
    // stamp_realtime_ns, the live view, bags and anything a robot merges with its other
    // data (ROS's header.stamp). The one place such a stamp is made.
    int64_t realtimeNs(int64_t monotonic_ns) const noexcept
    {
        return saturatingAddNs(monotonic_ns, realtime_offset_ns);
    }
};

class Publisher {
  public:
    // Creates the eventfd (EFD_NONBLOCK | EFD_CLOEXEC). Throws std::system_error when it
    // cannot.
    Publisher();
    ~Publisher();

    Publisher(const Publisher&) = delete;
    Publisher& operator=(const Publisher&) = delete;

    // Writer: the slot to fill next. Its previous content is an older result (or
    // nothing); the writer owns it until publish().
    PublishedFrame& writeSlot() noexcept { return slots_[back_]; }

    // Writer: makes the filled slot the newest result and wakes the reader. Never blocks.
    void publish() noexcept;

    // Reader: the newest result, or nullptr before the first publish(). The returned slot
    // stays valid and unchanged until the reader calls latest() again.
    const PublishedFrame* latest() noexcept;

    // Reader: consumes the eventfd's counter after it woke epoll.
    void clearEvent() noexcept;

    // Readable (EPOLLIN) after every publish() until clearEvent().
    int eventFd() const noexcept { return event_fd_.get(); }

    // Any thread (the I/O thread): someone wants raw frames (a raw snapshot, a raw
    // subscriber) until `deadline_ns` (CLOCK_MONOTONIC); a later deadline extends it.
    void wantRawUntil(int64_t deadline_ns) noexcept;

    // Writer: whether to copy the pair in hand into the slot's RawPair.
    bool rawWanted(int64_t now_ns) const noexcept
    {
        return now_ns < raw_wanted_until_ns_.load(std::memory_order_relaxed);
    }

    // How many results were published so far; any thread.
    uint64_t publishedCount() const noexcept { return published_.load(std::memory_order_acquire); }

  private:
    static constexpr uint8_t kIndexMask = 0x3;
    static constexpr uint8_t kFresh = 0x4; // the middle slot holds a result not taken yet

    std::array<PublishedFrame, 3> slots_;
    uint8_t back_ = 0;               // writer's slot
    uint8_t front_ = 1;              // reader's slot
    std::atomic<uint8_t> middle_{2}; // index of the middle slot | kFresh
    std::atomic<uint64_t> published_{0};
    std::atomic<int64_t> raw_wanted_until_ns_{0};
    UniqueFd event_fd_;
};

} // namespace stereod
