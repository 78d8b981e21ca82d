#pragma once
// The two-camera frame source: two V4L2 cameras (capture/v4l2_camera.hpp), each with its
// own capture thread, paired by capture time in a StereoSyncThread
// (capture/stereo_sync.hpp) that pushes the pairs into the PairRing.
//
// Frame path: capture thread -> the camera's inbox (SPSC, drop-oldest) -> sync thread ->
// PairRing (drop-oldest) -> worker. No lock and no allocation on it; a frame's buffer goes
// back to its camera when the pair holding it is released (or dropped anywhere on the way).
//
// Faults: a camera that vanishes, stalls or fails is reopened by the camera itself, with
// backoff. Meanwhile the source reports state Failed (or Stalled) with the camera and its
// reason ("left camera /dev/...: ..."), which the service turns into source_down readings;
// once the camera streams again, pairs resume (stereo sync never pairs across the gap).
//
// Both cameras get the same settings apart from their device; what each one accepted is
// compared, and a control that differs between them is reported in status().warnings.
//
// Thread-safety: as FrameSource: start()/stop() from one controlling thread; status() and
// frameSize() from any thread.
//
// Lifetime: every pair delivered must be released before the source is destroyed (the
// frames live in the cameras' buffers): stop(), drain or destroy the ring, then destroy.

#include <cstddef>
#include <mutex>
#include <string>
#include <vector>

#include "capture/frame_source.hpp"
#include "capture/stereo_sync.hpp"
#include "capture/v4l2_camera.hpp"

namespace stereod {

struct StereoCameraOptions {
    CameraSettings left; // everything but `device` should equal right's
    CameraSettings right;
    SyncSettings sync;
    std::size_t inbox_capacity = 4; // frames queued per camera before the sync thread
};

// V4L2 buffers a camera needs so that it never waits for one: those the driver keeps
// queued, those in the inbox, waiting in the sync, in a ring of `ring_capacity` pairs,
// and the pair the worker holds.
int cameraBufferCount(std::size_t ring_capacity, const SyncSettings& sync,
                      std::size_t inbox_capacity) noexcept;

// Compares what two cameras of a rig accepted: one sentence per control whose value
// differs between them, or that one of them refused ("gain: left 16, right 32").
std::vector<std::string> controlMismatches(const V4l2CameraStatus& left,
                                           const V4l2CameraStatus& right);

class StereoCameraSource final : public FrameSource {
  public:
    // Nothing is opened yet. Throws std::invalid_argument for bad sync settings.
    explicit StereoCameraSource(StereoCameraOptions options);
    ~StereoCameraSource() override;

    StereoCameraSource(const StereoCameraSource&) = delete;
    StereoCameraSource& operator=(const StereoCameraSource&) = delete;

    // Opens both cameras and starts streaming. Returns 0, or the negative errno of the
    // first camera that cannot start (nothing left running); status().last_error then
    // names the camera and the reason (what the device offers, for a refused format).
    int start(PairRing& ring) override;
    void stop() noexcept override;
    SourceStatus status() const override;
    // The configured size of each camera's frames.
    cv::Size frameSize() const override;

    // Either camera's full status, for tests and `status` details.
    V4l2CameraStatus cameraStatus(StereoSide side) const;

  private:
    const StereoCameraOptions options_;
    StereoSyncThread sync_;
    V4l2Camera left_;
    V4l2Camera right_;
    bool running_ = false; // controlling thread only
    mutable std::mutex error_mutex_;
    std::string start_error_; // why start() failed; guarded by error_mutex_
};

} // namespace stereod
