// The live view against real clients: Foxglove's own WebSocket client and ROS 2 CDR
// reader (tests/live_view/client.mjs, node) connect to a replaying `stereod`, and what
// they decode is held to the service's own snapshot and `stereoctl distance --json`.
// Also: a port already taken leaves the service running without the live view, and the
// HTTP side refuses what it does not serve.
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <string>
#include <thread>

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <sys/socket.h>
#include <unistd.h>

#include "base/unique_fd.hpp"
#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "tests/daemon/live_view_service.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/depth_values.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;
using test::freePort;
using test::httpExchange;
using test::httpGet;
using test::kClientScripts;
using test::LiveViewE2e;
using test::ProcessResult;
using test::runProcess;

TEST_F(LiveViewE2e, FoxgloveClientGetsEveryChannelAndTheServicesOwnValues)
{
    if (std::string(STEREOD_NODE).empty())
        GTEST_SKIP() << "node is not installed";
    ASSERT_TRUE(std::filesystem::exists(kClientScripts + "/node_modules/@foxglove/ws-protocol"))
        << "the live view's client packages are missing: run scripts/setup-node.sh";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port));
    ASSERT_FALSE(HasFailure());

    const ProcessResult node = runProcess({STEREOD_NODE, kClientScripts + "/client.mjs",
                                           "ws://127.0.0.1:" + std::to_string(port), "4"});
    ASSERT_EQ(node.exit_code, 0) << node.err;
    const Json got = Json::parse(node.out);

    // Every channel, with its schema.
    const std::map<std::string, std::pair<std::string, std::string>> expected = {
        {"/stereo/left/image_rect", {"cdr", "sensor_msgs/msg/Image"}},
        {"/stereo/depth", {"cdr", "sensor_msgs/msg/Image"}},
        {"/stereo/disparity", {"cdr", "stereo_msgs/msg/DisparityImage"}},
        {"/stereo/confidence", {"cdr", "sensor_msgs/msg/Image"}},
        {"/stereo/points", {"cdr", "sensor_msgs/msg/PointCloud2"}},
        {"/stereo/left/camera_info", {"cdr", "sensor_msgs/msg/CameraInfo"}},
        {"/stereo/right/camera_info", {"cdr", "sensor_msgs/msg/CameraInfo"}},
        {"/stereo/nearest", {"json", "stereod.Reading"}},
        {"/stereo/status", {"json", "stereod.Status"}}};
    ASSERT_EQ(got["channels"].size(), expected.size()) << got["channels"].dump();
    for (const Json& channel : got["channels"]) {
        const auto it = expected.find(channel["topic"]);
        ASSERT_NE(it, expected.end()) << channel.dump();
        EXPECT_EQ(channel["encoding"], it->second.first);
        EXPECT_EQ(channel["schemaName"], it->second.second);
        EXPECT_EQ(channel["schemaEncoding"], it->second.first == "cdr" ? "ros2msg" : "jsonschema");
        EXPECT_GT(channel["schemaLength"].get<int>(), 10);
        // Frame channels: at least 5 messages in 4 s (the client decoded every CDR one).
        if (it->second.first == "cdr" || it->first == "/stereo/nearest") {
            EXPECT_GE(got["counts"].value(it->first, 0), 5) << it->first;
        }
    }
    EXPECT_GE(got["counts"].value("/stereo/status", 0), 2);
    EXPECT_TRUE(got["statuses"].empty()) << got["statuses"].dump();

    // Depth: 32FC1 metres, NaN where none, equal to the snapshot's within 1 mm. The
    // replayed pairs are one pair three times, so every frame's depth is the same.
    const Json& depth = got["depth"];
    ASSERT_TRUE(depth.is_object());
    EXPECT_EQ(depth["encoding"], "32FC1");
    EXPECT_EQ(depth["width"], 384);
    EXPECT_EQ(depth["height"], 288);
    EXPECT_EQ(depth["step"], 384 * 4);
    EXPECT_EQ(depth["frame_id"], "stereo_left_optical_frame");
    EXPECT_EQ(depth["logTime"], depth["stamp_ns"]);
    const cv::Mat depth_mm = snapshotDepthMm(cv::Size(384, 288));
    ASSERT_FALSE(HasFailure());
    const Json& values = depth["data"];
    ASSERT_EQ(values.size(), depth_mm.total());
    const test::DepthAgreement agreement = test::compareDepth(depth_mm, values);
    EXPECT_EQ(agreement.mismatched, 0u);
    EXPECT_GT(agreement.with_depth, depth_mm.total() / 2);

    // The nearest reading: the object `stereoctl distance --json` prints, but for the
    // pair's stamp, frame number and age.
    const ProcessResult distance =
        runProcess({test::stereoctlPath(), "--socket", socket_, "distance", "--json"});
    ASSERT_EQ(distance.exit_code, 0) << distance.err;
    Json ours = Json::parse(distance.out);
    Json theirs = got["nearest"];
    for (Json* reading : {&ours, &theirs}) {
        ASSERT_TRUE(reading->contains("stamp_ns")) << reading->dump();
        reading->erase("stamp_ns");
        reading->erase("frame");
        reading->erase("age_ms");
    }
    EXPECT_EQ(theirs, ours);
    EXPECT_EQ(got["status"]["live_view"]["listening"], true);

    // The service counts what it sent.
    const Json live = status()["live_view"];
    EXPECT_EQ(live["listen"], "127.0.0.1:" + std::to_string(port));
    EXPECT_EQ(live["listening"], true);
    EXPECT_GT(live["messages_sent"].get<uint64_t>(), 40u);
    EXPECT_GT(live["bytes_sent"].get<uint64_t>(), 1'000'000u);
}

// The page in Debian's Chromium (headless, playwright-core): the distance `stereoctl
// distance` gives, a depth image that is not blank, a screenshot kept in the build tree;
// and with the region aimed at nothing, NO READING and the reason.
class LiveViewPage : public LiveViewE2e {
  protected:
    void SetUp() override
    {
        if (std::string(STEREOD_NODE).empty())
            GTEST_SKIP() << "node is not installed";
        if (!std::filesystem::exists(chromium()))
            GTEST_SKIP() << chromium() << " is not installed (scripts/setup.sh installs it)";
        ASSERT_TRUE(std::filesystem::exists(kClientScripts + "/node_modules/playwright-core"))
            << "the live view's client packages are missing: run scripts/setup-node.sh";
        LiveViewE2e::SetUp();
    }
    static std::string chromium()
    {
        const char* path = std::getenv("STEREOD_CHROMIUM");
        return path != nullptr ? path : "/usr/bin/chromium";
    }
    Json openPage(uint16_t port, const std::string& screenshot)
    {
        const ProcessResult page =
            runProcess({STEREOD_NODE, kClientScripts + "/page.mjs",
                        "http://127.0.0.1:" + std::to_string(port) + "/", screenshot});
        EXPECT_EQ(page.exit_code, 0) << page.err;
        return page.exit_code == 0 ? Json::parse(page.out) : Json::object();
    }
};

TEST_F(LiveViewPage, ShowsTheDistanceAndTheDepth)
{
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port));
    ASSERT_FALSE(HasFailure());
    const std::string screenshot = std::string(STEREOD_BINARY_DIR) + "/live-view-page.png";
    const Json shown = openPage(port, screenshot);
    ASSERT_FALSE(HasFailure());
    EXPECT_TRUE(shown["errors"].empty()) << shown["errors"].dump();
    const ProcessResult distance =
        runProcess({test::stereoctlPath(), "--socket", socket_, "distance"});
    ASSERT_EQ(distance.exit_code, 0) << distance.err;
    // Both print three decimals and " m": the same pair gives the same text.
    EXPECT_EQ(shown["distance"].get<std::string>() + "\n", distance.out);
    EXPECT_EQ(shown["depth_width"], 384);
    EXPECT_GT(shown["depth_variance"].get<double>(), 100.0) << "the depth canvas is blank";
    EXPECT_NE(shown["status"].get<std::string>().find("state running"), std::string::npos);
    EXPECT_TRUE(std::filesystem::file_size(screenshot) > 10000) << screenshot;

    // The hovered pixel's depth is the service's own there (its snapshot, in mm), with
    // the pixel's confidence.
    const std::string hover = shown["hover"];
    std::smatch match;
    ASSERT_TRUE(std::regex_match(
        hover, match,
        std::regex(R"(\((\d+), (\d+)\) (no depth|(\d+\.\d{3}) m), confidence (\d+))")))
        << hover;
    const int x = std::stoi(match[1]), y = std::stoi(match[2]);
    ProtocolClient client(socket_, 30000ms);
    const Json snapshot = client.request({{"cmd", "snapshot"}, {"items", Json::array({"depth"})}});
    cv::Mat depth_mm(288, 384, CV_16UC1);
    ASSERT_EQ(snapshot["payloads"][0]["bytes"], depth_mm.total() * 2);
    client.readPayload(depth_mm.data, depth_mm.total() * 2);
    const int mm = depth_mm.at<uint16_t>(y, x);
    if (match[3] == "no depth") {
        EXPECT_EQ(mm, 0) << hover;
    } else {
        EXPECT_NEAR(std::stod(match[4]) * 1000.0, mm, 1.0) << hover;
        EXPECT_GT(std::stoi(match[5]), 0) << hover;
    }
}

TEST_F(LiveViewPage, RegionAimedAtNothingShowsNoReadingAndTheReason)
{
    // Every depth of the scene is beyond 0.15 m: nothing in range.
    const std::string config = dir_.file("near.yaml");
    std::ofstream(config) << "nearest:\n  min_depth_m: 0.1\n  max_depth_m: 0.15\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config, false);
    ASSERT_FALSE(HasFailure());
    const Json shown =
        openPage(port, std::string(STEREOD_BINARY_DIR) + "/live-view-no-reading.png");
    ASSERT_FALSE(HasFailure());
    const std::string text = shown["distance"];
    EXPECT_EQ(text.rfind("NO READING: nothing_in_range", 0), 0u) << text;
}

TEST_F(LiveViewE2e, PortTakenLeavesTheServiceRunningAndSaysSo)
{
    const UniqueFd taken(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::bind(taken.get(), reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
    ASSERT_EQ(::listen(taken.get(), 1), 0);
    socklen_t length = sizeof address;
    ::getsockname(taken.get(), reinterpret_cast<sockaddr*>(&address), &length);
    const std::string listen = "127.0.0.1:" + std::to_string(ntohs(address.sin_port));

    startService(listen); // readings flow: the service runs without its live view
    ASSERT_FALSE(HasFailure());
    const Json live = status()["live_view"];
    EXPECT_EQ(live["listen"], listen);
    EXPECT_EQ(live["listening"], false);
    EXPECT_NE(live["error"].get<std::string>().find("in use"), std::string::npos) << live.dump();
    const ProcessResult view = runProcess({test::stereoctlPath(), "--socket", socket_, "view"});
    EXPECT_EQ(view.exit_code, 1);
    EXPECT_NE(view.err.find("not listening"), std::string::npos) << view.err;
}

TEST_F(LiveViewE2e, HttpServesThePageAndRefusesEverythingElse)
{
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port));
    ASSERT_FALSE(HasFailure());
    // `stereoctl view` names the address (no display here: no browser is opened).
    const ProcessResult view = runProcess({test::stereoctlPath(), "--socket", socket_, "view"},
                                          {"DISPLAY=", "WAYLAND_DISPLAY="});
    EXPECT_EQ(view.exit_code, 0) << view.err;
    EXPECT_EQ(view.out.rfind("http://127.0.0.1:" + std::to_string(port) + "/\n", 0), 0u)
        << view.out;
    const std::string page = httpGet(port, "/");
    EXPECT_EQ(page.rfind("HTTP/1.1 200", 0), 0u) << page.substr(0, 200);
    EXPECT_NE(page.find("text/html"), std::string::npos);
    EXPECT_NE(page.find("viewer.js"), std::string::npos);
    const std::string three = httpGet(port, "/three/build/three.module.js");
    EXPECT_EQ(three.rfind("HTTP/1.1 200", 0), 0u)
        << three.substr(0, 200) << " (is libjs-three installed?)";
    EXPECT_EQ(httpGet(port, "/../../etc/passwd").rfind("HTTP/1.1 400", 0), 0u);
    EXPECT_EQ(httpGet(port, "/three/../../../etc/passwd").rfind("HTTP/1.1 400", 0), 0u);
    EXPECT_EQ(httpGet(port, "/nothing.js").rfind("HTTP/1.1 404", 0), 0u);
    EXPECT_EQ(
        httpExchange(
            port,
            "POST / HTTP/1.1\r\nHost: stereod\r\nConnection: close\r\nContent-Length: 0\r\n\r\n")
            .rfind("HTTP/1.1 405", 0),
        0u);
    // Garbage instead of HTTP: an error answer or a closed connection, and the service
    // still serves.
    httpExchange(port, std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 11));
    httpExchange(port, "GET / HTTP/1.1\r\nHost: stereod\r\nConnection: close\r\nX: " +
                           std::string(100000, 'a') + "\r\n\r\n");
    EXPECT_EQ(httpGet(port, "/").rfind("HTTP/1.1 200", 0), 0u);
    ProtocolClient client(socket_, 10000ms);
    EXPECT_TRUE(client.request({{"cmd", "distance"}})["reading"].value("valid", false));
}

} // namespace
} // namespace stereod
