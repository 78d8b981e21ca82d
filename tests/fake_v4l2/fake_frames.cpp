// Image files turned into what a camera would put in its buffers.

#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tests/fake_v4l2/fake_internal.hpp"

namespace stereod::fake {

uint32_t imageBufferSize(uint32_t fourcc, uint32_t width, uint32_t height)
{
    return fourcc == V4L2_PIX_FMT_GREY ? width * height : 2 * width * height;
}

uint32_t bytesPerLine(uint32_t fourcc, uint32_t width)
{
    switch (fourcc) {
    case V4L2_PIX_FMT_GREY:
        return width;
    case V4L2_PIX_FMT_YUYV:
        return 2 * width;
    default:
        return 0; // compressed
    }
}

namespace {

// Packs Y0 U Y1 V per pixel pair; luma is exactly COLOR_BGR2GRAY's, chroma the pair's mean.
std::vector<uint8_t> packYuyv(const cv::Mat& bgr)
{
    cv::Mat gray;
    cv::Mat yuv;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    cv::cvtColor(bgr, yuv, cv::COLOR_BGR2YUV);
    std::vector<uint8_t> out(static_cast<size_t>(bgr.total()) * 2);
    uint8_t* dst = out.data();
    for (int y = 0; y < bgr.rows; ++y) {
        const uint8_t* luma = gray.ptr<uint8_t>(y);
        const cv::Vec3b* c = yuv.ptr<cv::Vec3b>(y);
        for (int x = 0; x < bgr.cols; x += 2) {
            *dst++ = luma[x];
            *dst++ = static_cast<uint8_t>((c[x][1] + c[x + 1][1] + 1) / 2);
            *dst++ = luma[x + 1];
            *dst++ = static_cast<uint8_t>((c[x][2] + c[x + 1][2] + 1) / 2);
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
