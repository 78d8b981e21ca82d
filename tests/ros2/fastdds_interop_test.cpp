// stereod as a ROS 2 node, seen by an implementation nobody here wrote: a replaying
// `stereod` publishes over Cyclone DDS on the loopback interface, and a subscriber built
// from eProsima Fast DDS with fastddsgen's types (tests/ros2/fastdds_subscriber.cpp)
// discovers every topic with its ROS 2 type and decodes each message. What it decodes is
// held to the service's own snapshot, `stereoctl distance --json` and the configured pose.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "ctl/client.hpp"
#include "ros2/camera_frames.hpp"
#include "tests/daemon/live_view_service.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/dds_domain.hpp"
#include "tests/support/depth_values.hpp"
#include "tests/support/process.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;
using test::ProcessResult;
using test::runProcess;

// The replaying service of the live view's tests (Tsukuba, three identical pairs, so every
// frame's depth and reading are the same), with ROS 2 on in a domain no other running test holds.
class Ros2Interop : public test::LiveViewE2e {
  protected:
    void SetUp() override
    {
        LiveViewE2e::SetUp();
        ::setenv("ROS_DOMAIN_ID", domain_.text().c_str(), 1);
    }

    void startRos2Service(const std::string& extra_yaml = {})
    {
        const std::string config = dir_.file("ros2.yaml");
        std::ofstream(config) << "ros2:\n  enabled: true\n  namespace: /stereo\n"
                              << "robot:\n  camera_pose:\n    translation_m: [0.2, 0.05, 0.5]\n"
                              << "    rpy_deg: [0, 15, -10]\n"
                              << extra_yaml;
        startService("off", config);
    }

    Json subscribe(int min_each)
    {
        const ProcessResult sub = runProcess({STEREOD_FASTDDS_SUBSCRIBER, domain_.text(), "/stereo",
                                              "60", std::to_string(min_each)});
        EXPECT_EQ(sub.exit_code, 0) << sub.err;
        return Json::parse(sub.out);
    }

    test::DdsDomainLease domain_;
};

TEST_F(Ros2Interop, FastDdsSubscriberGetsEveryTopicAndTheServicesOwnValues)
{
    startRos2Service();
    ASSERT_FALSE(HasFailure());
    const Json got = subscribe(5);
    const Json& topics = got["topics"];

    // Every topic found by its ROS 2 type name (a reader matches only a writer of its own
    // type), and at least five messages of each decoded (/tf_static: the one).
    const std::map<std::string, std::string> expected = {
        {"rt/stereo/left/image_rect", "sensor_msgs::msg::dds_::Image_"},
        {"rt/stereo/depth", "sensor_msgs::msg::dds_::Image_"},
        {"rt/stereo/disparity", "stereo_msgs::msg::dds_::DisparityImage_"},
        {"rt/stereo/points", "sensor_msgs::msg::dds_::PointCloud2_"},
        {"rt/stereo/left/camera_info", "sensor_msgs::msg::dds_::CameraInfo_"},
        {"rt/stereo/right/camera_info", "sensor_msgs::msg::dds_::CameraInfo_"},
        {"rt/stereo/nearest", "sensor_msgs::msg::dds_::Range_"},
        {"rt/stereo/reading", "std_msgs::msg::dds_::String_"},
        {"rt/tf_static", "tf2_msgs::msg::dds_::TFMessage_"},
        {"ros_discovery_info", "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"}};
    ASSERT_EQ(topics.size(), expected.size()) << topics.dump();
    for (const auto& [name, type] : expected) {
        ASSERT_TRUE(topics.contains(name)) << name;
        EXPECT_EQ(topics[name]["type"], type);
        EXPECT_GE(topics[name]["matched"].get<int>(), 1) << name;
        const bool once = name == "rt/tf_static" || name == "ros_discovery_info";
        EXPECT_GE(topics[name]["count"].get<int>(), once ? 1 : 5) << name;
    }

    // Depth: 32FC1 metres, NaN where none (REP 118), within 1 mm of the service's snapshot.
    const Json& depth = topics["rt/stereo/depth"]["last"];
    EXPECT_EQ(depth["encoding"], "32FC1");
    EXPECT_EQ(depth["width"], 384);
    EXPECT_EQ(depth["height"], 288);
    EXPECT_EQ(depth["step"], 384 * 4);
    EXPECT_EQ(depth["header"]["frame_id"], "stereo_left_optical_frame");
    const cv::Mat depth_mm = snapshotDepthMm(cv::Size(384, 288));
    ASSERT_FALSE(HasFailure());
    const test::DepthAgreement agreement = test::compareDepth(depth_mm, depth["data"]);
    EXPECT_EQ(agreement.mismatched, 0u);
    EXPECT_GT(agreement.with_depth, depth_mm.total() / 2);

    // Stamps: wall time (ROS 2's clock), within a minute of now.
    const int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
    EXPECT_LT(std::abs(now_ns - depth["header"]["stamp_ns"].get<int64_t>()), 60'000'000'000);

    // The Range: every one equal to `stereoctl distance` (the same scene each frame), which
    // gives metres to 0.1 mm; the Range is a float.
    const ProcessResult distance =
        runProcess({test::stereoctlPath(), "--socket", socket_, "distance", "--json"});
    ASSERT_EQ(distance.exit_code, 0) << distance.err;
    const Json reading = Json::parse(distance.out);
    ASSERT_EQ(reading["valid"], true) << reading.dump();
    const Json& ranges = topics["rt/stereo/nearest"]["last"];
    ASSERT_GE(ranges.size(), 5u);
    for (const Json& range : ranges) {
        ASSERT_TRUE(range["range"].is_number()) << range.dump();
        EXPECT_NEAR(range["range"].get<double>(), reading["distance_m"].get<double>(),
                    0.5e-4 + 1e-6);
        EXPECT_EQ(range["radiation_type"], 1);
        EXPECT_EQ(range["header"]["frame_id"], "stereo_left_optical_frame");
        EXPECT_GT(range["min_range"].get<double>(), 0.0);
        EXPECT_EQ(range["max_range"], 20.0);
        // The default region, the middle half of 384 px at Tsukuba's focal length.
        EXPECT_NEAR(range["field_of_view"].get<double>(),
                    2.0 * std::atan(96.0 / test::kTsukubaFocalPx), 1e-5);
    }
    // The full reading as JSON, the protocol's reading object.
    for (const Json& text : topics["rt/stereo/reading"]["last"]) {
        const Json object = Json::parse(text.get<std::string>());
        EXPECT_EQ(object["valid"], true);
        EXPECT_NEAR(object["distance_m"].get<double>(), reading["distance_m"].get<double>(), 1e-9);
    }

    // camera_info of the rectified pair (REP 104), as the calibration says.
    const Json& left = topics["rt/stereo/left/camera_info"]["last"];
    const Json& right = topics["rt/stereo/right/camera_info"]["last"];
    EXPECT_EQ(left["header"]["frame_id"], "stereo_left_optical_frame");
    EXPECT_EQ(right["header"]["frame_id"], "stereo_right_optical_frame");
    EXPECT_DOUBLE_EQ(left["k"][0].get<double>(), test::kTsukubaFocalPx);
    EXPECT_NEAR(right["p"][3].get<double>(), -test::kTsukubaFocalPx * test::kTsukubaBaselineM,
                1e-9);
    const Json& disparity = topics["rt/stereo/disparity"]["last"];
    EXPECT_FLOAT_EQ(disparity["f"].get<float>(), static_cast<float>(test::kTsukubaFocalPx));
    EXPECT_EQ(disparity["image"]["encoding"], "32FC1");
    // The replayed Tsukuba left image is in colour: rgb8, and a cloud with PCL's packed rgb.
    const Json& image = topics["rt/stereo/left/image_rect"]["last"];
    EXPECT_EQ(image["encoding"], "rgb8");
    EXPECT_EQ(image["step"], 384 * 3);
    EXPECT_EQ(image["bytes"], 384 * 288 * 3);
    const Json& points = topics["rt/stereo/points"]["last"];
    EXPECT_EQ(points["point_step"], 20);
    ASSERT_EQ(points["fields"].size(), 5u);
    EXPECT_EQ(points["fields"][4]["name"], "rgb");
    EXPECT_EQ(points["fields"][4]["offset"], 16);
    EXPECT_EQ(points["fields"][4]["datatype"], 7); // FLOAT32, as PCL packs it
    EXPECT_GT(points["width"].get<int>(), 1000);
    EXPECT_EQ(points["bytes"], points["width"].get<int>() * 20);

    // /tf_static: base_link -> stereo_link at the configured pose -> the optical frames.
    const Json& tf = topics["rt/tf_static"]["last"];
    ASSERT_EQ(tf.size(), 3u) << tf.dump();
    EXPECT_EQ(tf[0]["parent"], "base_link");
    EXPECT_EQ(tf[0]["child"], "stereo_link");
    EXPECT_EQ(tf[0]["translation"], Json::array({0.2, 0.05, 0.5}));
    const auto q = ros2::quaternionFromRpyDeg({0.0, 15.0, -10.0});
    for (int i = 0; i < 4; ++i)
        EXPECT_NEAR(tf[0]["rotation"][i].get<double>(), q[i], 1e-12);
    EXPECT_EQ(tf[1]["child"], "stereo_left_optical_frame");
    EXPECT_EQ(tf[2]["child"], "stereo_right_optical_frame");
    EXPECT_NEAR(tf[2]["translation"][1].get<double>(), -test::kTsukubaBaselineM, 1e-12);

    // ros_discovery_info: the participant holds the node /stereo/stereod (`ros2 node list`),
    // whose writers are those the subscriber got each topic from, by GUID. A replay has
    // no subscriptions: one participant announces.
    const Json& samples = topics["ros_discovery_info"]["last"];
    ASSERT_EQ(samples.size(), 1u) << samples.dump();
    const Json& graph = samples[0];
    ASSERT_EQ(graph["nodes"].size(), 1u) << graph.dump();
    const Json& node = graph["nodes"][0];
    EXPECT_EQ(node["namespace"], "/stereo");
    EXPECT_EQ(node["name"], "stereod");
    EXPECT_TRUE(node["readers"].empty());
    EXPECT_EQ(node["writers"].size(), expected.size() - 1);
    const std::string gid = graph["gid"];
    ASSERT_EQ(gid.size(), 32u);
    // The participant's GUID: its prefix, and the participant's entity id 0x000001c1.
    EXPECT_EQ(gid.substr(24), "000001c1");
    for (const auto& [name, type] : expected) {
        if (name == "ros_discovery_info")
            continue;
        const Json& writers = topics[name]["writers"];
        ASSERT_EQ(writers.size(), 1u) << name << ": " << writers.dump();
        const std::string writer = writers[0];
        EXPECT_EQ(writer.substr(0, 24), gid.substr(0, 24)) << name;
        EXPECT_NE(std::find(node["writers"].begin(), node["writers"].end(), Json(writer)),
                  node["writers"].end())
            << name << ": " << writer << " not in " << node["writers"].dump();
    }

    // The service's own count of what went out.
    const Json ros2 = status()["ros2"];
    EXPECT_EQ(ros2["publishing"], true) << ros2.dump();
    EXPECT_EQ(ros2["domain_id"], domain_.id());
    EXPECT_EQ(ros2["localhost_only"], true);
    EXPECT_GT(ros2["messages"].get<int>(), 5 * 8);
    EXPECT_EQ(ros2["write_errors"], 0);
}

} // namespace
} // namespace stereod
