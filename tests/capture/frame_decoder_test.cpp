// Each pixel format to grayscale, on a real photograph: GREY checked in place, YUYV's
// luma plane exact (with and without row padding), MJPEG close to the source, and bad
// data (short buffers, truncated or damaged JPEG, a JPEG of the wrong size) refused.

#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "capture/frame_decoder.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

constexpr int kWidth = 320;
constexpr int kHeight = 240;

class FrameDecoderTest : public ::testing::Test {
  protected:
    void SetUp() override
    {
        const cv::Mat aloe = cv::imread(test::opencvSamplesDir() + "/aloeL.jpg");
        ASSERT_FALSE(aloe.empty());
        cv::resize(aloe, bgr_, cv::Size(kWidth, kHeight), 0, 0, cv::INTER_AREA);
        cv::cvtColor(bgr_, gray_, cv::COLOR_BGR2GRAY);
        out_.create(kHeight, kWidth, CV_8UC1);
    }

    // YUYV rows of `bytes_per_line` bytes: luma from gray_, chroma arbitrary.
    std::vector<uint8_t> yuyv(uint32_t bytes_per_line) const
    {
        std::vector<uint8_t> data(static_cast<std::size_t>(bytes_per_line) * kHeight, 0xee);
        for (int y = 0; y < kHeight; ++y) {
            uint8_t* row = data.data() + static_cast<std::size_t>(y) * bytes_per_line;
            for (int x = 0; x < kWidth; ++x) {
                row[2 * x] = gray_.at<uint8_t>(y, x);
                row[2 * x + 1] = static_cast<uint8_t>(x * 7 + y); // U or V
            }
        }
        return data;
    }

    std::vector<uint8_t> jpeg(const cv::Mat& image) const
    {
        std::vector<uint8_t> data;
        EXPECT_TRUE(cv::imencode(".jpg", image, data, {cv::IMWRITE_JPEG_QUALITY, 90}));
        return data;
    }

    cv::Mat bgr_;
    cv::Mat gray_;
    cv::Mat out_;
};

TEST_F(FrameDecoderTest, GreyIsUsedInPlaceWhenComplete)
{
    const FrameDecoder padded(V4L2_PIX_FMT_GREY, kWidth, kHeight, kWidth + 64);
    EXPECT_TRUE(padded.inPlace());
    // The last row need not carry its padding.
    EXPECT_EQ(padded.checkInPlace((kWidth + 64) * (kHeight - 1) + kWidth), DecodeStatus::Ok);
    EXPECT_EQ(padded.checkInPlace((kWidth + 64) * (kHeight - 1) + kWidth - 1),
              DecodeStatus::ShortBuffer);
    EXPECT_EQ(padded.checkInPlace(0), DecodeStatus::ShortBuffer);
}

TEST_F(FrameDecoderTest, YuyvGivesTheLumaPlaneExactly)
{
    for (const uint32_t bytes_per_line : {2u * kWidth, 2u * kWidth + 32u}) {
        FrameDecoder decoder(V4L2_PIX_FMT_YUYV, kWidth, kHeight, bytes_per_line);
        EXPECT_FALSE(decoder.inPlace());
        const std::vector<uint8_t> data = yuyv(bytes_per_line);
        ASSERT_EQ(decoder.decode(data.data(), data.size(), out_), DecodeStatus::Ok);
        EXPECT_EQ(cv::norm(out_, gray_, cv::NORM_INF), 0.0) << "bytes_per_line " << bytes_per_line;
    }
}

TEST_F(FrameDecoderTest, YuyvWithTooFewBytesIsABadFrame)
{
    FrameDecoder decoder(V4L2_PIX_FMT_YUYV, kWidth, kHeight, 2 * kWidth);
    const std::vector<uint8_t> data = yuyv(2 * kWidth);
    EXPECT_EQ(decoder.decode(data.data(), data.size() / 2, out_), DecodeStatus::ShortBuffer);
    EXPECT_STRNE(decoder.lastError(), "");
}

TEST_F(FrameDecoderTest, MjpegDecodesCloseToTheSource)
{
    FrameDecoder decoder(V4L2_PIX_FMT_MJPEG, kWidth, kHeight, 0);
    // A colour JPEG (what UVC cameras send) and a grayscale one.
    for (const cv::Mat& source : {bgr_, gray_}) {
        const std::vector<uint8_t> data = jpeg(source);
        ASSERT_EQ(decoder.decode(data.data(), data.size(), out_), DecodeStatus::Ok)
            << decoder.lastError();
        // What JPEG itself loses at quality 90 on this textured scene, through OpenCV's
        // accurate decoder: the fast integer IDCT adds little to it.
        const cv::Mat reference = cv::imdecode(data, cv::IMREAD_GRAYSCALE);
        cv::Mat diff;
        cv::absdiff(reference, gray_, diff);
        const double jpeg_error = cv::mean(diff)[0];
        cv::absdiff(out_, gray_, diff);
        const double our_error = cv::mean(diff)[0];
        EXPECT_LT(our_error, 4.0);
        EXPECT_LT(our_error, jpeg_error + 0.25) << "JPEG alone: " << jpeg_error;
        EXPECT_LE(cv::norm(out_, reference, cv::NORM_INF), 8.0);
    }
}

TEST_F(FrameDecoderTest, TruncatedOrDamagedMjpegIsABadFrame)
{
    FrameDecoder decoder(V4L2_PIX_FMT_MJPEG, kWidth, kHeight, 0);
    const std::vector<uint8_t> data = jpeg(bgr_);

    // Cut to a third: the scan ends early (libjpeg's "premature end" warning).
    EXPECT_EQ(decoder.decode(data.data(), data.size() / 3, out_), DecodeStatus::Corrupt);
    EXPECT_STRNE(decoder.lastError(), "");
    // Cut inside the header.
    EXPECT_EQ(decoder.decode(data.data(), 40, out_), DecodeStatus::Corrupt);
    // Not a JPEG at all.
    const std::vector<uint8_t> zeros(4096, 0);
    EXPECT_EQ(decoder.decode(zeros.data(), zeros.size(), out_), DecodeStatus::Corrupt);
    EXPECT_EQ(decoder.decode(data.data(), 0, out_), DecodeStatus::Corrupt);
    // A JPEG of another size than negotiated.
    cv::Mat small;
    cv::resize(bgr_, small, cv::Size(kWidth / 2, kHeight / 2));
    const std::vector<uint8_t> other = jpeg(small);
    EXPECT_EQ(decoder.decode(other.data(), other.size(), out_), DecodeStatus::Corrupt);

    // The decoder is still good for the next frame.
    ASSERT_EQ(decoder.decode(data.data(), data.size(), out_), DecodeStatus::Ok)
        << decoder.lastError();
}

} // namespace
} // namespace stereod
