// PNG and JPEG decoded by libpng and libjpeg themselves (replay/image_codecs.hpp): the grey
// and the colour are bit for bit what cv::imdecode gives for every PNG and JPEG of the
// shared data and opencv-doc's samples, and for crafted files of every PNG layout (palette,
// tRNS, 16-bit, alpha, 1/2/4-bit grey, interlaced) and progressive JPEG; what the
// libraries say about a broken file comes back in the string, not on stderr.

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <png.h>

#include "replay/image_codecs.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

std::vector<uint8_t> readAll(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

bool isPng(const std::vector<uint8_t>& bytes)
{
    return bytes.size() >= 8 && png_sig_cmp(bytes.data(), 0, 8) == 0;
}

// Decodes `bytes` both ways, grey and colour, and expects the same pixels.
void expectAsImdecode(const std::vector<uint8_t>& bytes, const std::string& name)
{
    const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1,
                          const_cast<uint8_t*>(bytes.data()));
    for (const bool colour : {false, true}) {
        const cv::Mat expected =
            cv::imdecode(encoded, colour ? cv::IMREAD_COLOR : cv::IMREAD_GRAYSCALE);
        ASSERT_FALSE(expected.empty()) << name;
        cv::Mat out;
        std::string printed;
        const CodecResult result = isPng(bytes) ? decodePng(bytes, colour, out, printed)
                                                : decodeJpeg(bytes, colour, out, printed);
        ASSERT_EQ(result, CodecResult::Decoded) << name << ": " << printed;
        ASSERT_EQ(out.type(), expected.type()) << name << (colour ? " colour" : " grey");
        ASSERT_EQ(out.size(), expected.size()) << name;
        EXPECT_EQ(cv::norm(out, expected, cv::NORM_INF), 0.0)
            << name << (colour ? " colour" : " grey") << ": other pixels than imdecode's";
    }
}

TEST(ImageCodecs, EveryPngAndJpegOfTheSharedDataDecodesAsImdecodeDoes)
{
    int files = 0;
    for (const auto& entry : std::filesystem::recursive_directory_iterator(test::sharedDataDir())) {
        const std::string extension = entry.path().extension().string();
        if (!entry.is_regular_file() ||
            (extension != ".png" && extension != ".jpg" && extension != ".jpeg"))
            continue;
        expectAsImdecode(readAll(entry.path().string()), entry.path().string());
        ++files;
        if (HasFailure())
            return;
    }
    EXPECT_GE(files, 100); // Middlebury 2001/2005/2014, KITTI, ETH3D, the real rig
}

TEST(ImageCodecs, OpencvsChessboardJpegsDecodeAsImdecodeDoes)
{
    std::vector<std::string> left, right;
    test::chessboardSamples(left, right);
    left.insert(left.end(), right.begin(), right.end());
    for (const std::string& path : left)
        expectAsImdecode(readAll(path), path);
}

// A PNG written by libpng itself, for the layouts OpenCV's writer never makes.
struct PngLayout {
    const char* name;
    int colour_type;
    int bit_depth;
    bool interlaced = false;
    bool transparent = false; // a tRNS chunk
    double gamma = 0.0;       // a gAMA chunk when > 0
};

void appendBytes(png_structp png, png_bytep data, png_size_t size)
{
    auto* to = static_cast<std::vector<uint8_t>*>(png_get_io_ptr(png));
    to->insert(to->end(), data, data + size);
}

std::vector<uint8_t> writePng(const PngLayout& layout, int width, int height)
{
    std::vector<uint8_t> bytes;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png_create_info_struct(png);
    if (setjmp(png_jmpbuf(png)) != 0) {
        png_destroy_write_struct(&png, &info);
        return {};
    }
    png_set_write_fn(png, &bytes, appendBytes, nullptr);
    png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height),
                 layout.bit_depth, layout.colour_type,
                 layout.interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    const int entries = 1 << std::min(layout.bit_depth, 8);
    std::vector<png_color> palette(static_cast<std::size_t>(entries));
    std::vector<png_byte> alphas(static_cast<std::size_t>(entries));
    for (int i = 0; i < entries; ++i) {
        palette[i] = {static_cast<png_byte>(i * 37), static_cast<png_byte>(255 - i * 11),
                      static_cast<png_byte>(i * 97)};
        alphas[i] = static_cast<png_byte>(i * 53);
    }
    if (layout.colour_type == PNG_COLOR_TYPE_PALETTE)
        png_set_PLTE(png, info, palette.data(), entries);
    if (layout.transparent) {
        png_color_16 key{};
        key.red = key.green = key.blue = key.gray = 1;
        png_set_tRNS(png, info, alphas.data(),
                     layout.colour_type == PNG_COLOR_TYPE_PALETTE ? entries : 0, &key);
    }
    if (layout.gamma > 0)
        png_set_gAMA(png, info, layout.gamma);
    png_write_info(png, info);
    const int channels = png_get_channels(png, info);
    const std::size_t row_bytes = png_get_rowbytes(png, info);
    std::vector<std::vector<png_byte>> rows(static_cast<std::size_t>(height),
                                            std::vector<png_byte>(row_bytes));
    std::vector<png_bytep> pointers;
    for (int y = 0; y < height; ++y) {
        for (std::size_t i = 0; i < row_bytes; ++i)
            rows[y][i] = static_cast<png_byte>(
                (y * 7 + static_cast<int>(i) * 13 + (static_cast<int>(i) / channels) * y) & 255);
        pointers.push_back(rows[y].data());
    }
    png_write_image(png, pointers.data());
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return bytes;
}

TEST(ImageCodecs, EveryPngLayoutDecodesAsImdecodeDoes)
{
    const std::vector<PngLayout> layouts = {
        {"palette 8-bit", PNG_COLOR_TYPE_PALETTE, 8},
        {"palette 4-bit", PNG_COLOR_TYPE_PALETTE, 4},
        {"palette 1-bit", PNG_COLOR_TYPE_PALETTE, 1},
        {"palette with tRNS", PNG_COLOR_TYPE_PALETTE, 8, false, true},
        {"grey 1-bit", PNG_COLOR_TYPE_GRAY, 1},
        {"grey 2-bit", PNG_COLOR_TYPE_GRAY, 2},
        {"grey 4-bit", PNG_COLOR_TYPE_GRAY, 4},
        {"grey 8-bit", PNG_COLOR_TYPE_GRAY, 8},
        {"grey 16-bit", PNG_COLOR_TYPE_GRAY, 16},
        {"grey with tRNS", PNG_COLOR_TYPE_GRAY, 8, false, true},
        {"grey+alpha 8-bit", PNG_COLOR_TYPE_GRAY_ALPHA, 8},
        {"grey+alpha 16-bit", PNG_COLOR_TYPE_GRAY_ALPHA, 16},
        {"rgb 8-bit", PNG_COLOR_TYPE_RGB, 8},
        {"rgb 16-bit", PNG_COLOR_TYPE_RGB, 16},
        {"rgb with tRNS", PNG_COLOR_TYPE_RGB, 8, false, true},
        {"rgb with gamma", PNG_COLOR_TYPE_RGB, 8, false, false, 1.0 / 2.2},
        {"rgb 16-bit with gamma", PNG_COLOR_TYPE_RGB, 16, false, false, 0.6},
        {"rgba 8-bit", PNG_COLOR_TYPE_RGB_ALPHA, 8},
        {"rgba 16-bit", PNG_COLOR_TYPE_RGB_ALPHA, 16},
        {"rgb interlaced", PNG_COLOR_TYPE_RGB, 8, true},
        {"grey interlaced", PNG_COLOR_TYPE_GRAY, 8, true},
        {"palette 2-bit interlaced", PNG_COLOR_TYPE_PALETTE, 2, true},
    };
    for (const PngLayout& layout : layouts) {
        const std::vector<uint8_t> bytes = writePng(layout, 67, 45);
        ASSERT_FALSE(bytes.empty()) << layout.name;
        expectAsImdecode(bytes, layout.name);
    }
}

TEST(ImageCodecs, JpegsOfEveryKindDecodeAsImdecodeDoes)
{
    const cv::Mat photo = cv::imread(test::chessboardSample("left", 1), cv::IMREAD_COLOR);
    ASSERT_FALSE(photo.empty());
    cv::Mat grey;
    cv::extractChannel(photo, grey, 1);
    const std::vector<std::pair<std::string, std::vector<int>>> settings = {
        {"baseline", {}},
        {"progressive", {cv::IMWRITE_JPEG_PROGRESSIVE, 1}},
        {"optimized", {cv::IMWRITE_JPEG_OPTIMIZE, 1, cv::IMWRITE_JPEG_QUALITY, 60}},
        {"restart intervals", {cv::IMWRITE_JPEG_RST_INTERVAL, 3}},
        {"chroma at full quality",
         {cv::IMWRITE_JPEG_QUALITY, 100, cv::IMWRITE_JPEG_CHROMA_QUALITY, 100}},
    };
    for (const auto& [name, params] : settings) {
        for (const cv::Mat* image : std::initializer_list<const cv::Mat*>{&photo, &grey}) {
            std::vector<uint8_t> bytes;
            ASSERT_TRUE(cv::imencode(".jpg", *image, bytes, params)) << name;
            expectAsImdecode(bytes, name + (image == &grey ? " grey" : " colour"));
        }
    }
}

TEST(ImageCodecs, WhatTheLibrariesSayComesBackInTheString)
{
    const cv::Mat photo = cv::imread(test::chessboardSample("left", 2), cv::IMREAD_COLOR);
    ASSERT_FALSE(photo.empty());
    for (const char* extension : {".png", ".jpg"}) {
        std::vector<uint8_t> bytes;
        ASSERT_TRUE(cv::imencode(extension, photo, bytes));
        for (std::size_t i = bytes.size() / 3; i < bytes.size() * 2 / 3; i += 5)
            bytes[i] ^= 0x5a;
        cv::Mat out;
        std::string printed;
        if (std::string(extension) == ".png") {
            EXPECT_EQ(decodePng(bytes, false, out, printed), CodecResult::Failed);
            EXPECT_EQ(printed.rfind("libpng error: ", 0), 0u) << printed;
            EXPECT_TRUE(out.empty());
        } else {
            // libjpeg fills the damage in and warns (once, as its own handler would), or
            // gives up where imdecode gives up.
            const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1, bytes.data());
            const bool readable = !cv::imdecode(encoded, cv::IMREAD_GRAYSCALE).empty();
            EXPECT_EQ(decodeJpeg(bytes, false, out, printed),
                      readable ? CodecResult::Decoded : CodecResult::Failed)
                << printed;
            EXPECT_FALSE(printed.empty());
        }
    }
    // Not an image at all: libjpeg's error, and no longjmp past a destructor (ASan).
    const std::vector<uint8_t> junk = {0xff, 0xd8, 0xff, 0x00, 1, 2, 3};
    cv::Mat out;
    std::string printed;
    EXPECT_EQ(decodeJpeg(junk, true, out, printed), CodecResult::Failed);
    EXPECT_FALSE(printed.empty());
}

} // namespace
} // namespace stereod
