// ROS 2 CDR messages: byte layout checked by hand for a small Image, round trips of every
// type, refusal of damaged and foreign payloads. The independent decoder
// (@foxglove/rosmsg2-serialization) checks the same in tests/mcap_interop.

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ros2/messages.hpp"

namespace stereod::ros2 {
namespace {

TEST(Ros2Messages, ImageBytesAreXcdr1LittleEndian)
{
    const uint8_t pixels[6] = {1, 2, 3, 4, 5, 6};
    std::string out;
    serializeImage(Header{Time{7, 9}, "cam"}, 2, 3, "mono8", 3, pixels, 6, out);
    const std::string expected = std::string("\x00\x01\x00\x00" // encapsulation: CDR little-endian
                                             "\x07\x00\x00\x00" // stamp.sec
                                             "\x09\x00\x00\x00" // stamp.nanosec
                                             "\x04\x00\x00\x00"
                                             "cam\x00"          // frame_id, length with NUL
                                             "\x02\x00\x00\x00" // height
                                             "\x03\x00\x00\x00" // width
                                             "\x06\x00\x00\x00"
                                             "mono8\x00"
                                             "\x00"             // is_bigendian
                                             "\x00"             // padding: step is aligned to 4
                                             "\x03\x00\x00\x00" // step
                                             "\x06\x00\x00\x00" // data length
                                             "\x01\x02\x03\x04\x05\x06",
                                             54);
    EXPECT_EQ(out, expected);
    const ImageView back = parseImage(out);
    EXPECT_EQ(back.header.stamp.sec, 7);
    EXPECT_EQ(back.header.frame_id, "cam");
    EXPECT_EQ(back.encoding, "mono8");
    EXPECT_EQ(back.step, 3u);
    EXPECT_EQ(back.data, std::string_view("\x01\x02\x03\x04\x05\x06", 6));
}

TEST(Ros2Messages, TimeFromNanoseconds)
{
    EXPECT_EQ(Time::fromNs(1'500'000'001).sec, 1);
    EXPECT_EQ(Time::fromNs(1'500'000'001).nanosec, 500'000'001u);
    EXPECT_EQ(Time::fromNs(-1).sec, -1);
    EXPECT_EQ(Time::fromNs(-1).nanosec, 999'999'999u);
    EXPECT_EQ(Time::fromNs(123'456'789'012).toNs(), 123'456'789'012);
}

TEST(Ros2Messages, CameraInfoRoundTrip)
{
    CameraInfo info;
    info.header = Header{Time{100, 5}, "stereo_right_optical_frame"};
    info.height = 480;
    info.width = 640;
    info.distortion_model = "plumb_bob";
    info.d = {-0.28, 0.07, 0.001, -0.0002, 0.0};
    info.k = {530.1, 0, 320.5, 0, 531.2, 240.25, 0, 0, 1};
    info.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    info.p = {515.4, 0, 310, -515.4 * 0.0832, 0, 515.4, 245, 0, 0, 0, 1, 0};
    info.roi.do_rectify = true;
    std::string out;
    serializeCameraInfo(info, out);
    const CameraInfo back = parseCameraInfo(out);
    EXPECT_EQ(back.header.frame_id, info.header.frame_id);
    EXPECT_EQ(back.distortion_model, "plumb_bob");
    EXPECT_EQ(back.d, info.d);
    EXPECT_EQ(back.k, info.k);
    EXPECT_EQ(back.p, info.p);
    EXPECT_TRUE(back.roi.do_rectify);
    // Every cut of the message is refused, never read past.
    for (std::size_t n = 0; n < out.size(); ++n) {
        EXPECT_THROW(parseCameraInfo(std::string_view(out).substr(0, n)), CdrError) << n;
    }
}

TEST(Ros2Messages, PointCloud2RoundTrip)
{
    const std::vector<PointField> fields = {{"x", 0, PointField::FLOAT32, 1},
                                            {"y", 4, PointField::FLOAT32, 1},
                                            {"z", 8, PointField::FLOAT32, 1},
                                            {"intensity", 12, PointField::FLOAT32, 1}};
    const std::vector<float> points = {1, 2, 3, 4, 5, 6, 7, 8};
    std::string out;
    serializePointCloud2(Header{Time{1, 2}, "left"}, 1, 2, fields, 16, 32, points.data(),
                         points.size() * sizeof(float), true, out);
    const PointCloud2View back = parsePointCloud2(out);
    ASSERT_EQ(back.fields.size(), 4u);
    EXPECT_EQ(back.fields[3].name, "intensity");
    EXPECT_EQ(back.fields[3].offset, 12u);
    EXPECT_EQ(back.point_step, 16u);
    EXPECT_EQ(back.data.size(), 32u);
    EXPECT_TRUE(back.is_dense);
}

TEST(Ros2Messages, RefusesForeignAndShortPayloads)
{
    std::string out;
    const uint8_t pixels[4] = {};
    serializeImage(Header{}, 2, 2, "mono8", 2, pixels, 4, out);
    std::string big_endian = out;
    big_endian[1] = 0x00;
    EXPECT_THROW(parseImage(big_endian), CdrError);
    std::string xcdr2 = out;
    xcdr2[1] = 0x07;
    EXPECT_THROW(parseImage(xcdr2), CdrError);
    // An image whose data are shorter than step x height.
    serializeImage(Header{}, 3, 2, "mono8", 2, pixels, 4, out);
    EXPECT_THROW(parseImage(out), CdrError);
}

TEST(Ros2Messages, SchemaTextsCarryTheirDependencies)
{
    const std::string sep(80, '=');
    EXPECT_EQ(imageSchemaText().rfind("std_msgs/Header header\n", 0), 0u);
    EXPECT_NE(imageSchemaText().find(sep + "\nMSG: std_msgs/Header\n"), std::string::npos);
    EXPECT_NE(imageSchemaText().find(sep + "\nMSG: builtin_interfaces/Time\n"), std::string::npos);
    EXPECT_NE(cameraInfoSchemaText().find("MSG: sensor_msgs/RegionOfInterest\n"),
              std::string::npos);
    EXPECT_NE(pointCloud2SchemaText().find("MSG: sensor_msgs/PointField\n"), std::string::npos);
}

} // namespace
} // namespace stereod::ros2
