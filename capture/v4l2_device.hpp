#pragma once
// A V4L2 capture device opened through libv4l2: capabilities, format enumeration and
// negotiation, controls, mmap streaming. The capture edge of the project: calls return 0
// or a negative errno and leave the reason (what, which device, errno text) in
// errorText(); the caller adds its own context and logs.
//
// The device is opened with open() and handed to libv4l2 with v4l2_fd_open(fd,
// V4L2_DISABLE_CONVERSION): libv4l2's format emulation would list formats the camera
// does not have (RGB24, YUV420, ... converted in software into libv4l2's own buffers)
// and, when such a format is chosen, decode every frame with a copy. We only ask for
// GREY, YUYV, MJPEG and packed RGB24/BGR24 the camera itself offers, which we handle
// ourselves (zero-copy, luma plane, a JPEG decode, a grey conversion), so the raw format
// and the driver's own buffers are what we want.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <linux/videodev2.h>

#include "capture/camera_settings.hpp"
#include "capture/format_choice.hpp"

namespace stereod {

struct DeviceIdentity {
    std::string driver;       // v4l2_capability.driver ("uvcvideo")
    std::string card;         // the camera's name
    std::string bus_info;     // "usb-0000:00:14.0-3"
    uint32_t device_caps = 0; // V4L2_CAP_* of this node
};

// A buffer dequeued from the driver.
struct DequeuedBuffer {
    uint32_t index = 0;
    uint32_t bytes_used = 0;
    uint32_t flags = 0;       // V4L2_BUF_FLAG_*
    uint32_t sequence = 0;    // the driver's frame counter
    int64_t timestamp_ns = 0; // the driver's stamp; its clock is in `flags`
};

struct MappedBuffer {
    uint8_t* data = nullptr;
    std::size_t length = 0; // bytes mapped
};

// Thread-bound: one thread at a time uses a device (the capture thread once streaming).
// Move-only; the destructor stops streaming, unmaps and closes.
class V4l2Device {
  public:
    V4l2Device() = default;
    ~V4l2Device();
    V4l2Device(V4l2Device&& other) noexcept;
    V4l2Device& operator=(V4l2Device&& other) noexcept;
    V4l2Device(const V4l2Device&) = delete;
    V4l2Device& operator=(const V4l2Device&) = delete;

    // Opens `path` and checks that it is a V4L2 video capture device with streaming I/O
    // (-ENOTTY if not a V4L2 device, -ENODEV if it cannot capture or stream).
    int open(const std::string& path);
    void close() noexcept;
    bool isOpen() const noexcept { return fd_ >= 0; }
    int fd() const noexcept { return fd_; }
    const std::string& path() const noexcept { return path_; }
    const DeviceIdentity& identity() const noexcept { return identity_; }

    // Native formats with their sizes and rates (ENUM_FMT, ENUM_FRAMESIZES,
    // ENUM_FRAMEINTERVALS). Returns 0 or a negative errno.
    int enumerateFormats(std::vector<FormatDescription>& formats);

    // Chooses the format the settings ask for (`auto`: GREY > YUYV > MJPEG at the asked
    // size and rate), sets it (S_FMT) and the frame interval (S_PARM), and fills `out`
    // with what the driver actually set. -EINVAL when the device cannot deliver what is
    // asked: errorText() then names what it offers.
    int negotiate(const CameraSettings& settings, NegotiatedFormat& out);

    // Applies the controls (and lock_exposure) and reads every known control back. A
    // control the device lacks or refuses is reported in its reading, not as an error.
    std::vector<ControlReading> applyControls(const CameraControls& controls, bool lock_exposure);

    // Reads back the controls the project knows (present ones only).
    std::vector<ControlReading> readControls();

    // REQBUFS + QUERYBUF + mmap of `count` buffers (the driver may give more or fewer;
    // fewer than 2 is an error). Returns 0 or a negative errno.
    int allocateBuffers(int count);
    // Unmaps and frees the buffers (REQBUFS 0). Streaming must be off.
    void releaseBuffers() noexcept;
    std::size_t bufferCount() const noexcept { return buffers_.size(); }
    const MappedBuffer& buffer(std::size_t index) const noexcept { return buffers_[index]; }

    int queueBuffer(uint32_t index);
    // -EAGAIN when no buffer is ready (the fd is non-blocking).
    int dequeueBuffer(DequeuedBuffer& out);
    int streamOn();
    int streamOff() noexcept;

    // Why the last failing call failed: "VIDIOC_S_FMT on /dev/video0: Invalid argument".
    const std::string& errorText() const noexcept { return error_; }

  private:
    int fail(const char* what, int error_number);
    int xioctl(unsigned long request, void* arg);
    int queryControl(uint32_t id, v4l2_queryctrl& query);
    ControlReading setControl(const char* name, uint32_t id, int64_t value, int64_t unit);
    ControlReading readControl(const char* name, uint32_t id, int64_t unit);

    int fd_ = -1;
    bool streaming_ = false;
    std::string path_;
    DeviceIdentity identity_;
    std::vector<MappedBuffer> buffers_;
    std::string error_;
};

} // namespace stereod
