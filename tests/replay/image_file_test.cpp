// Image files read without trusting them (replay/image_file.hpp): sizes and completeness
// from PNG and JPEG headers, and bounded reads that refuse what is not a regular file.

#include <cerrno>
#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <sys/stat.h>

#include "replay/image_file.hpp"
#include "tests/support/process.hpp"
#include "tests/support/recordings.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::TempDir;

cv::Mat testImage(cv::Size size)
{
    cv::Mat image(size, CV_8UC1);
    cv::randu(image, 0, 255);
    return image;
}

std::vector<uint8_t> readAll(const std::string& path)
{
    std::vector<uint8_t> bytes;
    std::string reason;
    EXPECT_EQ(readImageFile(path, 1u << 30, bytes, reason), 0) << reason;
    return bytes;
}

TEST(ImageHeader, PngAndJpegSizesComeFromTheHeader)
{
    for (const char* extension : {".png", ".jpg"}) {
        const ImageHeader header = parseImageHeader(test::encode(testImage({123, 45}), extension));
        EXPECT_EQ(header.format,
                  extension == std::string(".png") ? ImageFormat::Png : ImageFormat::Jpeg);
        EXPECT_EQ(header.size, cv::Size(123, 45)) << extension;
        EXPECT_TRUE(header.complete) << extension;
        EXPECT_EQ(header.problem, "") << extension;
    }
}

TEST(ImageHeader, DecompressionBombDeclaresItsSizeInFewBytes)
{
    TempDir dir;
    const std::string path = dir.file("bomb.png");
    test::writeDecompressionBomb(path, {20000, 20000});
    EXPECT_LT(std::filesystem::file_size(path), 1u << 20);
    const ImageHeader header = parseImageHeader(readAll(path));
    EXPECT_EQ(header.format, ImageFormat::Png);
    EXPECT_EQ(header.size, cv::Size(20000, 20000));
    EXPECT_TRUE(header.complete);
}

TEST(ImageHeader, TruncatedImagesAreIncomplete)
{
    for (const char* extension : {".png", ".jpg"}) {
        std::vector<uint8_t> bytes = test::encode(testImage({64, 48}), extension);
        bytes.resize(bytes.size() * 2 / 3);
        const ImageHeader header = parseImageHeader(bytes);
        EXPECT_EQ(header.size, cv::Size(64, 48)) << extension;
        EXPECT_FALSE(header.complete) << extension;
    }
    // A JPEG with padding after its end-of-image marker is complete.
    std::vector<uint8_t> padded = test::encode(testImage({64, 48}), ".jpg");
    padded.insert(padded.end(), 16, 0);
    EXPECT_TRUE(parseImageHeader(padded).complete);
}

TEST(ImageHeader, HeadersCutShortOrOtherFormatsGiveNoSize)
{
    const std::vector<uint8_t> png = test::encode(testImage({64, 48}), ".png");
    const ImageHeader cut_png = parseImageHeader(std::span(png).first(20));
    EXPECT_NE(cut_png.problem, "");
    const std::vector<uint8_t> jpeg = test::encode(testImage({64, 48}), ".jpg");
    const ImageHeader cut_jpeg = parseImageHeader(std::span(jpeg).first(30));
    EXPECT_NE(cut_jpeg.problem, "");
    EXPECT_TRUE(cut_jpeg.size.empty());
    const ImageHeader bmp = parseImageHeader(test::encode(testImage({64, 48}), ".bmp"));
    EXPECT_EQ(bmp.format, ImageFormat::Other);
    EXPECT_TRUE(bmp.size.empty());
    EXPECT_EQ(bmp.problem, "");
    EXPECT_EQ(parseImageHeader({}).format, ImageFormat::Other);
}

TEST(ImageFile, DevicesFifosAndDirectoriesAreRefusedWithoutBlocking)
{
    TempDir dir;
    const std::string fifo = dir.file("fifo");
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    std::vector<uint8_t> bytes;
    for (const std::string& path : {std::string("/dev/zero"), fifo, dir.file("")}) {
        std::string reason;
        const auto started = std::chrono::steady_clock::now();
        EXPECT_EQ(readImageFile(path, 1u << 20, bytes, reason), EINVAL) << path;
        EXPECT_NE(reason.find("not a regular file"), std::string::npos) << reason;
        EXPECT_LT(std::chrono::steady_clock::now() - started, std::chrono::seconds(1)) << path;
        EXPECT_TRUE(bytes.empty());
    }
}

TEST(ImageFile, MissingAndTooLargeFilesSayWhy)
{
    TempDir dir;
    std::vector<uint8_t> bytes;
    std::string reason;
    EXPECT_EQ(readImageFile(dir.file("nothing.png"), 1024, bytes, reason), ENOENT);
    EXPECT_EQ(reason, "missing");
    const std::string big = dir.file("big.png");
    test::writeBytes(big, std::vector<uint8_t>(4096, 7));
    EXPECT_EQ(readImageFile(big, 1024, bytes, reason), EFBIG);
    EXPECT_NE(reason.find("4096 bytes"), std::string::npos) << reason;
    EXPECT_EQ(readImageFile(big, 4096, bytes, reason), 0) << reason;
    EXPECT_EQ(bytes.size(), 4096u);
}

} // namespace
} // namespace stereod
