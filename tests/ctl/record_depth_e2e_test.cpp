// `stereoctl record --with depth,points`: each pair's depth and point cloud in the bag, at
// the pair's stamp, as the service computed them (checked against its snapshot, through
// @mcap/core and @foxglove/rosmsg2-serialization), NaN and no point where the service
// trusts no depth, refused `--with` values, and the bag replays on its image topics. A
// colour recording's clouds carry ROS's packed `rgb`, the colours of the service's own
// cloud_colour.

#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "replay/mcap_recording.hpp"
#include "ros2/messages.hpp"
#include "tests/ctl/record_e2e_fixture.hpp"
#include "tests/support/depth_values.hpp"

namespace stereod {
namespace {

using namespace record_e2e;

// What a bag holds on one topic: per message its log time and its header stamp.
struct TopicStamps {
    std::vector<uint64_t> log_times;
    std::vector<int64_t> header_stamps;
};

std::map<std::string, TopicStamps> stampsByTopic(const std::string& path)
{
    mcap::Reader reader(path);
    std::map<std::string, TopicStamps> topics;
    reader.forEachMessage([&](const mcap::MessageView& message, const mcap::MessageRef&) {
        const std::string& topic = reader.channels().at(message.channel_id).topic;
        int64_t stamp_ns = 0;
        if (topic == kMcapPointsTopic)
            stamp_ns = ros2::parsePointCloud2(message.data).header.stamp.toNs();
        else if (topic.find("camera_info") == std::string::npos)
            stamp_ns = ros2::parseImage(message.data).header.stamp.toNs();
        else
            stamp_ns = ros2::parseCameraInfo(message.data).header.stamp.toNs();
        topics[topic].log_times.push_back(message.log_time_ns);
        topics[topic].header_stamps.push_back(stamp_ns);
    });
    return topics;
}

// The stamp of the bag's first pair whose left image is `left` (grey: the image as the
// bag's reader decodes it to grey; colour: its colour), or 0.
int64_t stampOfPairWithLeft(const std::string& bag, const cv::Mat& left)
{
    mcap::Reader reader(bag);
    for (const McapPair& pair : indexMcapStereo(reader, "", "").pairs) {
        cv::Mat grey, colour;
        std::string why;
        EXPECT_TRUE(decodeMcapImage(reader, pair.left, grey, colour, why)) << why;
        if (sameImage(left.channels() == 3 ? colour : grey, left))
            return pair.left_stamp_ns;
    }
    return 0;
}

// A PointCloud2's fields as rosmsg2-serialization decodes them: `names`, one float32
// (datatype 7) each, one after the other.
Json float32Fields(const std::vector<std::string>& names)
{
    Json fields = Json::array();
    for (std::size_t i = 0; i < names.size(); ++i)
        fields.push_back({{"name", names[i]}, {"offset", 4 * i}, {"datatype", 7}, {"count", 1}});
    return fields;
}

// The results of a recording read by an independent reader, for the pair of a snapshot.
class RecordResultsE2e : public RecordE2e {
  protected:
    // Records 18 pairs (three loops of the six source pairs: the snapshot's pair is among
    // them) `--with` these results into `bag`, and returns what
    // tests/mcap_interop/read_results.mjs (@mcap/core, rosmsg2-serialization) reads there
    // at the stamp of the pair whose left image is `left` (the bag stamps each delivery of
    // a pair anew, with the wall clock), with that stamp as "stamp_ns".
    Json recordResultsOfPair(const std::string& interop, const std::string& with,
                             const std::string& bag, const cv::Mat& left)
    {
        const ProcessResult recorded =
            ctl({"record", "--out", bag, "--frames", "18", "--with", with});
        EXPECT_EQ(recorded.exit_code, 0) << recorded.out << recorded.err;
        const int64_t stamp_ns = stampOfPairWithLeft(bag, left);
        EXPECT_NE(stamp_ns, 0) << "the snapshot's pair is not in the bag";
        if (recorded.exit_code != 0 || stamp_ns == 0)
            return Json::object();
        const ProcessResult node = runProcess(
            {STEREOD_NODE, interop + "/read_results.mjs", bag, std::to_string(stamp_ns)});
        EXPECT_EQ(node.exit_code, 0) << node.err;
        if (node.exit_code != 0)
            return Json::object();
        Json got = Json::parse(node.out);
        got["stamp_ns"] = stamp_ns;
        return got;
    }
};

TEST_F(RecordE2e, DepthAndPointsCarryTheStampsOfTheirPairs)
{
    startService(true);
    const std::string out = dir_.file("depth.mcap");
    const ProcessResult recorded =
        ctl({"record", "--out", out, "--frames", "8", "--with", "depth,points", "--json"});
    ASSERT_EQ(recorded.exit_code, 0) << recorded.out << recorded.err;
    EXPECT_EQ(Json::parse(recorded.out)["pairs"], 8);
    EXPECT_EQ(expectBagOfSourcePairs(out, source_), 8u);

    const auto topics = stampsByTopic(out);
    const TopicStamps& left = topics.at(kMcapLeftImageTopic);
    ASSERT_EQ(left.header_stamps.size(), 8u);
    for (const char* topic : {kMcapDepthTopic, kMcapPointsTopic}) {
        ASSERT_EQ(topics.count(topic), 1u) << topic;
        const TopicStamps& results = topics.at(topic);
        // One depth and one cloud per pair, in the pairs' order, each at its pair's left
        // stamp (header and log time alike).
        EXPECT_EQ(results.header_stamps, left.header_stamps) << topic;
        EXPECT_EQ(results.log_times, left.log_times) << topic;
    }

    // Depths beyond the outputs' cap (output.max_depth_m, by default f*B / 4 px: 2.0 m for
    // this rig) are not in the bag: NaN in the depth, no point.
    const float cap_m = static_cast<float>(kFocalPx * kBaselineM / 4.0);
    const auto within_cap = [cap_m](std::string_view data, std::size_t stride, std::size_t offset) {
        std::size_t beyond = 0, depths = 0;
        for (std::size_t at = offset; at + sizeof(float) <= data.size(); at += stride) {
            float z = 0;
            std::memcpy(&z, data.data() + at, sizeof z);
            depths += std::isfinite(z) ? 1 : 0;
            beyond += std::isfinite(z) && z > cap_m ? 1 : 0;
        }
        EXPECT_GT(depths, 10000u);
        return beyond;
    };
    mcap::Reader reader(out);
    reader.forEachMessage([&](const mcap::MessageView& message, const mcap::MessageRef&) {
        const std::string& topic = reader.channels().at(message.channel_id).topic;
        if (topic == kMcapDepthTopic) {
            const ros2::ImageView depth = ros2::parseImage(message.data);
            EXPECT_EQ(within_cap(depth.data, 4, 0), 0u) << "depths beyond the cap";
            EXPECT_EQ(depth.encoding, "32FC1");
            EXPECT_EQ(depth.width, static_cast<uint32_t>(kSize.width));
            EXPECT_EQ(depth.height, static_cast<uint32_t>(kSize.height));
            EXPECT_EQ(depth.step, 4u * kSize.width);
            EXPECT_EQ(depth.header.frame_id, "stereo_left_optical_frame");
        } else if (topic == kMcapPointsTopic) {
            const ros2::PointCloud2View cloud = ros2::parsePointCloud2(message.data);
            EXPECT_EQ(within_cap(cloud.data, 16, 8), 0u) << "points beyond the cap";
            EXPECT_EQ(cloud.header.frame_id, "stereo_left_optical_frame");
            EXPECT_GT(cloud.width, 1000u);
        }
    });

    // The bag replays: its image topics pair up (depth, an Image too, is no camera), and
    // stereod gives readings from it.
    const McapStereoIndex index = indexMcapStereo(reader, "", "");
    EXPECT_EQ(index.right_topic, kMcapRightImageTopic);
    EXPECT_EQ(index.pairs.size(), 8u);
    EXPECT_EQ(index.unpaired_left + index.unpaired_right, 0u);
    const Replayed replayed = replayOnce(out, "replay");
    EXPECT_EQ(replayed.reading.value("valid", false), true)
        << replayed.reading.dump() << replayed.log;
}

TEST_F(RecordE2e, PairsWithoutTrustedDepthGetNaNDepthAndNoPoints)
{
    // 20 ms between the cameras: every pair is out of sync (source.max_skew_ms 5).
    for (SourcePair& pair : source_)
        pair.right_stamp_ns = pair.left_stamp_ns + 20'000'000;
    startService(true);
    const std::string out = dir_.file("unsynced.mcap");
    const ProcessResult recorded =
        ctl({"record", "--out", out, "--frames", "4", "--with", "depth,points", "--json"});
    ASSERT_EQ(recorded.exit_code, 0) << recorded.out << recorded.err;

    mcap::Reader reader(out);
    std::size_t depths = 0, clouds = 0;
    reader.forEachMessage([&](const mcap::MessageView& message, const mcap::MessageRef&) {
        const std::string& topic = reader.channels().at(message.channel_id).topic;
        if (topic == kMcapDepthTopic) {
            const ros2::ImageView depth = ros2::parseImage(message.data);
            ASSERT_EQ(depth.data.size(), 4u * kSize.area());
            std::size_t numbers = 0;
            for (std::size_t i = 0; i < depth.data.size(); i += 4) {
                float value = 0.0f;
                std::memcpy(&value, depth.data.data() + i, 4);
                numbers += std::isnan(value) ? 0 : 1;
            }
            EXPECT_EQ(numbers, 0u) << "an untrusted pair's depth has numbers";
            ++depths;
        } else if (topic == kMcapPointsTopic) {
            EXPECT_EQ(ros2::parsePointCloud2(message.data).width, 0u);
            ++clouds;
        }
    });
    EXPECT_EQ(depths, 4u);
    EXPECT_EQ(clouds, 4u);
}

TEST_F(RecordE2e, UnknownWithValuesAreRefusedNamingTheAcceptedOnes)
{
    socket_ = dir_.file("none.sock");
    for (const std::vector<std::string>& args :
         {std::vector<std::string>{"--with", "depth,mesh"}, {"--with", "disparity"}}) {
        std::vector<std::string> command = {"record", "--out", dir_.file("x.mcap")};
        command.insert(command.end(), args.begin(), args.end());
        const ProcessResult r = ctl(command);
        EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
        EXPECT_NE(r.err.find("accepted: depth, points"), std::string::npos) << r.err;
        EXPECT_EQ(test::lineCount(r.err), 1u) << r.err;
    }
    const ProcessResult csv = ctl({"record", "--out", dir_.file("dir"), "--with", "depth"});
    EXPECT_EQ(csv.exit_code, 2) << csv.err;
    EXPECT_NE(csv.err.find("FILE.mcap"), std::string::npos) << csv.err;
}

TEST_F(RecordE2e, UncalibratedServiceHasNoDepthToRecord)
{
    startService(false);
    const std::string out = dir_.file("raw.mcap");
    const ProcessResult r = ctl({"record", "--out", out, "--frames", "2", "--with", "depth"});
    EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
    EXPECT_NE(r.err.find("without a calibration"), std::string::npos) << r.err;
    // Without --with it records the raw pairs as before.
    EXPECT_EQ(ctl({"record", "--out", dir_.file("raw2.mcap"), "--frames", "2"}).exit_code, 0);
}

// Through an independent reader: the depth and the cloud in the bag are those the service
// gives in a snapshot of the same pair.
TEST_F(RecordResultsE2e, RecordedDepthAndPointsAreTheSnapshotsThroughRosmsg2Serialization)
{
    const std::string interop = interopScripts();
    if (interop.empty())
        GTEST_SKIP() << "node is not installed";
    ASSERT_FALSE(HasFailure());
    startService(true);

    // The snapshot: a pair's raw left frame (its pixels name the source pair), depth and
    // cloud.
    ProtocolClient client(socket_, 30000ms);
    const Json snapshot = client.request(
        {{"cmd", "snapshot"}, {"items", Json::array({"raw_left", "depth", "cloud"})}});
    ASSERT_EQ(snapshot["ok"], true) << snapshot.dump();
    ASSERT_EQ(snapshot["depth_valid"], true) << snapshot.dump();
    const Json& payloads = snapshot["payloads"];
    const cv::Mat snapshot_left = readGray(client, payloads[0]);
    cv::Mat depth_mm(payloads[1]["height"].get<int>(), payloads[1]["width"].get<int>(), CV_16UC1);
    ASSERT_EQ(payloads[1]["bytes"], depth_mm.total() * 2);
    client.readPayload(depth_mm.data, depth_mm.total() * 2);
    std::vector<float> cloud(payloads[2]["points"].get<std::size_t>() * 4);
    client.readPayload(cloud.data(), cloud.size() * sizeof(float));

    const Json got =
        recordResultsOfPair(interop, "depth,points", dir_.file("results.mcap"), snapshot_left);
    ASSERT_FALSE(HasFailure());
    const int64_t stamp_ns = got["stamp_ns"];
    EXPECT_EQ(got["counts"][kMcapDepthTopic], 18);
    EXPECT_EQ(got["counts"][kMcapPointsTopic], 18);

    const Json& depth = got["depth"];
    ASSERT_TRUE(depth.is_object()) << "no depth at the snapshot's stamp " << stamp_ns;
    // Log times beyond a JavaScript number's exact range come as text.
    const auto text = [](const Json& value) {
        return value.is_string() ? value.get<std::string>() : value.dump();
    };
    EXPECT_EQ(text(depth["logTime"]), std::to_string(stamp_ns));
    const Json& image = depth["message"];
    EXPECT_EQ(image["encoding"], "32FC1");
    EXPECT_EQ(image["width"], depth_mm.cols);
    EXPECT_EQ(image["height"], depth_mm.rows);
    EXPECT_EQ(image["step"], depth_mm.cols * 4);
    EXPECT_EQ(image["is_bigendian"], 0);
    const Json& values = image["data"];
    ASSERT_EQ(values.size(), depth_mm.total());
    const test::DepthAgreement agreement = test::compareDepth(depth_mm, values);
    EXPECT_EQ(agreement.mismatched, 0u);
    EXPECT_GT(agreement.with_depth, depth_mm.total() / 2);

    const Json& points = got["points"];
    ASSERT_TRUE(points.is_object()) << "no points at the snapshot's stamp " << stamp_ns;
    EXPECT_EQ(text(points["logTime"]), std::to_string(stamp_ns));
    const Json& message = points["message"];
    EXPECT_EQ(message["fields"], float32Fields({"x", "y", "z", "intensity"}));
    EXPECT_EQ(message["point_step"], 16);
    EXPECT_EQ(message["height"], 1);
    EXPECT_EQ(message["width"], cloud.size() / 4);
    EXPECT_EQ(message["row_step"], cloud.size() * 4);
    EXPECT_EQ(message["is_dense"], true);
    ASSERT_EQ(message["data"].size(), cloud.size());
    std::size_t differing = 0;
    for (std::size_t i = 0; i < cloud.size(); ++i)
        differing += message["data"][i].get<float>() == cloud[i] ? 0 : 1;
    EXPECT_EQ(differing, 0u) << "of " << cloud.size() / 4 << " points";
}

// A colour recording replayed and recorded with --with points: each cloud in the bag has
// the field `rgb` after x y z intensity, ROS's packing (0x00RRGGBB in a float32's bits),
// read through @mcap/core and rosmsg2-serialization, and its colours are the snapshot's
// cloud_colour for the same pair.
TEST_F(RecordResultsE2e, ColourPairsGiveCloudsWithRosPackedRgb)
{
    const std::string interop = interopScripts();
    if (interop.empty())
        GTEST_SKIP() << "node is not installed";
    ASSERT_FALSE(HasFailure());
    // The source pairs in tsukuba's colours, each darker than the one before.
    const cv::Mat left = cv::imread(kTsukuba + "/im3.png", cv::IMREAD_COLOR);
    const cv::Mat right = cv::imread(kTsukuba + "/im4.png", cv::IMREAD_COLOR);
    ASSERT_EQ(left.type(), CV_8UC3);
    for (int i = 0; i < kSourcePairs; ++i) {
        left.convertTo(source_[i].left, CV_8UC3, 1.0, -3.0 * i);
        right.convertTo(source_[i].right, CV_8UC3, 1.0, -3.0 * i);
    }
    startService(true);

    ProtocolClient client(socket_, 30000ms);
    const Json snapshot =
        client.request({{"cmd", "snapshot"},
                        {"items", Json::array({"raw_left_colour", "cloud", "cloud_colour"})}});
    ASSERT_EQ(snapshot["ok"], true) << snapshot.dump();
    ASSERT_EQ(snapshot["depth_valid"], true) << snapshot.dump();
    const Json& payloads = snapshot["payloads"];
    ASSERT_EQ(payloads[0]["format"], "u8_rgb");
    cv::Mat snapshot_left(kSize, CV_8UC3);
    ASSERT_EQ(payloads[0]["bytes"], snapshot_left.total() * 3);
    client.readPayload(snapshot_left.data, snapshot_left.total() * 3);
    cv::cvtColor(snapshot_left, snapshot_left, cv::COLOR_RGB2BGR);
    std::vector<float> cloud(payloads[1]["points"].get<std::size_t>() * 4);
    client.readPayload(cloud.data(), cloud.size() * sizeof(float));
    const std::size_t points = cloud.size() / 4;
    ASSERT_EQ(payloads[2]["points"], points);
    std::vector<uint8_t> colours(points * 3);
    client.readPayload(colours.data(), colours.size());
    ASSERT_GT(points, 1000u);

    // Recorded as captured (bgr8): the pair is found by its colours.
    const Json got =
        recordResultsOfPair(interop, "points", dir_.file("colour.mcap"), snapshot_left);
    ASSERT_FALSE(HasFailure());
    const int64_t stamp_ns = got["stamp_ns"];
    EXPECT_EQ(got["counts"][kMcapPointsTopic], 18);
    const Json& message = got["points"]["message"];
    ASSERT_TRUE(message.is_object()) << "no points at the snapshot's stamp " << stamp_ns;
    EXPECT_EQ(message["fields"], float32Fields({"x", "y", "z", "intensity", "rgb"}));
    EXPECT_EQ(message["point_step"], 20);
    EXPECT_EQ(message["width"], points);
    EXPECT_EQ(message["row_step"], points * 20);
    ASSERT_EQ(message["data"].size(), points * 5);
    ASSERT_EQ(message["rgb"].size(), points);
    std::size_t other_points = 0, other_colours = 0, grey_colours = 0;
    for (std::size_t i = 0; i < points; ++i) {
        for (std::size_t k = 0; k < 4; ++k)
            other_points += message["data"][5 * i + k].get<float>() == cloud[4 * i + k] ? 0 : 1;
        const uint8_t* rgb = &colours[3 * i];
        const uint32_t packed = (uint32_t{rgb[0]} << 16) | (uint32_t{rgb[1]} << 8) | rgb[2];
        other_colours += message["rgb"][i].get<uint32_t>() == packed ? 0 : 1;
        grey_colours += rgb[0] == rgb[1] && rgb[1] == rgb[2] ? 1 : 0;
    }
    EXPECT_EQ(other_points, 0u) << "of " << points << " points";
    EXPECT_EQ(other_colours, 0u) << "of " << points << " points";
    // Tsukuba in colour: a cloud of grey points would be a grey recording.
    EXPECT_LT(grey_colours, points / 10);
}

} // namespace
} // namespace stereod
