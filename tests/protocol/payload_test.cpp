// The binary payloads' descriptors as the service writes them and a client reads them
// back, and the checks a client makes before reading. The images' descriptors and bytes,
// which need OpenCV, are tested with their code (tests/daemon/image_payload_test.cpp).

#include <cstdint>
#include <string>

#include <gtest/gtest.h>

#include "protocol/payload.hpp"

namespace stereod {
namespace {

TEST(Payload, CloudIsSixteenBytesAPoint)
{
    const Payload payload = cloudPayload(5);
    EXPECT_EQ(payloadToJson(payload),
              Json::parse(R"({"name":"cloud","format":"f32_xyzi","points":5,"bytes":80})"));
    EXPECT_TRUE(cloudPayloadAddsUp(payload));
    Payload wrong = payload;
    wrong.bytes = 79;
    EXPECT_FALSE(cloudPayloadAddsUp(wrong));
}

TEST(Payload, BytesThatAreNotACountAreRefused)
{
    EXPECT_EQ(payloadBytesFromJson(Json::object()), 0u);
    EXPECT_EQ(payloadBytesFromJson(Json{{"bytes", 12}}), 12u);
    EXPECT_FALSE(payloadBytesFromJson(Json{{"bytes", -1}}));
    EXPECT_FALSE(payloadBytesFromJson(Json{{"bytes", 1.5}}));
    EXPECT_FALSE(payloadBytesFromJson(Json{{"bytes", "12"}}));
    EXPECT_FALSE(payloadFromJson(Json{{"name", "depth"}, {"bytes", -1}}));
}

} // namespace
} // namespace stereod
