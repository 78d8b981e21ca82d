#pragma once
// One V4L2 camera: settings, the capture thread, and what it tells `status`.
//
// A V4l2Camera opens its device through libv4l2, negotiates the format, applies the
// controls, streams with mmap buffers and hands every frame to its consumer through an
// SpscRing<CapturedFrame> the consumer owns. GREY frames are zero-copy (the frame is the
// kernel buffer, queued again when its last holder lets go); YUYV and MJPEG frames are
// turned into grayscale in a FramePool buffer and the kernel buffer is queued again at
// once. A camera that vanishes (ENODEV, EIO) or stalls is reopened with backoff.
//
// Interface changes after the first version are additive only and listed here.

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/types.hpp>

#include "capture/frame.hpp"
#include "capture/frame_source.hpp"
#include "capture/spsc_ring.hpp"

namespace stereod {

// Pixel format asked of the device. `Auto` takes the first the device offers at the
// asked size and rate, in the order GREY > YUYV > MJPEG: GREY needs no work and no copy,
// YUYV only a luma copy, MJPEG a decode (and JPEG artefacts hurt matching).
enum class PixelFormatChoice { Auto, Grey, Yuyv, Mjpeg };

const char* toString(PixelFormatChoice format) noexcept;
// "auto", "grey", "yuyv", "mjpeg" (case-insensitive); nothing for anything else.
std::optional<PixelFormatChoice> parsePixelFormatChoice(const std::string& text) noexcept;

// V4L2_CID_POWER_LINE_FREQUENCY menu (anti-flicker under mains lighting).
enum class PowerLineFrequency { Disabled = 0, Hz50 = 1, Hz60 = 2, Auto = 3 };

// Controls applied alike to every camera of a rig. An unset field leaves the device's
// value alone. Two cameras with different exposure or gain ruin matching, so what each
// camera actually accepted is read back and reported (V4l2CameraStatus::controls).
struct CameraControls {
    std::optional<bool> auto_exposure;      // V4L2_CID_EXPOSURE_AUTO (true: auto, false: manual)
    std::optional<int32_t> exposure_us;     // V4L2_CID_EXPOSURE_ABSOLUTE (device unit: 100 us)
    std::optional<int32_t> gain;            // V4L2_CID_GAIN, device units
    std::optional<bool> auto_white_balance; // V4L2_CID_AUTO_WHITE_BALANCE
    std::optional<int32_t> white_balance_k; // V4L2_CID_WHITE_BALANCE_TEMPERATURE, kelvin
    std::optional<PowerLineFrequency> power_line; // V4L2_CID_POWER_LINE_FREQUENCY
};

struct CameraSettings {
    std::string device; // /dev/videoN or a /dev/v4l/by-id/... link;
                        // reopened by this same path
    PixelFormatChoice format = PixelFormatChoice::Auto;
    int width = 640; // px; the device must offer exactly this size
    int height = 480;
    double fps = 30.0; // asked frame rate (S_PARM); the driver's
                       // actual rate is reported
    CameraControls controls;
    // Manual exposure with auto exposure off: controls.exposure_us when set, otherwise
    // the exposure the device has at open time (frozen there).
    bool lock_exposure = false;
    // V4L2 mmap buffers asked for (REQBUFS), >= 2. GREY frames are the buffers
    // themselves: frames waiting in the consumer's ring or held by it count against these,
    // so keep ring capacity + frames held below this (else: pool exhausted, frames lost).
    int buffer_count = 6;
    // No frame for this long (while buffers are queued) means Stalled; 0: five frame
    // periods at the negotiated rate, at least 200 ms.
    int stall_timeout_ms = 0;
    int reopen_min_ms = 100;  // first reopen delay after a failure
    int reopen_max_ms = 2000; // the delay doubles up to this
};

// What the device settled on after negotiation.
struct NegotiatedFormat {
    uint32_t fourcc = 0;     // V4L2_PIX_FMT_GREY / _YUYV / _MJPEG
    std::string format_name; // "GREY", "YUYV", "MJPG"
    int width = 0;
    int height = 0;
    uint32_t bytes_per_line = 0; // 0 for compressed formats
    uint32_t size_image = 0;     // bytes of one buffer as the driver sized it
    double fps = 0.0;            // the rate the driver set (from S_PARM)
    std::string reason;          // why this format (auto choice, or as asked)
};

// One control after apply and read-back.
struct ControlReading {
    std::string name;            // "exposure_us", "gain", ...
    uint32_t id = 0;             // V4L2_CID_*
    bool present = false;        // the device has it
    bool requested = false;      // the settings asked for a value
    int64_t requested_value = 0; // in the unit of `name`
    int64_t actual_value = 0;    // read back from the device, same unit
    std::string error;           // why the request was not met; empty if met
};

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

// A frame from one camera of a rig. The frame carries stamp_ns (CLOCK_MONOTONIC: the
// kernel's stamp when the driver gives a monotonic one, else the dequeue time),
// source_stamp_ns (the driver's raw stamp, 0 when it has none) and sequence (per camera,
// increasing across reopens). Destroying the handle gives the buffer back.
struct CapturedFrame {
    FrameHandle frame;
    uint32_t camera_index = 0; // the index given to the camera's constructor
};

using CapturedRing = SpscRing<CapturedFrame>;

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
