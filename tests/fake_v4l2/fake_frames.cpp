// Image files turned into what a camera would put in its buffers.

#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tests/fake_v4l2/fake_internal.hpp"

namespace stereod::fake {

uint32_t imageBufferSize(uint32_t fourcc, uint32_t width, uint32_t height)
{
    switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
        return width * height;
    case V4L2_PIX_FMT_RGB24:
    case V4L2_PIX_FMT_BGR24:
        return 3 * width * height;
    default:
        return 2 * width * height;
    }
}

uint32_t bytesPerLine(uint32_t fourcc, uint32_t width)
{
    switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
        return width;
    case V4L2_PIX_FMT_YUYV:
        return 2 * width;
    case V4L2_PIX_FMT_RGB24:
    case V4L2_PIX_FMT_BGR24:
        return 3 * width;
    default:
        return 0; // compressed
    }
}

namespace {

// Packs Y0 U Y1 V per pixel pair, full-range BT.601 (JFIF's YCbCr): luma is exactly
// COLOR_BGR2GRAY's, chroma the pair's mean of COLOR_BGR2YCrCb's Cb and Cr.
std::vector<uint8_t> packYuyv(const cv::Mat& bgr)
{
    cv::Mat gray;
    cv::Mat ycrcb;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    cv::cvtColor(bgr, ycrcb, cv::COLOR_BGR2YCrCb);
    std::vector<uint8_t> out(static_cast<size_t>(bgr.total()) * 2);
    uint8_t* dst = out.data();
    for (int y = 0; y < bgr.rows; ++y) {
        const uint8_t* luma = gray.ptr<uint8_t>(y);
        const cv::Vec3b* c = ycrcb.ptr<cv::Vec3b>(y); // Y Cr Cb
        for (int x = 0; x < bgr.cols; x += 2) {
            *dst++ = luma[x];
            *dst++ = static_cast<uint8_t>((c[x][2] + c[x + 1][2] + 1) / 2); // U = Cb
            *dst++ = luma[x + 1];
            *dst++ = static_cast<uint8_t>((c[x][1] + c[x + 1][1] + 1) / 2); // V = Cr
        }
    }
    return out;
}

} // namespace

std::vector<std::vector<uint8_t>> renderFrames(const std::vector<std::string>& image_files,
                                               uint32_t fourcc, uint32_t width, uint32_t height,
                                               int jpeg_quality)
{
    std::vector<std::vector<uint8_t>> frames;
    frames.reserve(image_files.size());
    for (const std::string& file : image_files) {
        cv::Mat image = cv::imread(file, cv::IMREAD_COLOR);
        if (image.empty())
            throw std::runtime_error(file + ": cannot read the image");
        const cv::Size size(static_cast<int>(width), static_cast<int>(height));
        if (image.size() != size)
            cv::resize(image, image, size, 0.0, 0.0, cv::INTER_AREA);
        if (fourcc == V4L2_PIX_FMT_GREY) {
            cv::Mat gray;
            cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
            frames.emplace_back(gray.data, gray.data + gray.total());
        } else if (fourcc == V4L2_PIX_FMT_YUYV) {
            frames.push_back(packYuyv(image));
        } else if (fourcc == V4L2_PIX_FMT_RGB24 || fourcc == V4L2_PIX_FMT_BGR24) {
            cv::Mat packed;
            if (fourcc == V4L2_PIX_FMT_RGB24)
                cv::cvtColor(image, packed, cv::COLOR_BGR2RGB);
            else
                packed = image.isContinuous() ? image : image.clone();
            frames.emplace_back(packed.data, packed.data + packed.total() * packed.elemSize());
        } else {
            std::vector<uint8_t> jpeg;
            cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, jpeg_quality});
            if (jpeg.size() > imageBufferSize(fourcc, width, height))
                throw std::runtime_error(file + ": JPEG larger than the buffer");
            frames.push_back(std::move(jpeg));
        }
    }
    return frames;
}

} // namespace stereod::fake
