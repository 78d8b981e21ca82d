#include "capture/frame_decoder.hpp"

#include <cassert>

#include <linux/videodev2.h>
#include <opencv2/core.hpp>
#include <turbojpeg.h>

namespace stereod {

const char* toString(DecodeStatus status) noexcept
{
    switch (status) {
    case DecodeStatus::Ok:
        return "ok";
    case DecodeStatus::ShortBuffer:
        return "short buffer";
    case DecodeStatus::Corrupt:
        return "corrupt";
    }
    return "unknown";
}

FrameDecoder::FrameDecoder(uint32_t fourcc, int width, int height, uint32_t bytes_per_line)
    : fourcc_(fourcc), width_(width), height_(height), bytes_per_line_(bytes_per_line),
      in_place_(fourcc == V4L2_PIX_FMT_GREY)
{
    assert(fourcc == V4L2_PIX_FMT_GREY || fourcc == V4L2_PIX_FMT_YUYV ||
           fourcc == V4L2_PIX_FMT_MJPEG);
    if (fourcc == V4L2_PIX_FMT_MJPEG)
        jpeg_ = tjInitDecompress();
}

FrameDecoder::~FrameDecoder()
{
    if (jpeg_ != nullptr)
        tjDestroy(static_cast<tjhandle>(jpeg_));
}

DecodeStatus FrameDecoder::checkInPlace(std::size_t bytes_used) const noexcept
{
    // The last row need not be padded to bytes_per_line.
    const std::size_t needed =
        static_cast<std::size_t>(bytes_per_line_) * static_cast<std::size_t>(height_ - 1) +
        static_cast<std::size_t>(width_);
    return bytes_used >= needed ? DecodeStatus::Ok : DecodeStatus::ShortBuffer;
}

DecodeStatus FrameDecoder::decode(const uint8_t* data, std::size_t bytes_used,
                                  cv::Mat& gray) noexcept
{
    assert(gray.type() == CV_8UC1 && gray.cols == width_ && gray.rows == height_);
    error_ = "";
    if (fourcc_ == V4L2_PIX_FMT_YUYV) {
        const std::size_t needed =
            static_cast<std::size_t>(bytes_per_line_) * static_cast<std::size_t>(height_ - 1) +
            2 * static_cast<std::size_t>(width_);
        if (bytes_used < needed) {
            error_ = "YUYV buffer shorter than the image";
            return DecodeStatus::ShortBuffer;
        }
        // Y0 U Y1 V: the luma plane is channel 0 of a two-channel view.
        const cv::Mat yuyv(height_, width_, CV_8UC2, const_cast<uint8_t*>(data), bytes_per_line_);
        cv::extractChannel(yuyv, gray, 0);
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
        if (tjDecompress2(handle, data, static_cast<unsigned long>(bytes_used), gray.data, width_,
                          static_cast<int>(gray.step), height_, TJPF_GRAY,
                          TJFLAG_FASTDCT | TJFLAG_NOREALLOC) != 0) {
            error_ = tjGetErrorStr2(handle);
            return DecodeStatus::Corrupt;
        }
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
