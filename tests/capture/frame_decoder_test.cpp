// Each pixel format to grayscale, on a real photograph: GREY checked in place, YUYV's
// luma plane exact (with and without row padding), MJPEG close to the source, packed
// RGB/BGR exactly as OpenCV's grey, and bad data (short buffers, truncated or damaged
// JPEG, a JPEG of the wrong size) refused. The colour beside the grey: YUYV in both
// ranges, MJPEG, RGB24 and BGR24 against the photograph, and the grey unchanged by it.

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

// Packs the photograph as full-range BT.601 YUYV, as the fake camera does: luma exactly
// COLOR_BGR2GRAY's, chroma COLOR_BGR2YCrCb's (JFIF's Cb and Cr), averaged over each pair.
std::vector<uint8_t> fullRangeYuyv(const cv::Mat& bgr)
{
    cv::Mat gray;
    cv::Mat ycrcb;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    cv::cvtColor(bgr, ycrcb, cv::COLOR_BGR2YCrCb);
    std::vector<uint8_t> out(bgr.total() * 2);
    uint8_t* dst = out.data();
    for (int y = 0; y < bgr.rows; ++y) {
        for (int x = 0; x < bgr.cols; x += 2) {
            const cv::Vec3b a = ycrcb.at<cv::Vec3b>(y, x);
            const cv::Vec3b b = ycrcb.at<cv::Vec3b>(y, x + 1);
            *dst++ = gray.at<uint8_t>(y, x);
            *dst++ = static_cast<uint8_t>((a[2] + b[2] + 1) / 2);
            *dst++ = gray.at<uint8_t>(y, x + 1);
            *dst++ = static_cast<uint8_t>((a[1] + b[1] + 1) / 2);
        }
    }
    return out;
}

double meanError(const cv::Mat& a, const cv::Mat& b)
{
    cv::Mat diff;
    cv::absdiff(a, b, diff);
    const cv::Scalar mean = cv::mean(diff);
    return (mean[0] + mean[1] + mean[2]) / a.channels();
}

TEST_F(FrameDecoderTest, YuyvColourFollowsTheDriversRange)
{
    // Full range: within a level of OpenCV's full-range YUV->BGR of the same samples (each
    // pair's chroma given to both pixels), and close to the photograph (the chroma shared
    // by a pixel pair costs a few levels on average on this textured scene).
    const std::vector<uint8_t> full = fullRangeYuyv(bgr_);
    FrameDecoder decoder(V4L2_PIX_FMT_YUYV, kWidth, kHeight, 2 * kWidth, true);
    cv::Mat colour(kHeight, kWidth, CV_8UC3);
    ASSERT_EQ(decoder.decode(full.data(), full.size(), out_, colour), DecodeStatus::Ok);
    EXPECT_EQ(cv::norm(out_, gray_, cv::NORM_INF), 0.0) << "the luma plane is the grey image";
    cv::Mat ycrcb(kHeight, kWidth, CV_8UC3);
    for (int y = 0; y < kHeight; ++y) {
        for (int x = 0; x < kWidth; ++x) {
            const uint8_t* pair =
                full.data() + (static_cast<std::size_t>(y) * kWidth + x / 2 * 2) * 2;
            ycrcb.at<cv::Vec3b>(y, x) = cv::Vec3b(pair[(x % 2) * 2], pair[3], pair[1]);
        }
    }
    cv::Mat reference;
    cv::cvtColor(ycrcb, reference, cv::COLOR_YCrCb2BGR);
    EXPECT_LE(cv::norm(colour, reference, cv::NORM_INF), 1.0);
    EXPECT_LT(meanError(colour, bgr_), 4.0);

    // Limited range (V4L2's default for YUV): black is Y 16, white Y 235, grey chroma 128.
    std::vector<uint8_t> levels(static_cast<std::size_t>(2 * kWidth) * kHeight);
    for (std::size_t i = 0; i < levels.size(); i += 4) {
        const bool white = (i / (2 * kWidth)) % 2 == 1;
        levels[i] = levels[i + 2] = white ? 235 : 16;
        levels[i + 1] = levels[i + 3] = 128;
    }
    FrameDecoder limited(V4L2_PIX_FMT_YUYV, kWidth, kHeight, 2 * kWidth);
    ASSERT_EQ(limited.decode(levels.data(), levels.size(), out_, colour), DecodeStatus::Ok);
    EXPECT_EQ(colour.at<cv::Vec3b>(0, 0), cv::Vec3b(0, 0, 0));
    EXPECT_EQ(colour.at<cv::Vec3b>(1, 5), cv::Vec3b(255, 255, 255));
    // The same bytes read as full range are dark and light grey, not black and white.
    ASSERT_EQ(decoder.decode(levels.data(), levels.size(), out_, colour), DecodeStatus::Ok);
    EXPECT_EQ(colour.at<cv::Vec3b>(0, 0), cv::Vec3b(16, 16, 16));
}

TEST_F(FrameDecoderTest, MjpegColourIsThePhotographAndItsGrey)
{
    const std::vector<uint8_t> data = jpeg(bgr_);
    FrameDecoder decoder(V4L2_PIX_FMT_MJPEG, kWidth, kHeight, 0);
    cv::Mat colour(kHeight, kWidth, CV_8UC3);
    ASSERT_EQ(decoder.decode(data.data(), data.size(), out_, colour), DecodeStatus::Ok)
        << decoder.lastError();
    // Quality 90 with 4:2:0 chroma loses a few levels on this textured scene (4.8).
    EXPECT_LT(meanError(colour, bgr_), 6.0);
    cv::Mat grey_of_colour;
    cv::cvtColor(colour, grey_of_colour, cv::COLOR_BGR2GRAY);
    EXPECT_EQ(cv::norm(out_, grey_of_colour, cv::NORM_INF), 0.0);
    // Within a level or so of the grey decode the matcher sees without colour.
    cv::Mat grey_only(kHeight, kWidth, CV_8UC1);
    FrameDecoder grey_decoder(V4L2_PIX_FMT_MJPEG, kWidth, kHeight, 0);
    ASSERT_EQ(grey_decoder.decode(data.data(), data.size(), grey_only), DecodeStatus::Ok);
    EXPECT_LT(meanError(grey_only, out_), 1.0);
}

TEST_F(FrameDecoderTest, PackedRgbAndBgrGiveTheirGreyAndColour)
{
    for (const uint32_t fourcc : {V4L2_PIX_FMT_RGB24, V4L2_PIX_FMT_BGR24}) {
        SCOPED_TRACE(fourcc == V4L2_PIX_FMT_RGB24 ? "RGB24" : "BGR24");
        // Rows padded to 16 bytes beyond the pixels, as some drivers align them.
        const uint32_t bytes_per_line = 3 * kWidth + 16;
        cv::Mat packed(kHeight, kWidth, CV_8UC3);
        if (fourcc == V4L2_PIX_FMT_RGB24)
            cv::cvtColor(bgr_, packed, cv::COLOR_BGR2RGB);
        else
            bgr_.copyTo(packed);
        std::vector<uint8_t> data(static_cast<std::size_t>(bytes_per_line) * kHeight, 0x5a);
        for (int y = 0; y < kHeight; ++y)
            std::memcpy(data.data() + static_cast<std::size_t>(y) * bytes_per_line, packed.ptr(y),
                        3 * kWidth);
        FrameDecoder decoder(fourcc, kWidth, kHeight, bytes_per_line);
        cv::Mat colour(kHeight, kWidth, CV_8UC3);
        ASSERT_EQ(decoder.decode(data.data(), data.size(), out_, colour), DecodeStatus::Ok);
        EXPECT_EQ(cv::norm(out_, gray_, cv::NORM_INF), 0.0);
        EXPECT_EQ(cv::norm(colour, bgr_, cv::NORM_INF), 0.0);
        // Without colour the grey is the same.
        out_.setTo(0);
        ASSERT_EQ(decoder.decode(data.data(), data.size(), out_), DecodeStatus::Ok);
        EXPECT_EQ(cv::norm(out_, gray_, cv::NORM_INF), 0.0);
        // The last row may stop at its pixels; one byte fewer is a short buffer.
        const std::size_t whole = static_cast<std::size_t>(bytes_per_line) * (kHeight - 1) +
                                  3 * static_cast<std::size_t>(kWidth);
        EXPECT_EQ(decoder.decode(data.data(), whole, out_, colour), DecodeStatus::Ok);
        EXPECT_EQ(decoder.decode(data.data(), whole - 1, out_, colour), DecodeStatus::ShortBuffer);
    }
}

} // namespace
} // namespace stereod
