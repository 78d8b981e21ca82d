#pragma once
// Turns one V4L2 buffer into a grayscale image, and on request the camera's colour beside
// it: GREY is checked and used in place (no copy), YUYV gives its luma plane (no colour
// conversion), MJPEG is decoded straight to grayscale with TurboJPEG (fast integer IDCT;
// libjpeg skips the inverse transform and upsampling of the chroma planes for grayscale
// output), packed RGB24/BGR24 are converted to grey (cv::COLOR_RGB2GRAY/BGR2GRAY).
//
// With colour: YUYV is converted as BT.601, limited range (cv::COLOR_YUV2BGR_YUYV; V4L2's
// default for YUV) or full range when the driver says so, and its luma plane is still the
// grey image (the matcher sees the camera's own luma, as without colour); MJPEG is
// decoded to BGR and the grey image is cv::COLOR_BGR2GRAY of it (within a grey level of
// the JPEG's own luma); RGB24 is swapped to BGR, BGR24 copied.
//
// Why TurboJPEG: measured with bench/mjpeg_decode_bench.cpp (Aloe encoded as a camera
// would, colour JPEG at quality 90; median CPU time of 5 runs on the 2-core build machine
// under load), TJPF_GRAY + TJFLAG_FASTDCT takes 1.92 ms at 640x480 and 4.58 ms at
// 1280x720 against 2.09 ms and 5.21 ms for cv::imdecode(IMREAD_GRAYSCALE), and it decodes
// into the frame's own buffer where imdecode allocates per call.

#include <cstddef>
#include <cstdint>
#include <string>

#include <opencv2/core/mat.hpp>

#include "base/name_table.hpp"

namespace stereod {

enum class DecodeStatus {
    Ok,
    ShortBuffer, // bytesused smaller than the format needs (wrong byte count)
    Corrupt,     // the data do not decode (truncated or damaged JPEG, wrong size)
};

inline constexpr NameTable<DecodeStatus, 3> kDecodeStatuses{{{
    {DecodeStatus::Ok, "ok"},
    {DecodeStatus::ShortBuffer, "short buffer"},
    {DecodeStatus::Corrupt, "corrupt"},
}}};
static_assert(kDecodeStatuses.wellFormed());

const char* toString(DecodeStatus status) noexcept;

// Thread-bound: one decoder per capture thread. Holds the TurboJPEG handle for MJPEG;
// decoding allocates nothing.
class FrameDecoder {
  public:
    // `fourcc` is V4L2_PIX_FMT_GREY, _YUYV, _MJPEG, _RGB24 or _BGR24; `bytes_per_line` as
    // the driver set it (0 for MJPEG). Anything else is a programming error (the
    // negotiation refuses it).
    // `full_range`: YUYV uses 0..255 (NegotiatedFormat::full_range), else 16..235.
    FrameDecoder(uint32_t fourcc, int width, int height, uint32_t bytes_per_line,
                 bool full_range = false);
    ~FrameDecoder();
    FrameDecoder(const FrameDecoder&) = delete;
    FrameDecoder& operator=(const FrameDecoder&) = delete;

    // True for GREY: the buffer itself is the frame (wrap it, check it with checkInPlace()).
    bool inPlace() const noexcept { return in_place_; }

    // GREY: whether `bytes_used` covers the whole image.
    DecodeStatus checkInPlace(std::size_t bytes_used) const noexcept;

    // YUYV, MJPEG, RGB24, BGR24: decodes `data` (bytes_used long) into `gray`, which must
    // already be CV_8UC1 of the frame size. On failure `gray` holds garbage and lastError()
    // says why.
    DecodeStatus decode(const uint8_t* data, std::size_t bytes_used, cv::Mat& gray) noexcept;
    // The same, and the colour into `colour_bgr` when it is not empty (then CV_8UC3 of the
    // frame size; a GREY buffer leaves it alone). Allocates nothing.
    DecodeStatus decode(const uint8_t* data, std::size_t bytes_used, cv::Mat& gray,
                        cv::Mat& colour_bgr) noexcept;

    // The reason of the last failure (TurboJPEG's message for MJPEG).
    const char* lastError() const noexcept { return error_; }

  private:
    // Bytes of a whole image of `bytes_per_pixel` in rows of bytes_per_line_.
    std::size_t bytesNeeded(std::size_t bytes_per_pixel) const noexcept;

    uint32_t fourcc_ = 0;
    int width_ = 0;
    int height_ = 0;
    uint32_t bytes_per_line_ = 0;
    bool in_place_ = false;
    bool full_range_ = false;
    void* jpeg_ = nullptr; // tjhandle
    const char* error_ = "";
};

} // namespace stereod
