#pragma once
// One V4L2 camera: settings, the capture thread, and what it tells `status`.
//
// A V4l2Camera opens its device through libv4l2, negotiates the format, applies the
// controls, streams with mmap buffers and hands every frame to its consumer through an
// SpscRing<CapturedFrame> the consumer owns. GREY frames are zero-copy (the frame is the
// kernel buffer, queued again when its last holder lets go); YUYV, MJPEG, RGB24 and BGR24
// frames are turned into grayscale in a FramePool buffer (and, with
// CameraSettings::keep_colour, into BGR colour beside it: Frame::colour) and the kernel
// buffer is queued again at once. A camera that vanishes (ENODEV, EIO) or stalls is
// reopened with backoff.
//
// Interface changes after the first version are additive only and listed here.

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/types.hpp>

#include "capture/camera_settings.hpp"
#include "capture/captured_frame.hpp"
#include "capture/frame.hpp"
#include "capture/frame_source.hpp"
#include "capture/spsc_ring.hpp"

namespace stereod {

// Detailed state of one camera, for `status` and for tests.
struct V4l2CameraStatus {
    CameraStatus camera;                  // state, last error, fps and counters
    std::string device;                   // the path it was opened by
    NegotiatedFormat format;              // valid once the camera ran once
    std::vector<ControlReading> controls; // as applied at the latest open
    bool kernel_monotonic_stamps = false; // false: stamped at dequeue (said once in the log)
    uint64_t pool_exhausted = 0;          // frames lost because every buffer was held
    uint64_t reopens = 0;                 // successful reopens after a failure
    uint64_t sequence_gaps = 0;           // frames the driver skipped (sequence gaps)
};

// Thread-safety: start()/stop() from one controlling thread; status(), frameSize() and
// the counters from any thread. The camera runs one capture thread that is the single
// producer of the ring; frames may be released on any thread. The frame path takes no
// lock and allocates nothing; a state change (open, failure, reopen: rare) takes a
// mutex that only status() also takes.
//
// Lifetime: every frame handed out must be released before the camera is destroyed
// (the frame points into the camera's buffers, like a FramePool's).
class V4l2Camera {
  public:
    // `index` is copied into every CapturedFrame; `name` ("left", "right") names the
    // camera in status and logs.
    V4l2Camera(CameraSettings settings, uint32_t index, std::string name);
    ~V4l2Camera();

    V4l2Camera(const V4l2Camera&) = delete;
    V4l2Camera& operator=(const V4l2Camera&) = delete;

    // Opens and negotiates synchronously, then starts the capture thread delivering into
    // `ring` (borrowed until stop() returns). Returns 0, or a negative errno with the
    // reason in status().camera.last_error: -ENOENT/-ENODEV when the device is absent,
    // -EINVAL when the device cannot deliver what the settings ask (the message names
    // what it offers), -ENOTTY when it is not a V4L2 capture device. When `wake` is
    // given, each push also increments it and calls notify_all(), so one consumer can
    // wait on several cameras' rings at once.
    int start(CapturedRing& ring, std::atomic<uint32_t>* wake = nullptr);

    // Stops streaming and joins the capture thread. Idempotent; never throws. Frames
    // still held stay valid until released (and the camera lives).
    void stop() noexcept;

    // Any thread: a consistent snapshot.
    V4l2CameraStatus status() const;

    // The settings' size: frames are always exactly this size (negotiation refuses
    // anything else).
    cv::Size frameSize() const noexcept;

    const CameraSettings& settings() const noexcept { return settings_; }
    uint32_t index() const noexcept { return index_; }

  private:
    class Impl;

    CameraSettings settings_;
    uint32_t index_ = 0;
    std::unique_ptr<Impl> impl_;
};

} // namespace stereod
