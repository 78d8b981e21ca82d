// A recording's image file decoded for replay (replay/image_decode.hpp): with its colour,
// the grey is still exactly the grey decode a grey replay of the file gives, whether it is
// made from the one colour decode (an 8-bit colour PNG without gamma: checked for every
// 8-bit colour) or decoded a second time (a PNG with a gamma, 16-bit samples, a JPEG).

#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <zlib.h>

#include "replay/image_decode.hpp"
#include "replay/image_file.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/recordings.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

// What decodeImageFile gives for `bytes` written to a file, against OpenCV's grey and
// colour decodes of the same bytes.
void expectGreyOfTheGreyDecode(const test::TempDir& dir, const std::vector<uint8_t>& bytes,
                               const std::string& name)
{
    const std::string path = dir.file(name);
    test::writeBytes(path, bytes);
    std::vector<uint8_t> scratch;
    cv::Mat grey, colour;
    std::string reason;
    int code = 0;
    ASSERT_TRUE(decodeImageFile(path, {}, "", scratch, grey, reason, code, &colour)) << reason;
    const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1,
                          const_cast<uint8_t*>(bytes.data()));
    const cv::Mat expected_grey = cv::imdecode(encoded, cv::IMREAD_GRAYSCALE);
    const cv::Mat expected_colour = cv::imdecode(encoded, cv::IMREAD_COLOR);
    ASSERT_EQ(grey.type(), CV_8UC1) << name;
    ASSERT_EQ(colour.type(), CV_8UC3) << name;
    EXPECT_EQ(cv::countNonZero(grey != expected_grey), 0) << name << ": pixels of another grey";
    EXPECT_EQ(cv::norm(colour, expected_colour, cv::NORM_INF), 0.0) << name;
}

std::vector<uint8_t> encodePng(const cv::Mat& image)
{
    std::vector<uint8_t> bytes;
    cv::imencode(".png", image, bytes, {cv::IMWRITE_PNG_COMPRESSION, 1});
    return bytes;
}

// Every 8-bit colour, 2^24, in 16 PNGs of 1024x1024 as `stereoctl record` writes them (no
// gamma, compression 1): one colour decode gives libpng's grey of each, bit for bit.
TEST(ImageDecode, AColourPngsGreyFromItsColourIsLibpngsForEveryColour)
{
    test::TempDir dir;
    cv::Mat image(1024, 1024, CV_8UC3);
    for (int part = 0; part < 16; ++part) {
        for (int y = 0; y < image.rows; ++y) {
            auto* bgr = image.ptr<cv::Vec3b>(y);
            for (int x = 0; x < image.cols; ++x) {
                bgr[x][0] = static_cast<uint8_t>(x & 255);
                bgr[x][1] = static_cast<uint8_t>(((y & 63) << 2) | (x >> 8));
                bgr[x][2] = static_cast<uint8_t>((part << 4) | (y >> 6));
            }
        }
        const std::vector<uint8_t> bytes = encodePng(image);
        ASSERT_TRUE(parseImageHeader(bytes).grey_from_rgb) << "not the one-decode path";
        expectGreyOfTheGreyDecode(dir, bytes, "part" + std::to_string(part) + ".png");
        if (HasFailure())
            return;
    }
}

// The PNG with a gAMA chunk inserted after IHDR (length, type, value, CRC of type and
// value): libpng then makes its grey through gamma tables.
std::vector<uint8_t> withGamma(std::vector<uint8_t> png, uint32_t gamma_100000)
{
    std::vector<uint8_t> chunk = {0, 0, 0, 4, 'g', 'A', 'M', 'A'};
    for (int shift = 24; shift >= 0; shift -= 8)
        chunk.push_back(static_cast<uint8_t>(gamma_100000 >> shift));
    const uLong crc = crc32(0, chunk.data() + 4, 8);
    for (int shift = 24; shift >= 0; shift -= 8)
        chunk.push_back(static_cast<uint8_t>(crc >> shift));
    const std::size_t after_ihdr = 8 + 4 + 4 + 13 + 4;
    png.insert(png.begin() + after_ihdr, chunk.begin(), chunk.end());
    return png;
}

// The files whose grey is not a weighting of their 8-bit RGB are decoded twice: the grey
// is still the grey decode's.
TEST(ImageDecode, ColourFilesOfOtherKindsKeepTheirGreyDecode)
{
    test::TempDir dir;
    const cv::Mat tsukuba =
        cv::imread(test::sharedDataDir() + "/middlebury/tsukuba/im3.png", cv::IMREAD_COLOR);
    ASSERT_FALSE(tsukuba.empty());
    const std::vector<uint8_t> plain = encodePng(tsukuba);
    ASSERT_TRUE(parseImageHeader(plain).grey_from_rgb);

    const std::vector<uint8_t> gamma = withGamma(plain, 45455);
    EXPECT_FALSE(parseImageHeader(gamma).grey_from_rgb);
    expectGreyOfTheGreyDecode(dir, gamma, "gamma.png");

    cv::Mat deep;
    tsukuba.convertTo(deep, CV_16UC3, 257.0, 100.0);
    const std::vector<uint8_t> sixteen = encodePng(deep);
    EXPECT_FALSE(parseImageHeader(sixteen).grey_from_rgb);
    expectGreyOfTheGreyDecode(dir, sixteen, "16bit.png");

    std::vector<uint8_t> jpeg;
    cv::imencode(".jpg", tsukuba, jpeg, {cv::IMWRITE_JPEG_QUALITY, 90});
    EXPECT_FALSE(parseImageHeader(jpeg).grey_from_rgb);
    expectGreyOfTheGreyDecode(dir, jpeg, "colour.jpg");
}

} // namespace
} // namespace stereod
