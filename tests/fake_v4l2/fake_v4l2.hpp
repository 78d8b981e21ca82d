#pragma once
// A userspace fake V4L2 capture device for tests: the unchanged production capture code
// talks to it through libv4l2 (v4l2_open, v4l2_ioctl, v4l2_mmap, ...) and plain libc
// (open, ioctl, poll, close, stat), and it answers as a UVC camera driven by videobuf2
// would: same ioctls, same buffer states, same error codes and flags.
//
// How it reaches the code under test
// ----------------------------------
// The library libstereod_fake_v4l2.so defines the libc entry points libv4l2 and our code
// use to reach a device: open/open64/openat/openat64 (and the _FORTIFY_SOURCE
// variants), close, ioctl, mmap/mmap64, munmap, read, write, poll, ppoll, syscall
// (libv4l2 and libv4lconvert reach the kernel only through syscall(SYS_openat,
// SYS_ioctl, SYS_mmap, SYS_munmap, SYS_close, SYS_read, SYS_write)), fstat/stat/lstat
// (a fake device is a character device), access, readlink, realpath, and
// opendir/readdir/closedir (fake devices show up in their parent directory, e.g. /dev and
// /dev/v4l/by-id). Every call that is not about a fake device goes to the next
// definition (libc, or a sanitizer's interceptor) untouched.
//   - In-process (gtest binaries): link it with `stereod_use_fake_v4l2(TARGET)` (CMake,
//     tests/fake_v4l2/CMakeLists.txt); its definitions then come before libc's.
//   - Into an unchanged stereod/stereoctl: run the child with the environment from
//     stereod::fake_v4l2::childEnvironment() below (LD_PRELOAD, STEREOD_FAKE_V4L2 and
//     ASAN_OPTIONS+=verify_asan_link_order=0, which the ASan build needs because the
//     preloaded library is not the sanitizer runtime). `stereod_use_fake_v4l2(TARGET)`
//     also gives TARGET the compile definition STEREOD_FAKE_V4L2_LIBRARY (path of the .so).
// The library is idle (every call forwarded) until a description is loaded: from the
// file named by the environment variable STEREOD_FAKE_V4L2 on the first call that names
// a path, or explicitly with stereod_fake_v4l2_load().
//
// Device model (what a test can rely on)
// --------------------------------------
// - The file descriptor returned for a fake device is a real eventfd, so poll/select/
//   epoll on it work; poll()/ppoll() report POLLIN|POLLRDNORM when a buffer is DONE,
//   POLLERR when not streaming (as videobuf2 does), POLLERR|POLLHUP after an unplug.
//   Blocking and O_NONBLOCK (at open or via fcntl) DQBUF are both supported.
// - QUERYCAP: V4L2_CAP_VIDEO_CAPTURE|V4L2_CAP_STREAMING|V4L2_CAP_EXT_PIX_FORMAT in
//   device_caps, plus V4L2_CAP_DEVICE_CAPS in capabilities; no read()/write() I/O.
// - ENUM_FMT, ENUM_FRAMESIZES (discrete), ENUM_FRAMEINTERVALS (discrete); G/S/TRY_FMT
//   adjust to an offered format (an unknown pixelformat becomes the first offered one)
//   and the nearest offered size, as drivers do; with V4L2_PIX_FMT_PRIV_MAGIC in priv,
//   YUYV says it is full range (V4L2_QUANTIZATION_FULL_RANGE, BT.601); S_FMT is EBUSY while buffers
//   exist. G/S_PARM with V4L2_CAP_TIMEPERFRAME, the nearest offered interval; frames are produced
//   at the negotiated rate.
// - Controls: QUERYCTRL (with V4L2_CTRL_FLAG_NEXT_CTRL), QUERY_EXT_CTRL, QUERYMENU,
//   G/S_CTRL, G/S/TRY_EXT_CTRLS (error_idx set). Integer values are clamped to
//   [min,max] and rounded to step (read the value back to see what was accepted);
//   booleans become 0/1 (both as v4l2-ctrls does); a menu value out of range gives
//   ERANGE; an unknown id gives EINVAL.
//   Exposure (absolute) is flagged INACTIVE while auto exposure is not manual.
// - REQBUFS (MMAP only; count clamped to [2, 32]; 0 frees; EBUSY while streaming or
//   while any buffer is still mapped), QUERYBUF, mmap of each buffer at m.offset,
//   QBUF/DQBUF (EINVAL for a bad index/type/memory or a buffer already queued, or DQBUF
//   while not streaming; EAGAIN when non-blocking and nothing is DONE; EBUSY when
//   another open file owns the queue). DQBUF returns flags DONE|MAPPED|
//   TIMESTAMP_MONOTONIC (or TIMESTAMP_UNKNOWN, then the stamp is on CLOCK_REALTIME so
//   code that trusts it fails)|TSTAMP_SRC_EOF, ERROR for a frame corrupted with kind
//   "error", field NONE, bytesused (the JPEG size for MJPG), a timestamp that is the
//   frame's capture instant (grid + jitter, not the moment the producer thread got to
//   run: a driver stamps in its interrupt handler), and a sequence number that
//   counts every frame period since STREAMON, so dropped frames leave gaps. A frame
//   period with no buffer queued is dropped, as a real driver does.
// - STREAMON/STREAMOFF: STREAMOFF returns every buffer to the dequeued state.
// - Unplug: every ioctl on an open fd fails with ENODEV, mmap too, poll gives
//   POLLERR|POLLHUP, close and munmap still work, open fails with ENOENT until replug.
//   After replug the device opens again (old fds stay dead, as with a real USB camera).
// - One producer thread per streaming device, named "fake-v4l2" (the control FIFO
//   thread "fake-v4l2-ctl"), so a measurement can tell the fake's CPU time (its stand-in
//   for DMA) from the code under test's.
//
// Description file (YAML), named by STEREOD_FAKE_V4L2 or given to stereod_fake_v4l2_load:
//
//   control: /tmp/x/fake-v4l2.fifo   # optional: FIFO for commands from other processes
//                                    # (created if missing; one command per line)
//   seed: 1                          # optional: jitter random seed
//   devices:
//     - path: /dev/video-fake-left   # required, absolute
//       by_id: usb-Fake_Stereo_Left_0001-video-index0  # optional: /dev/v4l/by-id/<name>
//       driver: uvcvideo             # QUERYCAP driver (default uvcvideo)
//       card: Fake Stereo Left       # QUERYCAP card (default: the path)
//       bus_info: usb-0000:00:14.0-1 # QUERYCAP bus_info (default usb-fake-N, N = 1-based index)
//       images: /data/left*.png      # glob, sorted; served in a loop; converted to the
//                                    # negotiated format and size (resized with INTER_AREA;
//                                    # luma = cv::COLOR_BGR2GRAY, YUYV chroma the mean
//                                    # of each pixel pair; RGB3/BGR3 the image's colour;
//                                    # MJPG colour, encoded at STREAMON with jpeg_quality)
//       jpeg_quality: 90
//       fps: [30, 15]                # offered rates, for sizes that list none (first = default)
//       formats:                     # first format and its first size are the default
//         - fourcc: YUYV             # GREY, YUYV, MJPG, RGB3 or BGR3 (packed 24-bit)
//           sizes: [640x480, 1280x720@10]   # WxH, optional @fps,fps,... overriding fps
//         - fourcc: MJPG
//           sizes: [640x480, 1280x720]
//       jitter_ms: 0.5               # uniform +-jitter on each frame's capture instant
//       phase_ms: 0                  # capture instants lie on a grid k*period + phase on
//                                    # CLOCK_MONOTONIC, so two devices with the same rate
//                                    # capture at fixed skew (phase difference) like
//                                    # hardware-synced cameras
//       clock_offset_ms: 0           # added to the reported timestamps only
//       clock_skew_ppm: 0            # reported clock runs fast by this many ppm
//       drop_every: 0                # K > 0: every K-th frame is lost (sequence gap)
//       timestamps: monotonic        # or unknown
//       controls:                    # optional; names below or `id: 0x...` with `name:`
//         - { name: exposure_auto, default: 3 }               # menu 0..3 (1 = manual)
//         - { name: exposure_absolute, min: 3, max: 2047, step: 1, default: 250 }
//         - { name: gain, min: 0, max: 255, step: 1, default: 32 }
//         - { name: white_balance_automatic, default: 1 }     # boolean
//         - { name: white_balance_temperature, min: 2800, max: 6500, step: 10, default: 4600 }
//         - { name: power_line_frequency, default: 1 }        # menu 0..2
//         - { name: brightness, min: -64, max: 64, step: 1, default: 0 }
//       Each control accepts min/max/step/default overriding the built-in ones; type
//       (integer|boolean|menu) follows the name, or `type:` for an explicit id.
//
// Commands (same text through the FIFO and stereod_fake_v4l2_command); DEV is the path,
// the by-id name or by-id path of a device:
//   unplug DEV            the device vanishes (see "Unplug" above)
//   replug DEV            it comes back
//   stall DEV MS          no frame completes for MS milliseconds from now (buffers stay
//                         queued); a new stall replaces the current one, `stall DEV 0` ends it
//   corrupt DEV N KIND    the next N frames are bad; KIND: truncated (MJPG cut to a third,
//                         no EOI marker), bytesused (bytesused = half the image size),
//                         error (V4L2_BUF_FLAG_ERROR set, as drivers do on bus errors)
//   drop DEV N            the next N frames are lost (sequence gap)

#include <cstdint>

extern "C" {

// Counters of one device, for tests (e.g. all buffers back after close, fd leaks).
struct StereodFakeV4l2Stats {
    uint64_t frames_done;   // frames completed into a buffer since load
    uint64_t frames_lost;   // frame periods without a delivered frame since load
    uint64_t next_sequence; // sequence number the next frame will carry
    int32_t open_fds;       // open file descriptions of this device
    int32_t buffers;        // buffers allocated by REQBUFS
    int32_t buffers_mapped; // live mmap()s of those buffers
    int32_t buffers_queued; // buffers with the driver (queued or done)
    int32_t streaming;      // 1 while streaming
    int32_t plugged;        // 0 after unplug
    uint32_t width;         // current format
    uint32_t height;
    uint32_t pixelformat; // V4L2 fourcc
    double fps;           // current frame rate
};

// Loads a description (replacing any loaded one; open fake fds become dead). Returns 0,
// or -errno with the reason in stereod_fake_v4l2_last_error().
int stereod_fake_v4l2_load(const char* description_path);
// Removes all fake devices and stops their threads; later opens of their paths fail.
void stereod_fake_v4l2_unload(void);
// Runs one command line (syntax above). Returns 0, -ENOENT for an unknown device,
// -EINVAL for a malformed command.
int stereod_fake_v4l2_command(const char* line);
int stereod_fake_v4l2_unplug(const char* device);
int stereod_fake_v4l2_replug(const char* device);
int stereod_fake_v4l2_stall(const char* device, int32_t milliseconds);
int stereod_fake_v4l2_drop(const char* device, int32_t frames);
// kind: "truncated", "bytesused" or "error".
int stereod_fake_v4l2_corrupt(const char* device, int32_t frames, const char* kind);
// Fills *out. Returns 0 or -ENOENT.
int stereod_fake_v4l2_stats(const char* device, struct StereodFakeV4l2Stats* out);
// The reason of the last failed load or command (thread-local, never null).
const char* stereod_fake_v4l2_last_error(void);

} // extern "C"

#ifdef __cplusplus
#include <cstdlib>
#include <string>
#include <vector>

namespace stereod::fake_v4l2 {

// Environment entries ("NAME=value") to add to a child process (stereod, stereoctl) so
// that the fake, at `library_path` (use STEREOD_FAKE_V4L2_LIBRARY), serves the devices
// described in `description_path`. Keeps the current ASAN_OPTIONS and adds
// verify_asan_link_order=0; prepends to an existing LD_PRELOAD.
inline std::vector<std::string> childEnvironment(const std::string& library_path,
                                                 const std::string& description_path)
{
    std::vector<std::string> env;
    const char* preload = std::getenv("LD_PRELOAD");
    env.push_back("LD_PRELOAD=" + library_path +
                  (preload != nullptr && *preload != '\0' ? std::string(":") + preload : ""));
    env.push_back("STEREOD_FAKE_V4L2=" + description_path);
    const char* asan = std::getenv("ASAN_OPTIONS");
    env.push_back("ASAN_OPTIONS=" +
                  (asan != nullptr && *asan != '\0' ? std::string(asan) + ":" : std::string()) +
                  "verify_asan_link_order=0");
    return env;
}

} // namespace stereod::fake_v4l2
#endif
