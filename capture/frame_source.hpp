#pragma once
// The one interface every producer of stereo pairs implements: two V4L2 cameras with
// stereo sync, one side-by-side device, the replay of a recording, and a ROS 2 camera
// driver's image topics (ros2/ros2_image_source.hpp).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/types.hpp>

#include "base/name_table.hpp"
#include "capture/frame.hpp"
#include "capture/spsc_ring.hpp"

namespace stereod {

using PairRing = SpscRing<StereoPair>;

enum class SourceState {
    Stopped,  // not started, or stopped on request
    Starting, // opening devices / files
    Running,  // delivering frames
    Stalled,  // open, but no frame for longer than expected
    Failed,   // lost (device vanished, files unreadable); may recover
    Finished, // a replay that reached its end without looping
};

// The states as status writes them.
inline constexpr NameTable<SourceState, 6> kSourceStates{{{
    {SourceState::Stopped, "stopped"},
    {SourceState::Starting, "starting"},
    {SourceState::Running, "running"},
    {SourceState::Stalled, "stalled"},
    {SourceState::Failed, "failed"},
    {SourceState::Finished, "finished"},
}}};
static_assert(kSourceStates.wellFormed());

// "stopped", "starting", ...
const char* toString(SourceState state) noexcept;

// What one camera (or one side of a recording) is doing, for `status`.
struct CameraStatus {
    std::string name; // "left", "right", or a device path
    SourceState state = SourceState::Stopped;
    std::string last_error;     // empty when none
    double fps = 0.0;           // measured delivery rate
    uint64_t frames = 0;        // frames delivered
    uint64_t dropped = 0;       // frames lost before pairing (gaps, pool exhausted)
    uint64_t bad_frames = 0;    // corrupt or unreadable frames skipped
    std::string last_bad_frame; // why the latest bad frame was skipped; empty when none
    uint64_t unpaired = 0;      // frames stereo sync dropped without a partner
};

// The pairs the skew figures of SourceStatus cover: the most recent ones.
inline constexpr std::size_t kSkewWindowPairs = 256;

struct SourceStatus {
    std::string kind; // "replay", "v4l2", "side-by-side", "ros2"
    SourceState state = SourceState::Stopped;
    std::string last_error;
    std::vector<CameraStatus> cameras;
    uint64_t pairs = 0;            // pairs delivered into the ring
    uint64_t unpaired_dropped = 0; // frames dropped for lack of a partner in time
    // |right - left| capture time over the last kSkewWindowPairs delivered pairs, in ms;
    // every source means the same window.
    double skew_mean_ms = 0.0;
    double skew_p99_ms = 0.0;
    double skew_max_ms = 0.0;
    // Stereo sync found the two cameras' frames consistently apart (capture/stereo_sync.hpp):
    // the estimate of right minus left, in ms, known modulo the frame period.
    bool clock_offset_detected = false;
    double clock_offset_ms = 0.0;
    // Conditions that do not stop the source but hurt depth, one sentence each (a control
    // the two cameras accepted differently, a clock offset, stamps taken at dequeue).
    std::vector<std::string> warnings;
};

// Thread-safety: start()/stop() from one controlling thread; status() from any thread.
// The source's own threads deliver into the ring and take no lock on the frame path.
class FrameSource {
  public:
    virtual ~FrameSource() = default;

    // Starts delivering pairs into `ring` (borrowed until stop() returns) from the
    // source's own thread(s). Returns 0, or a negative errno; the reason is then in
    // status().last_error.
    virtual int start(PairRing& ring) = 0;

    // Stops and joins the source's threads. Idempotent; never throws.
    virtual void stop() noexcept = 0;

    // A consistent snapshot for `status`.
    virtual SourceStatus status() const = 0;

    // Size of the frames this source delivers (known once constructed).
    virtual cv::Size frameSize() const = 0;

    // True for a source that waits for room in the ring rather than dropping (a lockstep
    // replay, whose every pair is meant to be processed): the worker then takes the pairs
    // oldest first. Otherwise a pair is about now: the worker takes the newest waiting and
    // drops the older ones (counted with the ring's drops), so that a reading's age stays
    // within one pair's processing and one frame interval while the worker is behind,
    // rather than growing to the ring's length in frames.
    virtual bool keepsEveryPair() const noexcept { return false; }
};

} // namespace stereod
