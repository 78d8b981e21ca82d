#pragma once
// The side-by-side frame source: one V4L2 device whose every frame holds the left camera's
// image in its left half and the right camera's in its right half (a common form of USB
// stereo camera: both sensors share one clock and one shutter, so there is nothing to
// sync).
//
// Frame path: the camera's capture thread -> its inbox (SPSC, drop-oldest) -> split thread
// -> PairRing (drop-oldest) -> worker. The split copies nothing: the two halves are views
// (cv::Mat ROIs) into the camera's frame (its grey image, and its colour when the camera
// keeps it), which goes back to the camera when both halves are released. No lock and no allocation
// on the frame path.
//
// Faults: as StereoCameraSource, for its one camera (reopened by the camera itself with
// backoff; the source reports Failed/Stalled with the reason meanwhile).
//
// Thread-safety: as FrameSource: start()/stop() from one controlling thread; status() and
// frameSize() from any thread.
//
// Lifetime: every pair delivered must be released before the source is destroyed.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "capture/frame_source.hpp"
#include "capture/v4l2_camera.hpp"

namespace stereod {

// Splits frames into left and right halves without copying. Each split takes one of a
// fixed number of slots until both halves are released; the whole frame is released then
// (on the thread that lets go of the last half).
//
// Thread-safety: split() from one thread at a time; halves may be released on any thread.
// Lock-free and allocation-free.
class FrameSplitter final : public FrameRecycler {
  public:
    // With `right_colour`, the right half keeps the frame's colour too; the left half
    // always does when the frame has it.
    explicit FrameSplitter(std::size_t slots, bool right_colour = false);
    ~FrameSplitter() override;

    FrameSplitter(const FrameSplitter&) = delete;
    FrameSplitter& operator=(const FrameSplitter&) = delete;

    // The pair of halves of `whole` (width split at width / 2; stamps and sequence copied
    // to both), or false when every slot is held (`whole` is then released).
    bool split(FrameHandle whole, StereoPair& pair) noexcept;

    void recycle(Frame* half) noexcept override;

    std::size_t inUse() const noexcept;

  private:
    struct Slot {
        FrameHandle whole;
        Frame halves[2];
        std::atomic<int> holders{0};
        std::atomic<bool> in_use{false};
    };
    std::unique_ptr<Slot[]> slots_;
    std::size_t count_;
    bool right_colour_;
};

struct SideBySideOptions {
    CameraSettings camera;          // width/height: the whole frame (both halves)
    bool right_colour = false;      // with camera.keep_colour: the right half keeps it too
    std::size_t inbox_capacity = 4; // frames queued before the split thread
    std::size_t ring_capacity = 4;  // of the PairRing it will deliver into (sizes slots)
};

class SideBySideSource final : public FrameSource {
  public:
    // Nothing is opened yet. Throws std::invalid_argument for an odd frame width.
    explicit SideBySideSource(SideBySideOptions options);
    ~SideBySideSource() override;

    SideBySideSource(const SideBySideSource&) = delete;
    SideBySideSource& operator=(const SideBySideSource&) = delete;

    // Opens the camera and starts streaming. Returns 0, or the camera's negative errno
    // with the reason in status().last_error.
    int start(PairRing& ring) override;
    void stop() noexcept override;
    SourceStatus status() const override;
    // One half: (width / 2) x height.
    cv::Size frameSize() const override;

    V4l2CameraStatus cameraStatus() const { return camera_.status(); }

  private:
    void run() noexcept;

    const SideBySideOptions options_;
    FrameSplitter splitter_;
    CapturedRing inbox_;
    std::atomic<uint32_t> wake_{0};
    std::atomic<bool> stop_requested_{false};
    V4l2Camera camera_;
    PairRing* ring_ = nullptr; // borrowed between start() and stop()
    std::thread thread_;

    std::atomic<uint64_t> pairs_{0};
    std::atomic<uint64_t> split_dropped_{0}; // frames dropped for want of a free slot
    mutable std::mutex error_mutex_;
    std::string start_error_; // guarded by error_mutex_
};

} // namespace stereod
