// The service's images as payloads: their descriptors as the service writes them and a
// client reads them back, the checks a client makes before reading, and the bytes of an
// image (moved here from tests/protocol/payload_test.cpp with the functions they test).

#include <cstdint>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "daemon/image_payload.hpp"

namespace stereod {
namespace {

TEST(Payload, ImageDescriptorReadsBackAsWritten)
{
    const cv::Mat depth(3, 4, CV_16UC1, cv::Scalar(1000));
    const Payload payload = imagePayload("depth", kFormatDepthMm, depth);
    std::string text;
    appendPayloadJson(text, payload);
    EXPECT_EQ(text, R"({"name":"depth","format":"u16_mm","width":4,"height":3,"bytes":24})");

    const std::optional<Payload> back = payloadFromJson(payloadToJson(payload));
    ASSERT_TRUE(back);
    EXPECT_EQ(back->name, "depth");
    EXPECT_EQ(back->format, kFormatDepthMm);
    EXPECT_EQ(back->width, 4);
    EXPECT_EQ(back->height, 3);
    EXPECT_EQ(back->bytes, 24u);
    EXPECT_FALSE(back->stamp_ns);
    EXPECT_TRUE(imagePayloadAddsUp(*back, sizeof(uint16_t)));
    EXPECT_FALSE(imagePayloadAddsUp(*back, sizeof(float)));
}

TEST(Payload, RawFramesCarryTheirStamp)
{
    Payload payload = imagePayload("raw_left", kFormatGray, cv::Mat(2, 2, CV_8UC1));
    payload.stamp_ns = 81263511234;
    const Json json = payloadToJson(payload);
    EXPECT_EQ(json, Json::parse(R"({"name":"raw_left","format":"u8_gray","width":2,"height":2,)"
                                R"("bytes":4,"stamp_ns":81263511234})"));
    EXPECT_EQ(payloadFromJson(json)->stamp_ns, 81263511234);
}

TEST(Payload, AnEmptyImageIsNoBytesAndDoesNotAddUp)
{
    const Payload payload = imagePayload("confidence", kFormatConfidence, cv::Mat());
    EXPECT_EQ(payload.width, 0);
    EXPECT_EQ(payload.bytes, 0u);
    EXPECT_FALSE(imagePayloadAddsUp(payload, sizeof(uint8_t)));
}

TEST(Payload, ImageBytesAreRowsWithoutPadding)
{
    cv::Mat whole(4, 6, CV_8UC1);
    for (int row = 0; row < whole.rows; ++row)
        for (int col = 0; col < whole.cols; ++col)
            whole.at<uint8_t>(row, col) = static_cast<uint8_t>(row * 10 + col);
    const cv::Mat region = whole(cv::Rect(1, 1, 3, 2)); // not continuous
    ASSERT_FALSE(region.isContinuous());
    EXPECT_EQ(matBytes(region), 6u);
    std::string out;
    appendMatBytes(out, region);
    EXPECT_EQ(out, std::string({11, 12, 13, 21, 22, 23}));

    out.clear();
    appendMatBytes(out, cv::Mat());
    EXPECT_TRUE(out.empty());
    EXPECT_EQ(matBytes(cv::Mat()), 0u);
}

TEST(Payload, ColourTravelsAsRgbBytes)
{
    // Two BGR pixels a row, the second row padded away by a view.
    cv::Mat bgr(2, 3, CV_8UC3);
    for (int i = 0; i < 6; ++i)
        bgr.at<cv::Vec3b>(i / 3, i % 3) =
            cv::Vec3b(static_cast<uint8_t>(10 * i), static_cast<uint8_t>(10 * i + 1),
                      static_cast<uint8_t>(10 * i + 2));
    const cv::Mat view = bgr(cv::Rect(0, 0, 2, 2));
    std::string bytes = "x";
    appendBgrAsRgb(bytes, view);
    const std::string expected = {'x', 2, 1, 0, 12, 11, 10, 32, 31, 30, 42, 41, 40};
    EXPECT_EQ(bytes, expected);

    const Payload image = colourPayload("left_colour", view);
    EXPECT_EQ(payloadToJson(image), Json::parse(R"({"name":"left_colour","format":"u8_rgb",)"
                                                R"("width":2,"height":2,"bytes":12})"));
    EXPECT_TRUE(colourPayloadAddsUp(image));
    // A grey source: an empty colour image adds up as 0 bytes; a colour that does not
    // fill its size does not.
    EXPECT_TRUE(colourPayloadAddsUp(colourPayload("left_colour", cv::Mat())));
    Payload short_image = image;
    short_image.bytes = 11;
    EXPECT_FALSE(colourPayloadAddsUp(short_image));

    const Payload points = cloudColourPayload(5);
    const Json json = payloadToJson(points);
    EXPECT_EQ(json, Json::parse(R"({"name":"cloud_colour","format":"u8_rgb","points":5,)"
                                R"("bytes":15})"));
    const std::optional<Payload> back = payloadFromJson(json);
    ASSERT_TRUE(back);
    EXPECT_TRUE(back->per_point);
    EXPECT_TRUE(colourPayloadAddsUp(*back));
    Payload wrong = *back;
    wrong.bytes = 16;
    EXPECT_FALSE(colourPayloadAddsUp(wrong));
}

} // namespace
} // namespace stereod
