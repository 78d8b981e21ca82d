// The event lines of subscriptions: reading, depth and raw headers, one line each.

#include <string>

#include <gtest/gtest.h>

#include "protocol/events.hpp"
#include "tests/protocol/sample_reading.hpp"

namespace stereod {
namespace {

TEST(ProtocolEvents, ReadingEventIsOneLine)
{
    ReadingReport report;
    report.reading = sampleValidReading();
    std::string line;
    appendReadingEvent(line, report, report.reading.stamp_ns, 0);
    EXPECT_EQ(line.find('\n'), line.size() - 1);
    const Json event = Json::parse(line);
    EXPECT_EQ(event["event"], "reading");
    EXPECT_FALSE(event.contains("skipped"));
    EXPECT_EQ(event["reading"]["frame"], 118);

    line.clear();
    appendReadingEvent(line, report, report.reading.stamp_ns, 3);
    EXPECT_EQ(Json::parse(line)["skipped"], 3);
}

TEST(ProtocolEvents, DepthEventHeaderGivesThePayloadSize)
{
    ReadingReport report;
    report.reading = sampleValidReading();
    DepthEventHeader header;
    header.frame = 118;
    header.stamp_ns = report.reading.stamp_ns;
    header.width = 1282;
    header.height = 1110;
    header.bytes = 1282u * 1110u * 2u;
    std::string line;
    appendDepthEventHeader(line, header, report, report.reading.stamp_ns, 2);
    const Json event = Json::parse(line);
    EXPECT_EQ(event["event"], "depth");
    EXPECT_EQ(event["format"], "u16_mm");
    EXPECT_EQ(event["width"], 1282);
    EXPECT_EQ(event["height"], 1110);
    EXPECT_EQ(event["bytes"], 2846040);
    EXPECT_EQ(event["skipped"], 2);
    EXPECT_EQ(event["reading"]["valid"], true);
}

TEST(ProtocolEvents, RawEventHeaderFollowsTheContract)
{
    RawEventHeader header;
    header.frame = 42;
    header.left_stamp_ns = 81263511234;
    header.right_stamp_ns = 81263512001;
    header.width = 640;
    header.height = 480;
    std::string out;
    appendRawEventHeader(out, header, 3);
    ASSERT_EQ(out.back(), '\n');
    EXPECT_EQ(out.find('\n'), out.size() - 1);
    Json event = Json::parse(out);
    EXPECT_EQ(event["event"], "raw");
    EXPECT_EQ(event["frame"], 42);
    EXPECT_EQ(event["left_stamp_ns"], 81263511234);
    EXPECT_EQ(event["right_stamp_ns"], 81263512001);
    EXPECT_EQ(event["skipped"], 3);
    ASSERT_EQ(event["payloads"].size(), 2u);
    EXPECT_EQ(event["payloads"][0],
              Json::parse(R"({"name":"raw_left","format":"u8_gray","width":640,"height":480,)"
                          R"("bytes":307200,"stamp_ns":81263511234})"));
    EXPECT_EQ(event["payloads"][1]["name"], "raw_right");
    EXPECT_EQ(event["payloads"][1]["stamp_ns"], 81263512001);
    EXPECT_EQ(event["payloads"][1]["bytes"], 307200);
    EXPECT_FALSE(event.contains("depth_valid"));

    // With the pair's depth and cloud: their descriptors after the two frames.
    header.depth_valid = true;
    header.depth_width = 620;
    header.depth_height = 470;
    header.cloud_points = 1000;
    out.clear();
    appendRawEventHeader(out, header, 0, true, true);
    event = Json::parse(out);
    EXPECT_EQ(event["depth_valid"], true);
    ASSERT_EQ(event["payloads"].size(), 4u);
    EXPECT_EQ(event["payloads"][2],
              Json::parse(R"({"name":"depth","format":"f32_m","width":620,"height":470,)"
                          R"("bytes":1165600})"));
    EXPECT_EQ(event["payloads"][3],
              Json::parse(R"({"name":"cloud","format":"f32_xyzi","points":1000,"bytes":16000})"));

    // With colour: the frames' colour right after them (a grey right camera: 0 x 0), and
    // the cloud's after the cloud.
    header.left_colour_width = 640;
    header.left_colour_height = 480;
    header.cloud_colour_points = 1000;
    out.clear();
    appendRawEventHeader(out, header, 0, true, true, true);
    event = Json::parse(out);
    ASSERT_EQ(event["payloads"].size(), 7u);
    EXPECT_EQ(event["payloads"][2],
              Json::parse(R"({"name":"raw_left_colour","format":"u8_rgb","width":640,)"
                          R"("height":480,"bytes":921600,"stamp_ns":81263511234})"));
    EXPECT_EQ(event["payloads"][3],
              Json::parse(R"({"name":"raw_right_colour","format":"u8_rgb","width":0,)"
                          R"("height":0,"bytes":0,"stamp_ns":81263512001})"));
    EXPECT_EQ(event["payloads"][4]["name"], "depth");
    EXPECT_EQ(event["payloads"][5]["name"], "cloud");
    EXPECT_EQ(event["payloads"][6],
              Json::parse(R"({"name":"cloud_colour","format":"u8_rgb","points":1000,)"
                          R"("bytes":3000})"));
    // Colour without the cloud: no cloud colours either.
    out.clear();
    appendRawEventHeader(out, header, 0, false, false, true);
    event = Json::parse(out);
    ASSERT_EQ(event["payloads"].size(), 4u);
    EXPECT_EQ(event["payloads"][3]["name"], "raw_right_colour");
}

} // namespace
} // namespace stereod
