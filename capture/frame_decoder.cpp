#include "capture/frame_decoder.hpp"

#include <cassert>

#include <linux/videodev2.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <turbojpeg.h>

namespace stereod {

namespace {

uint8_t clampByte(int value) noexcept
{
    return static_cast<uint8_t>(value < 0 ? 0 : (value > 255 ? 255 : value));
}

// Full-range BT.601 (JFIF's): OpenCV's YUV422 conversions are limited range only. Fixed
// point with 16 fraction bits; each pixel pair shares its U and V.
void fullRangeYuyvToBgr(const cv::Mat& yuyv, cv::Mat& bgr) noexcept
{
    constexpr int kShift = 16;
    constexpr int kHalf = 1 << (kShift - 1);
    constexpr int kVtoR = 91881;  // 1.402
    constexpr int kUtoG = 22554;  // 0.344136
    constexpr int kVtoG = 46802;  // 0.714136
    constexpr int kUtoB = 116130; // 1.772
    for (int row = 0; row < yuyv.rows; ++row) {
        const uint8_t* in = yuyv.ptr<uint8_t>(row);
        uint8_t* out = bgr.ptr<uint8_t>(row);
        for (int x = 0; x + 1 < yuyv.cols; x += 2, in += 4, out += 6) {
            const int u = in[1] - 128;
            const int v = in[3] - 128;
            const int r = (kVtoR * v + kHalf) >> kShift;
            const int g = (-kUtoG * u - kVtoG * v + kHalf) >> kShift;
            const int b = (kUtoB * u + kHalf) >> kShift;
            for (int i = 0; i < 2; ++i) {
                const int y = in[2 * i];
                out[3 * i] = clampByte(y + b);
                out[3 * i + 1] = clampByte(y + g);
                out[3 * i + 2] = clampByte(y + r);
            }
        }
    }
}

} // namespace

const char* toString(DecodeStatus status) noexcept
{
    return kDecodeStatuses.name(status, "unknown");
}

FrameDecoder::FrameDecoder(uint32_t fourcc, int width, int height, uint32_t bytes_per_line,
                           bool full_range)
    : fourcc_(fourcc), width_(width), height_(height), bytes_per_line_(bytes_per_line),
      in_place_(fourcc == V4L2_PIX_FMT_GREY), full_range_(full_range)
{
    assert(fourcc == V4L2_PIX_FMT_GREY || fourcc == V4L2_PIX_FMT_YUYV ||
           fourcc == V4L2_PIX_FMT_MJPEG || fourcc == V4L2_PIX_FMT_RGB24 ||
           fourcc == V4L2_PIX_FMT_BGR24);
    if (fourcc == V4L2_PIX_FMT_MJPEG)
        jpeg_ = tjInitDecompress();
}

FrameDecoder::~FrameDecoder()
{
    if (jpeg_ != nullptr)
        tjDestroy(static_cast<tjhandle>(jpeg_));
}

std::size_t FrameDecoder::bytesNeeded(std::size_t bytes_per_pixel) const noexcept
{
    // The last row need not be padded to bytes_per_line.
    return static_cast<std::size_t>(bytes_per_line_) * static_cast<std::size_t>(height_ - 1) +
           bytes_per_pixel * static_cast<std::size_t>(width_);
}

DecodeStatus FrameDecoder::checkInPlace(std::size_t bytes_used) const noexcept
{
    return bytes_used >= bytesNeeded(1) ? DecodeStatus::Ok : DecodeStatus::ShortBuffer;
}

DecodeStatus FrameDecoder::decode(const uint8_t* data, std::size_t bytes_used,
                                  cv::Mat& gray) noexcept
{
    cv::Mat no_colour;
    return decode(data, bytes_used, gray, no_colour);
}

DecodeStatus FrameDecoder::decode(const uint8_t* data, std::size_t bytes_used, cv::Mat& gray,
                                  cv::Mat& colour_bgr) noexcept
{
    assert(gray.type() == CV_8UC1 && gray.cols == width_ && gray.rows == height_);
    assert(colour_bgr.empty() || (colour_bgr.type() == CV_8UC3 && colour_bgr.cols == width_ &&
                                  colour_bgr.rows == height_));
    const bool colour = !colour_bgr.empty();
    error_ = "";
    if (fourcc_ == V4L2_PIX_FMT_YUYV) {
        if (bytes_used < bytesNeeded(2)) {
            error_ = "YUYV buffer shorter than the image";
            return DecodeStatus::ShortBuffer;
        }
        // Y0 U Y1 V: the luma plane is channel 0 of a two-channel view.
        const cv::Mat yuyv(height_, width_, CV_8UC2, const_cast<uint8_t*>(data), bytes_per_line_);
        cv::extractChannel(yuyv, gray, 0);
        if (colour && full_range_)
            fullRangeYuyvToBgr(yuyv, colour_bgr);
        else if (colour)
            cv::cvtColor(yuyv, colour_bgr, cv::COLOR_YUV2BGR_YUYV);
        return DecodeStatus::Ok;
    }
    if (fourcc_ == V4L2_PIX_FMT_RGB24 || fourcc_ == V4L2_PIX_FMT_BGR24) {
        if (bytes_used < bytesNeeded(3)) {
            error_ = "RGB buffer shorter than the image";
            return DecodeStatus::ShortBuffer;
        }
        const bool rgb = fourcc_ == V4L2_PIX_FMT_RGB24;
        const cv::Mat packed(height_, width_, CV_8UC3, const_cast<uint8_t*>(data), bytes_per_line_);
        cv::cvtColor(packed, gray, rgb ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
        if (colour) {
            if (rgb)
                cv::cvtColor(packed, colour_bgr, cv::COLOR_RGB2BGR);
            else
                packed.copyTo(colour_bgr);
        }
        return DecodeStatus::Ok;
    }
    if (fourcc_ == V4L2_PIX_FMT_MJPEG) {
        auto handle = static_cast<tjhandle>(jpeg_);
        if (handle == nullptr) {
            error_ = "TurboJPEG decompressor could not be created";
            return DecodeStatus::Corrupt;
        }
        // Too short to hold a JPEG header, or not starting with SOI: not a JPEG at all.
        if (bytes_used < 4 || data[0] != 0xff || data[1] != 0xd8) {
            error_ = "not a JPEG (no SOI marker)";
            return DecodeStatus::Corrupt;
        }
        int width = 0;
        int height = 0;
        int subsampling = 0;
        int colorspace = 0;
        if (tjDecompressHeader3(handle, data, static_cast<unsigned long>(bytes_used), &width,
                                &height, &subsampling, &colorspace) != 0) {
            error_ = tjGetErrorStr2(handle);
            return DecodeStatus::Corrupt;
        }
        if (width != width_ || height != height_) {
            error_ = "JPEG size differs from the negotiated size";
            return DecodeStatus::Corrupt;
        }
        // A warning (a truncated scan: "Premature end of JPEG file") also fails here:
        // the bottom of such a frame is filled in, not seen, and must not be matched.
        cv::Mat& target = colour ? colour_bgr : gray;
        if (tjDecompress2(handle, data, static_cast<unsigned long>(bytes_used), target.data, width_,
                          static_cast<int>(target.step), height_, colour ? TJPF_BGR : TJPF_GRAY,
                          TJFLAG_FASTDCT | TJFLAG_NOREALLOC) != 0) {
            error_ = tjGetErrorStr2(handle);
            return DecodeStatus::Corrupt;
        }
        if (colour)
            cv::cvtColor(colour_bgr, gray, cv::COLOR_BGR2GRAY);
        return DecodeStatus::Ok;
    }
    // GREY copied out (used when the caller wants a pool frame rather than the buffer).
    if (checkInPlace(bytes_used) != DecodeStatus::Ok) {
        error_ = "GREY buffer shorter than the image";
        return DecodeStatus::ShortBuffer;
    }
    const cv::Mat grey(height_, width_, CV_8UC1, const_cast<uint8_t*>(data), bytes_per_line_);
    grey.copyTo(gray);
    return DecodeStatus::Ok;
}

} // namespace stereod
