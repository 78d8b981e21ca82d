// The bag writer's depth and points (McapRecordingWriter::writeDepth/writePoints/
// writeColouredPoints), read back with our reader: 32FC1 with NaN where the pipeline has
// 0, the cloud's fields and layout (with `rgb` for a coloured one), the pair's sequence
// and stamps, and what is refused.

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "replay/mcap_recording.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

// Every message of the bag by topic, with its sequence and log time.
struct Message {
    uint32_t sequence = 0;
    uint64_t log_time_ns = 0;
    std::string data;
};

std::map<std::string, std::vector<Message>> messagesByTopic(const std::string& path)
{
    mcap::Reader reader(path);
    std::map<std::string, std::vector<Message>> topics;
    for (const auto& [id, channel] : reader.channels())
        topics[channel.topic];
    reader.forEachMessage([&](const mcap::MessageView& m, const mcap::MessageRef&) {
        topics[reader.channels().at(m.channel_id).topic].push_back(
            {m.sequence, m.log_time_ns, std::string(m.data)});
    });
    return topics;
}

// The cloud's fields are `names`, one float32 each, one after the other.
void expectFloat32Fields(const ros2::PointCloud2View& points, const std::vector<std::string>& names)
{
    ASSERT_EQ(points.fields.size(), names.size());
    for (std::size_t i = 0; i < names.size(); ++i) {
        EXPECT_EQ(points.fields[i].name, names[i]);
        EXPECT_EQ(points.fields[i].offset, 4 * i);
        EXPECT_EQ(points.fields[i].datatype, ros2::PointField::FLOAT32);
        EXPECT_EQ(points.fields[i].count, 1u);
    }
}

TEST(McapRecordingResults, DepthAndPointsBesideTheirPair)
{
    test::TempDir dir;
    const std::string path = dir.file("results.mcap");
    const cv::Mat left(4, 6, CV_8UC1, cv::Scalar(10));
    const cv::Mat right(4, 6, CV_8UC1, cv::Scalar(20));
    cv::Mat depth(4, 6, CV_32FC1, cv::Scalar(1.5f));
    depth.at<float>(1, 2) = 0.0f; // no depth there
    const std::vector<float> cloud = {0.1f, -0.2f, 1.5f, 10.0f, 0.3f, 0.4f, 2.5f, 200.0f};
    {
        McapRecordingWriter writer(path);
        writer.enableDepth();
        writer.enablePoints();
        for (int64_t k = 0; k < 2; ++k) {
            const int64_t stamp_ns = 5'000'000'000 + k * 100'000'000;
            writer.write(left, right, stamp_ns, stamp_ns + 7);
            writer.writeDepth(depth, stamp_ns);
            writer.writePoints(cloud.data(), k == 0 ? 2 : 0, stamp_ns);
        }
        writer.close();
    }
    const auto topics = messagesByTopic(path);
    ASSERT_EQ(topics.at(kMcapDepthTopic).size(), 2u);
    ASSERT_EQ(topics.at(kMcapPointsTopic).size(), 2u);
    for (std::size_t k = 0; k < 2; ++k) {
        const Message& image = topics.at(kMcapLeftImageTopic)[k];
        for (const char* topic : {kMcapDepthTopic, kMcapPointsTopic}) {
            const Message& m = topics.at(topic)[k];
            EXPECT_EQ(m.sequence, image.sequence) << topic;
            EXPECT_EQ(m.log_time_ns, image.log_time_ns) << topic;
        }
    }

    const ros2::ImageView image = ros2::parseImage(topics.at(kMcapDepthTopic)[0].data);
    EXPECT_EQ(image.encoding, "32FC1");
    EXPECT_EQ(image.width, 6u);
    EXPECT_EQ(image.height, 4u);
    EXPECT_EQ(image.step, 24u);
    EXPECT_EQ(image.is_bigendian, 0);
    EXPECT_EQ(image.header.frame_id, "stereo_left_optical_frame");
    EXPECT_EQ(image.header.stamp.toNs(), 5'000'000'000);
    ASSERT_EQ(image.data.size(), 4u * 24u);
    std::vector<float> values(24);
    std::memcpy(values.data(), image.data.data(), image.data.size());
    for (int i = 0; i < 24; ++i) {
        if (i == 1 * 6 + 2)
            EXPECT_TRUE(std::isnan(values[i])) << "0 must become NaN";
        else
            EXPECT_EQ(values[i], 1.5f) << i;
    }

    const ros2::PointCloud2View points =
        ros2::parsePointCloud2(topics.at(kMcapPointsTopic)[0].data);
    EXPECT_EQ(points.header.frame_id, "stereo_left_optical_frame");
    EXPECT_EQ(points.height, 1u);
    EXPECT_EQ(points.width, 2u);
    EXPECT_EQ(points.point_step, 16u);
    EXPECT_EQ(points.row_step, 32u);
    EXPECT_TRUE(points.is_dense);
    expectFloat32Fields(points, {"x", "y", "z", "intensity"});
    ASSERT_EQ(points.data.size(), cloud.size() * sizeof(float));
    EXPECT_EQ(std::memcmp(points.data.data(), cloud.data(), points.data.size()), 0);
    EXPECT_EQ(ros2::parsePointCloud2(topics.at(kMcapPointsTopic)[1].data).width, 0u);
}

TEST(McapRecordingResults, ColouredPointsHaveTheRgbFieldAfterIntensity)
{
    test::TempDir dir;
    const std::string path = dir.file("coloured.mcap");
    const cv::Mat image(4, 6, CV_8UC1, cv::Scalar(10));
    // Two points, their colours packed as ROS packs them: 0x00RRGGBB in a float's bits.
    std::vector<float> cloud = {0.1f, -0.2f, 1.5f, 10.0f, 0.0f, 0.3f, 0.4f, 2.5f, 200.0f, 0.0f};
    const uint32_t colours[2] = {0x00ff8001, 0x0000ff00};
    std::memcpy(&cloud[4], &colours[0], 4);
    std::memcpy(&cloud[9], &colours[1], 4);
    {
        McapRecordingWriter writer(path);
        writer.enablePoints();
        writer.write(image, image, 1, 2);
        writer.writeColouredPoints(cloud.data(), 2, 1);
        writer.close();
    }
    // The view points into the message's bytes: they must outlive it.
    const auto topics = messagesByTopic(path);
    const ros2::PointCloud2View points =
        ros2::parsePointCloud2(topics.at(kMcapPointsTopic).at(0).data);
    EXPECT_EQ(points.width, 2u);
    EXPECT_EQ(points.point_step, 20u);
    EXPECT_EQ(points.row_step, 40u);
    expectFloat32Fields(points, {"x", "y", "z", "intensity", "rgb"});
    ASSERT_EQ(points.data.size(), cloud.size() * sizeof(float));
    EXPECT_EQ(std::memcmp(points.data.data(), cloud.data(), points.data.size()), 0);
}

TEST(McapRecordingResults, ChannelsOnlyWhenEnabledAndWrongInputRefused)
{
    test::TempDir dir;
    const cv::Mat image(4, 6, CV_8UC1, cv::Scalar(10));
    {
        McapRecordingWriter writer(dir.file("plain.mcap"));
        writer.write(image, image, 1, 2);
        EXPECT_THROW(writer.writeDepth(cv::Mat(4, 6, CV_32FC1, cv::Scalar(1.0f)), 1),
                     mcap::McapError);
        const float point[4] = {0, 0, 1, 0};
        EXPECT_THROW(writer.writePoints(point, 1, 1), mcap::McapError);
        const float coloured[5] = {0, 0, 1, 0, 0};
        EXPECT_THROW(writer.writeColouredPoints(coloured, 1, 1), mcap::McapError);
        writer.close();
    }
    const auto plain = messagesByTopic(dir.file("plain.mcap"));
    EXPECT_EQ(plain.count(kMcapDepthTopic), 0u);
    EXPECT_EQ(plain.count(kMcapPointsTopic), 0u);

    {
        // Enabled, the channels are listed even before any message.
        McapRecordingWriter writer(dir.file("enabled.mcap"));
        writer.enableDepth();
        writer.enablePoints();
        EXPECT_THROW(writer.writeDepth(cv::Mat(4, 6, CV_16UC1), 1), mcap::McapError);
        writer.close();
    }
    const auto enabled = messagesByTopic(dir.file("enabled.mcap"));
    EXPECT_EQ(enabled.at(kMcapDepthTopic).size(), 0u);
    EXPECT_EQ(enabled.at(kMcapPointsTopic).size(), 0u);
}

} // namespace
} // namespace stereod
