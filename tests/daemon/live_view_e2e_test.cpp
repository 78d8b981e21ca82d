// The live view against real clients: Foxglove's own WebSocket client and ROS 2 CDR
// reader (tests/live_view/client.mjs, node) connect to a replaying `stereod`, and what
// they decode is held to the service's own snapshot and `stereoctl distance --json`.
// Also: a port already taken leaves the service running without the live view, and the
// HTTP side refuses what it does not serve.
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
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
#include "tests/support/websocket_client.hpp"

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

    const ProcessResult node =
        runProcess({STEREOD_NODE, kClientScripts + "/client.mjs", websocket_, "4"});
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
        {"/stereo/status", {"json", "stereod.Status"}},
        {"/stereo/zones", {"json", "stereod.Zones"}}};
    ASSERT_EQ(got["channels"].size(), expected.size()) << got["channels"].dump();
    for (const Json& channel : got["channels"]) {
        const auto it = expected.find(channel["topic"]);
        ASSERT_NE(it, expected.end()) << channel.dump();
        EXPECT_EQ(channel["encoding"], it->second.first);
        EXPECT_EQ(channel["schemaName"], it->second.second);
        EXPECT_EQ(channel["schemaEncoding"], it->second.first == "cdr" ? "ros2msg" : "jsonschema");
        EXPECT_GT(channel["schemaLength"].get<int>(), 10);
        // Frame channels: at least 5 messages in 4 s (the client decoded every CDR one).
        if (it->second.first == "cdr" || it->first == "/stereo/nearest" ||
            it->first == "/stereo/zones") {
            EXPECT_GE(got["counts"].value(it->first, 0), 5) << it->first;
        }
    }
    EXPECT_GE(got["counts"].value("/stereo/status", 0), 2);
    EXPECT_TRUE(got["statuses"].empty()) << got["statuses"].dump();

    // The replayed left image is in colour: rgb8, and points with PCL's packed rgb, as a
    // Foxglove client decodes them.
    ASSERT_TRUE(got["left"].is_object()) << got.dump().substr(0, 2000);
    EXPECT_EQ(got["left"]["encoding"], "rgb8");
    EXPECT_EQ(got["left"]["step"], 384 * 3);
    EXPECT_EQ(got["left"]["bytes"], 384 * 288 * 3);
    ASSERT_TRUE(got["points"].is_object());
    EXPECT_EQ(got["points"]["point_step"], 20);
    ASSERT_EQ(got["points"]["fields"].size(), 5u);
    EXPECT_EQ(got["points"]["fields"][4],
              Json::parse(R"({"name":"rgb","offset":16,"datatype":7})"));

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
    // One time base: header stamps and log times on the wall clock (CLOCK_REALTIME), the
    // reading's stamp_realtime_ns its CLOCK_MONOTONIC stamp_ns moved by the clocks' offset,
    // and its log time that very stamp.
    const auto wall_now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                 std::chrono::system_clock::now().time_since_epoch())
                                 .count();
    const int64_t depth_stamp = std::stoll(depth["stamp_ns"].get<std::string>());
    EXPECT_LT(depth_stamp, wall_now_ns);
    EXPECT_GT(depth_stamp, wall_now_ns - 60'000'000'000LL) << "not the wall clock";
    // The reading as it came (as text: its realtime stamp is too large for a JavaScript
    // number to hold exactly).
    const Json nearest = Json::parse(got["nearest_text"].get<std::string>());
    ASSERT_TRUE(nearest.contains("stamp_realtime_ns")) << nearest.dump();
    EXPECT_EQ(std::to_string(nearest["stamp_realtime_ns"].get<int64_t>()),
              got["nearest_log_time"].get<std::string>());
    EXPECT_NEAR(static_cast<double>(nearest["stamp_realtime_ns"].get<int64_t>() -
                                    nearest["stamp_ns"].get<int64_t>()),
                std::stod(got["clock_offset_ns"].get<std::string>()), 5e6);
    // The zones channel: none configured here, the pair's frame and stamps all the same.
    ASSERT_TRUE(got["zones"].is_object());
    EXPECT_TRUE(got["zones"]["zones"].empty());
    EXPECT_TRUE(got["zones"].contains("stamp_realtime_ns"));
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
    Json theirs = nearest;
    for (Json* reading : {&ours, &theirs}) {
        ASSERT_TRUE(reading->contains("stamp_ns")) << reading->dump();
        reading->erase("stamp_ns");
        reading->erase("stamp_realtime_ns");
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

// The page in Debian's Chromium (headless, playwright-core), followed through the states
// of the reading (tests/live_view/page.mjs): each shown as such, with a screenshot in the
// build tree (build/tests/daemon/live-view/).
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
    static std::string screenshots() { return std::string(STEREOD_BINARY_DIR) + "/live-view"; }
    // The page at the address `stereoctl view` prints, opened by page.mjs, going through `states`;
    // read each with next().
    void openPage(const std::string& name, const std::vector<std::string>& states)
    {
        std::vector<std::string> argv = {STEREOD_NODE, kClientScripts + "/page.mjs", page_,
                                         screenshots(), name};
        argv.insert(argv.end(), states.begin(), states.end());
        browser_ = std::make_unique<test::ChildProcess>(argv, dir_.file("page.log"));
    }
    // What the page showed in its next state.
    Json next()
    {
        const auto line = browser_->readLine(90s);
        if (!line) {
            ADD_FAILURE() << "the page never showed the state: " << readText(dir_.file("page.log"));
            return Json::object();
        }
        Json shown = Json::parse(*line);
        std::printf("[page] %s: \"%s\" / \"%s\", %s\n", shown["state"].get<std::string>().c_str(),
                    shown["distance"].get<std::string>().c_str(),
                    shown["detail"].get<std::string>().c_str(),
                    shown["screenshot"].get<std::string>().c_str());
        EXPECT_TRUE(shown["errors"].empty()) << shown["errors"].dump();
        EXPECT_TRUE(shown["failed_requests"].empty()) << shown["failed_requests"].dump();
        EXPECT_GT(std::filesystem::file_size(shown["screenshot"].get<std::string>()), 10000u);
        return shown;
    }
    static std::string readText(const std::string& path)
    {
        std::ifstream in(path);
        return std::string(std::istreambuf_iterator<char>(in), {});
    }

    std::unique_ptr<test::ChildProcess> browser_;
};

// The distance `stereoctl distance` gives, connected, the depth in colours that follow the
// data with a colour bar in metres, the status with calibration health and zones; then,
// with the service stopped (SIGSTOP: the connection stays, nothing comes), the distance
// greys out as STALE once it is older than publish.max_reading_age_ms (3 s here: on two
// loaded cores a reading of the running service can be over 1 s old).
TEST_F(LiveViewPage, ShowsTheDistanceThenStaleWhenNothingComes)
{
    const std::string config = dir_.file("zones.yaml");
    std::ofstream(config)
        << "zones:\n  - {name: ahead, min: [0.3, -0.5, -0.5], max: [1.0, 0.5, 0.5]}\n"
        << "publish:\n  max_reading_age_ms: 3000\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config);
    ASSERT_FALSE(HasFailure());
    openPage("distance", {"valid", "stale"});
    const Json shown = next();
    ASSERT_FALSE(HasFailure());
    const ProcessResult distance =
        runProcess({test::stereoctlPath(), "--socket", socket_, "distance"});
    ASSERT_EQ(distance.exit_code, 0) << distance.err;
    // Both print three decimals and " m": the same pair gives the same text.
    EXPECT_EQ(shown["distance"].get<std::string>() + "\n", distance.out);
    EXPECT_EQ(shown["detail"], "");
    EXPECT_EQ(shown["connected"], "true");
    EXPECT_EQ(shown["connection"], "● connected to 127.0.0.1:" + std::to_string(port));
    EXPECT_EQ(shown["depth_width"], 384);
    EXPECT_GT(shown["depth_variance"].get<double>(), 100.0) << "the depth canvas is blank";
    // The 3-D view draws the points in the left camera's colour (tsukuba's, from the
    // points' packed rgb field), not in grey.
    EXPECT_GT(shown["cloud"]["lit_pixels"].get<int>(), 1000) << shown["cloud"].dump();
    EXPECT_GT(shown["cloud"]["mean_chroma"].get<double>(), 8.0) << shown["cloud"].dump();
    // The colour bar: metres from the frame's own 1st to 99th percentile (tsukuba, f*B
    // 8 px*m: 0.5 to 1.7 m or so).
    const std::string bar = shown["colourbar"];
    std::smatch ends;
    ASSERT_TRUE(std::regex_match(bar, ends, std::regex(R"((\d+\.\d+) m .* (\d+\.\d+) m)"))) << bar;
    EXPECT_GT(std::stod(ends[1]), 0.9); // the far end first (blue, left)
    EXPECT_LT(std::stod(ends[2]), 0.7); // the near end last (red, right)
    EXPECT_NE(shown["status"].get<std::string>().find("state running"), std::string::npos);
    EXPECT_EQ(shown["health"].get<std::string>().rfind("calibration health: ", 0), 0u)
        << shown["health"];
    ASSERT_EQ(shown["zones"].size(), 1u) << shown["zones"].dump();
    EXPECT_EQ(shown["zones"][0]["text"].get<std::string>().rfind("zone ahead: ", 0), 0u)
        << shown["zones"].dump();
    EXPECT_NE(shown["zones"][0]["text"].get<std::string>().find("% in sight"), std::string::npos);

    // The hovered pixel's depth is the service's own there (its snapshot, in mm), with
    // the pixel's confidence.
    const std::string hover = shown["hover"];
    std::smatch match;
    ASSERT_TRUE(std::regex_match(
        hover, match,
        std::regex(R"(\((\d+), (\d+)\) (no depth|(\d+\.\d{3}) m), confidence (\d+))")))
        << hover;
    const int x = std::stoi(match[1]), y = std::stoi(match[2]);
    {
        ProtocolClient client(socket_, 30000ms);
        const Json snapshot =
            client.request({{"cmd", "snapshot"}, {"items", Json::array({"depth"})}});
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

    // Stopped: the reading ages on the page's clock past max_reading_age_ms.
    service_->sendSignal(SIGSTOP);
    const Json stale = next();
    service_->sendSignal(SIGCONT);
    EXPECT_EQ(stale["distance"], "STALE " + shown["distance"].get<std::string>());
    EXPECT_EQ(stale["detail"].get<std::string>().rfind("no fresh reading: ", 0), 0u)
        << stale["detail"];
    EXPECT_NE(stale["detail"].get<std::string>().find("3.0 s allowed"), std::string::npos)
        << stale["detail"];
    EXPECT_NE(stale["distance_colour"], shown["distance_colour"]) << "not greyed out";
    EXPECT_EQ(stale["connected"], "true"); // still connected: the reading is what is old
}

TEST_F(LiveViewPage, RegionAimedAtNothingShowsNoReadingAndTheReason)
{
    // Every depth of the scene is beyond 0.15 m: nothing in range.
    const std::string config = dir_.file("near.yaml");
    std::ofstream(config) << "nearest:\n  min_depth_m: 0.1\n  max_depth_m: 0.15\n"
                          << "publish:\n  max_reading_age_ms: 10000\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config, false);
    ASSERT_FALSE(HasFailure());
    openPage("no-reading", {"none"});
    const Json shown = next();
    EXPECT_EQ(shown["distance"], "NO READING: nothing_in_range");
    EXPECT_EQ(shown["detail"].get<std::string>().rfind("nothing within the depth range", 0), 0u)
        << shown["detail"];
}

// A region from the image's left edge: the distance, and under it how much of the region the
// edge keeps from seeing that near (out_of_view_fraction).
TEST_F(LiveViewPage, ARegionAtTheLeftEdgeShowsWhatItCannotSee)
{
    const std::string config = dir_.file("edge.yaml");
    std::ofstream(config) << "nearest:\n  roi: {x: 0.0, y: 0.25, width: 0.5, height: 0.5}\n"
                          << "publish:\n  max_reading_age_ms: 10000\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config, false);
    ASSERT_FALSE(HasFailure());
    openPage("left-edge", {"valid"});
    const Json shown = next();
    EXPECT_NE(shown["distance"].get<std::string>().find(" m"), std::string::npos)
        << shown["distance"];
    const std::string detail = shown["detail"].get<std::string>();
    EXPECT_EQ(detail.rfind("LEFT EDGE: ", 0), 0u) << detail;
    EXPECT_NE(detail.find("% of the region cannot see this near"), std::string::npos) << detail;
}

// Something nearer than the disparity range can see (tsukuba enlarged three times, as
// census-sgm's accuracy test has it, with 32 disparities): NEARER THAN the bound, never a
// distance.
TEST_F(LiveViewPage, SomethingNearerThanTheRangeShowsTheBound)
{
    for (int i = 0; i < 3; ++i) {
        for (const char* side : {"left", "right"}) {
            const std::string file = recording_ + "/" + side + std::to_string(i) + ".png";
            cv::Mat image = cv::imread(file, cv::IMREAD_GRAYSCALE);
            cv::resize(image, image, {}, 3.0, 3.0, cv::INTER_CUBIC);
            cv::imwrite(file, image);
        }
    }
    saveCalibration(makeRectifiedCalibration(cv::Size(1152, 864), 3000.0, 0.1), calibration_);
    // The readings of 1152x864 pairs may come slower than the default 1 s of age allows.
    const std::string config = dir_.file("narrow.yaml");
    std::ofstream(config) << "matcher:\n  num_disparities: 32\nnearest:\n  max_depth_m: 100\n"
                          << "publish:\n  max_reading_age_ms: 10000\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config, false);
    ASSERT_FALSE(HasFailure());
    openPage("nearer", {"nearer"});
    const Json shown = next();
    // The closest the range sees: f*B / 31 px = 9.68 m.
    EXPECT_EQ(shown["distance"], "NEARER THAN 9.68 m");
    EXPECT_EQ(shown["detail"].get<std::string>().rfind("something in the region is nearer", 0), 0u)
        << shown["detail"];
}

// A rig whose calibration no longer holds (the Baumer rig after it moved, checked every
// half second; its scenes 1, 2, 3 and 5, which give a distance with 64 disparities; in 4,
// 6, 7 and 8 something is nearer than that range sees): the
// distance, in amber, with CALIBRATION SUSPECT and the row offset; the status panel says
// degraded; `stereoctl distance` prints the flag and exits 4.
TEST_F(LiveViewPage, ASuspectCalibrationIsShownWithTheDistance)
{
    const std::string baumer = test::sharedDataDir() + "/real-rig/baumer/";
    std::filesystem::remove_all(recording_);
    std::filesystem::create_directories(recording_ + "/left");
    std::filesystem::create_directories(recording_ + "/right");
    std::ofstream csv(recording_ + "/frames.csv");
    csv << "index,left_stamp_ns,right_stamp_ns,left,right\n";
    const int scenes[] = {1, 2, 3, 5};
    for (int i = 0; i < 4; ++i) {
        char number[8];
        std::snprintf(number, sizeof number, "%02d", scenes[i]);
        const std::string name = std::string(number) + ".png";
        // The scenes' files named "right" come from the calibration's left camera.
        std::filesystem::create_symlink(baumer + "samples_baumer/right" + name,
                                        recording_ + "/left/" + name);
        std::filesystem::create_symlink(baumer + "samples_baumer/left" + name,
                                        recording_ + "/right/" + name);
        csv << i << "," << 200'000'000LL * i << "," << 200'000'000LL * i << ",left/" << name
            << ",right/" << name << "\n";
    }
    csv.close();
    const ProcessResult imported = runProcess({test::stereoctlPath(), "calibrate", "--from-opencv",
                                               baumer + "Checkerboard_Baumer/intrinsics.yml",
                                               baumer + "Checkerboard_Baumer/extrinsics.yml",
                                               "--size", "696x524", "--out", calibration_});
    ASSERT_EQ(imported.exit_code, 0) << imported.err;
    const std::string config = dir_.file("health.yaml");
    std::ofstream(config)
        << "calibration_health:\n  interval_s: 0.5\nmatcher:\n  num_disparities: 64\n"
        << "publish:\n  max_reading_age_ms: 10000\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config, false);
    ASSERT_FALSE(HasFailure());
    openPage("suspect", {"suspect"});
    const Json shown = next();
    EXPECT_TRUE(
        std::regex_match(shown["distance"].get<std::string>(), std::regex(R"(\d+\.\d{3} m)")))
        << shown["distance"];
    EXPECT_EQ(shown["detail"].get<std::string>().rfind("CALIBRATION SUSPECT: rows ", 0), 0u)
        << shown["detail"];
    EXPECT_EQ(shown["health_state"], "degraded") << shown["health"];
    // And stereoctl says so too, with its own exit code.
    const ProcessResult distance =
        runProcess({test::stereoctlPath(), "--socket", socket_, "distance"});
    EXPECT_EQ(distance.exit_code, 4) << distance.out << distance.err;
    EXPECT_TRUE(std::regex_match(
        distance.out,
        std::regex(R"(\d+\.\d{3} m  CALIBRATION SUSPECT: rows [+-]\d+\.\d\d px apart\n)")))
        << distance.out;
}

// The matcher's whole name, longer than the 15 characters it was once cut to, read back
// through `status` (JSON and text) and the live view's /stereo/status; the text status
// also gives the live view's counters.
TEST_F(LiveViewE2e, TheMatchersWholeNameReadsBackThroughStatusAndTheLiveView)
{
    if (std::string(STEREOD_NODE).empty())
        GTEST_SKIP() << "node is not installed";
    const std::string config = dir_.file("planar.yaml");
    std::ofstream(config) << "matcher:\n  tuning: planar\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config, false);
    ASSERT_FALSE(HasFailure());
    EXPECT_EQ(status()["pipeline"]["matcher"], "census-sgm (planar)");
    const ProcessResult text = runProcess({test::stereoctlPath(), "--socket", socket_, "status"});
    ASSERT_EQ(text.exit_code, 0) << text.err;
    EXPECT_NE(text.out.find(", matcher census-sgm (planar), "), std::string::npos) << text.out;

    const ProcessResult node =
        runProcess({STEREOD_NODE, kClientScripts + "/client.mjs", websocket_, "3"});
    ASSERT_EQ(node.exit_code, 0) << node.err;
    const Json got = Json::parse(node.out);
    ASSERT_TRUE(got["status"].is_object()) << node.out.substr(0, 300);
    EXPECT_EQ(got["status"]["pipeline"]["matcher"], "census-sgm (planar)");

    const ProcessResult after = runProcess({test::stereoctlPath(), "--socket", socket_, "status"});
    EXPECT_NE(after.out.find("live view: http://127.0.0.1:" + std::to_string(port) + "/, "),
              std::string::npos)
        << after.out;
    EXPECT_NE(after.out.find(" frames dropped for slow clients, "), std::string::npos) << after.out;
}

// output.max_depth_m: depths beyond the cap are left out of the snapshot's depth, the
// cloud and the live view's depth and points; the reading is the one without the cap.
TEST_F(LiveViewE2e, DepthsBeyondTheOutputCapAreLeftOut)
{
    if (std::string(STEREOD_NODE).empty())
        GTEST_SKIP() << "node is not installed";
    // Tsukuba here: f*B = 8 px*m, its depths 0.57 .. 1.6 m; the default cap is f*B / 4 px.
    {
        const uint16_t port = freePort();
        startService("127.0.0.1:" + std::to_string(port));
        ASSERT_FALSE(HasFailure());
        EXPECT_NEAR(status()["pipeline"]["max_output_depth_m"].get<double>(), 615.0 * 0.013 / 4,
                    1e-3);
        service_.reset();
        socket_ = dir_.file("capped.sock");
    }
    const std::string config = dir_.file("cap.yaml");
    std::ofstream(config) << "output:\n  max_depth_m: 0.8\n";
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port), config);
    ASSERT_FALSE(HasFailure());
    EXPECT_EQ(status()["pipeline"]["max_output_depth_m"].get<double>(), 0.8);
    const ProcessResult text = runProcess({test::stereoctlPath(), "--socket", socket_, "status"});
    EXPECT_NE(text.out.find("depth out to 0.8 m"), std::string::npos) << text.out;

    ProtocolClient client(socket_, 30000ms);
    const Json snapshot =
        client.request({{"cmd", "snapshot"}, {"items", Json::array({"depth", "cloud"})}});
    ASSERT_EQ(snapshot["payloads"].size(), 2u) << snapshot.dump();
    cv::Mat depth_mm(288, 384, CV_16UC1);
    client.readPayload(depth_mm.data, depth_mm.total() * 2);
    std::vector<float> cloud(snapshot["payloads"][1]["bytes"].get<std::size_t>() / 4);
    client.readPayload(cloud.data(), cloud.size() * 4);
    double most_mm = 0;
    cv::minMaxLoc(depth_mm, nullptr, &most_mm);
    EXPECT_LE(most_mm, 800.0);
    EXPECT_GT(cv::countNonZero(depth_mm), 10000);
    for (std::size_t i = 2; i < cloud.size(); i += 4)
        ASSERT_LE(cloud[i], 0.8f) << "point " << i / 4;
    // The reading comes from the whole depth: tsukuba's nearest objects, within the cap.
    EXPECT_TRUE(snapshot["reading"]["valid"].get<bool>()) << snapshot["reading"].dump();

    const ProcessResult node =
        runProcess({STEREOD_NODE, kClientScripts + "/client.mjs", websocket_, "2"});
    ASSERT_EQ(node.exit_code, 0) << node.err;
    const Json got = Json::parse(node.out);
    ASSERT_TRUE(got["depth"].is_object());
    std::size_t with_depth = 0;
    for (const Json& z : got["depth"]["data"]) {
        if (z.is_null())
            continue;
        ++with_depth;
        ASSERT_LE(z.get<double>(), 0.8);
    }
    EXPECT_GT(with_depth, 10000u);
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
    // `stereoctl view` names the address with the token (no display here: no browser is
    // opened), and Foxglove's.
    const ProcessResult view = runProcess({test::stereoctlPath(), "--socket", socket_, "view"},
                                          {"DISPLAY=", "WAYLAND_DISPLAY="});
    EXPECT_EQ(view.exit_code, 0) << view.err;
    const std::string authority = "127.0.0.1:" + std::to_string(port);
    ASSERT_EQ(token_.size(), 32u) << page_;
    EXPECT_EQ(view.out, "http://" + authority + "/?token=" + token_ +
                            "\nFoxglove: Open connection, Foxglove WebSocket, ws://" + authority +
                            "/?token=" + token_ + "\n");
    const std::string t = "?token=" + token_;
    const std::string page = httpGet(port, "/" + t);
    EXPECT_EQ(page.rfind("HTTP/1.1 200", 0), 0u) << page.substr(0, 200);
    EXPECT_NE(page.find("text/html"), std::string::npos);
    EXPECT_NE(page.find("viewer.js"), std::string::npos);
    // The page keeps the token in a cookie of its own for its scripts and WebSocket.
    EXPECT_NE(page.find("Set-Cookie: stereod_live_view_" + std::to_string(port) + "=" + token_ +
                        "; Path=/; HttpOnly; SameSite=Strict"),
              std::string::npos)
        << page.substr(0, 400);
    const std::string cookie =
        "Cookie: stereod_live_view_" + std::to_string(port) + "=" + token_ + "\r\n";
    // The page's icon, which it names (no 404 in the browser's console).
    EXPECT_NE(page.find(R"(rel="icon" href="favicon.svg")"), std::string::npos);
    const std::string icon = httpGet(port, "/favicon.svg", cookie);
    EXPECT_EQ(icon.rfind("HTTP/1.1 200", 0), 0u) << icon.substr(0, 200);
    EXPECT_NE(icon.find("image/svg+xml"), std::string::npos);
    const std::string three = httpGet(port, "/three/build/three.module.js", cookie);
    EXPECT_EQ(three.rfind("HTTP/1.1 200", 0), 0u)
        << three.substr(0, 200) << " (is libjs-three installed?)";
    EXPECT_EQ(httpGet(port, "/../../etc/passwd" + t).rfind("HTTP/1.1 400", 0), 0u);
    EXPECT_EQ(httpGet(port, "/three/../../../etc/passwd" + t).rfind("HTTP/1.1 400", 0), 0u);
    EXPECT_EQ(httpGet(port, "/nothing.js" + t).rfind("HTTP/1.1 404", 0), 0u);
    // Issue 23: a target without its leading slash was glued onto the web root as text:
    // "socket_transport.cpp" served daemon/live_view/websocket_transport.cpp.
    const std::string glued = httpGet(port, "socket_transport.cpp" + t);
    EXPECT_EQ(glued.rfind("HTTP/1.1 400", 0), 0u) << glued.substr(0, 300);
    EXPECT_EQ(glued.find("websocketpp"), std::string::npos);
    // Without the token, or with another: nothing is served, and the reason says where
    // the address comes from.
    const std::string bare = httpGet(port, "/");
    EXPECT_EQ(bare.rfind("HTTP/1.1 401", 0), 0u) << bare.substr(0, 300);
    EXPECT_NE(bare.find("stereoctl view"), std::string::npos) << bare;
    EXPECT_EQ(httpGet(port, "/?token=" + std::string(32, '0')).rfind("HTTP/1.1 401", 0), 0u);
    EXPECT_EQ(
        httpExchange(port, "POST /" + t +
                               " HTTP/1.1\r\nHost: stereod\r\nConnection: close\r\nContent-Length: "
                               "0\r\n\r\n")
            .rfind("HTTP/1.1 405", 0),
        0u);
    // Garbage instead of HTTP: an error answer or a closed connection, and the service
    // still serves.
    httpExchange(port, std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 11));
    httpExchange(port, "GET / HTTP/1.1\r\nHost: stereod\r\nConnection: close\r\nX: " +
                           std::string(100000, 'a') + "\r\n\r\n");
    EXPECT_EQ(httpGet(port, "/" + t).rfind("HTTP/1.1 200", 0), 0u);
    ProtocolClient client(socket_, 10000ms);
    EXPECT_TRUE(client.request({{"cmd", "distance"}})["reading"].value("valid", false));
}

// Issue 23: a page served from another origin (here http://127.0.0.2:PORT) opened the live
// view's WebSocket in Chromium and received 38 camera images in 4 s. Now its handshake is
// refused for its Origin, and so is the same page holding the token (one that leaked).
TEST_F(LiveViewPage, AForeignPageGetsNothingEvenWithTheToken)
{
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port));
    ASSERT_FALSE(HasFailure());
    const ProcessResult page =
        runProcess({STEREOD_NODE, kClientScripts + "/cross_origin.mjs", "127.0.0.2",
                    "ws://127.0.0.1:" + std::to_string(port) + "/", websocket_, "4"});
    ASSERT_EQ(page.exit_code, 0) << page.err;
    const Json got = Json::parse(page.out);
    ASSERT_EQ(got["attempts"].size(), 2u) << got.dump();
    for (const Json& attempt : got["attempts"]) {
        EXPECT_FALSE(attempt["opened"].get<bool>()) << attempt.dump();
        EXPECT_EQ(attempt["messages"], 0) << attempt.dump();
    }
    EXPECT_NE(got["origin"].get<std::string>().find("127.0.0.2"), std::string::npos);
    EXPECT_GE(status()["live_view"]["refused"].get<uint64_t>(), 2u);
}

// CPU seconds a process has used (utime + stime of /proc/PID/stat).
double cpuSeconds(pid_t pid)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
    std::string text((std::istreambuf_iterator<char>(in)), {});
    std::istringstream fields(text.substr(text.rfind(')') + 2));
    std::string field;
    long long utime = 0, stime = 0;
    for (int i = 3; fields >> field; ++i) {
        if (i == 14)
            utime = std::stoll(field);
        if (i == 15) {
            stime = std::stoll(field);
            break;
        }
    }
    return static_cast<double>(utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

// Issue 23: under `ulimit -n 200`, 260 WebSocket connections left the replay unable to
// open its frames, for good ("no pair readable in a whole pass"), the Unix socket unable
// to accept, and the live view's thread spinning on accept() at 85 % of a core. The live
// view's connections are now kept within the descriptor budget (the rest wait in the
// kernel's backlog): the replay, the socket and the live view's own clients go on.
TEST_F(LiveViewE2e, ManyConnectionsUnderALowDescriptorLimitLeaveTheServiceServing)
{
    launcher_ = {"/usr/bin/prlimit", "--nofile=200:200", "--"};
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port));
    ASSERT_FALSE(HasFailure());
    const pid_t pid = service_->pid();
    const auto frames = [&] { return status()["pipeline"]["frames"].get<uint64_t>(); };
    const double idle_cpu_start = cpuSeconds(pid);
    std::this_thread::sleep_for(2s);
    const double idle_cpu = cpuSeconds(pid) - idle_cpu_start;

    std::vector<UniqueFd> connections;
    const std::string handshake = "GET /?token=" + token_ +
                                  " HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                                  "Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
                                  "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                                  "Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";
    for (int i = 0; i < 260; ++i) {
        UniqueFd fd = test::connectLoopback(port);
        ASSERT_TRUE(fd) << "connection " << i;
        ::send(fd.get(), handshake.data(), handshake.size(), MSG_NOSIGNAL);
        connections.push_back(std::move(fd));
    }
    std::this_thread::sleep_for(1s);
    const uint64_t frames_before = frames();
    const double busy_cpu_start = cpuSeconds(pid);
    std::this_thread::sleep_for(2s);
    const double busy_cpu = cpuSeconds(pid) - busy_cpu_start;
    EXPECT_GE(frames(), frames_before + 5) << "the replay stopped";
    // A spinning accept loop costs 85 % of a core (1.7 s in 2 s); the margin allows for
    // the noise of a sanitizer's build, where the idle service already takes 1.7 s.
    EXPECT_LT(busy_cpu, idle_cpu * 1.25 + 0.6)
        << "idle " << idle_cpu << " s, with 260 connections " << busy_cpu << " s of CPU in 2 s";
    ProtocolClient client(socket_, 10000ms);
    EXPECT_TRUE(client.request({{"cmd", "distance"}})["reading"].value("valid", false));
    const Json live = status()["live_view"];
    EXPECT_LE(live["clients"].get<uint64_t>(), 16u) << live.dump();
    EXPECT_GE(live["refused"].get<uint64_t>(), 1u) << live.dump();

    // The connections closed, the pipeline goes on: three more frames and a valid reading
    // (waited for: a sanitizer's build on loaded cores makes a few frames a second).
    connections.clear();
    const uint64_t frames_after = frames();
    const auto going_on = std::chrono::steady_clock::now() + 15s;
    Json reading;
    while (std::chrono::steady_clock::now() < going_on) {
        reading = client.request({{"cmd", "distance"}})["reading"];
        if (frames() >= frames_after + 3 && reading.value("valid", false))
            break;
        std::this_thread::sleep_for(100ms);
    }
    EXPECT_GE(frames(), frames_after + 3);
    EXPECT_TRUE(reading.value("valid", false)) << reading.dump();
    // A client gets in again.
    const auto deadline = std::chrono::steady_clock::now() + 15s;
    bool admitted = false;
    while (!admitted && std::chrono::steady_clock::now() < deadline) {
        try {
            test::WebSocketClient viewer(
                port, "foxglove.websocket.v1",
                test::WebSocketClient::Options{"/?token=" + token_, "", 0});
            admitted = true;
        } catch (const std::runtime_error&) {
            std::this_thread::sleep_for(200ms);
        }
    }
    EXPECT_TRUE(admitted);
}

// Issue 23: "[::]" was logged as http://:::18771/, and 0.0.0.0 at info with no warning.
// Addresses are written as URLs write them, a wildcard is reached at loopback, and an
// address beyond this machine is warned about.
TEST_F(LiveViewE2e, AddressesAreWrittenAsUrlsAndOnesBeyondLoopbackWarned)
{
    const uint16_t port = freePort();
    startService("[::]:" + std::to_string(port));
    ASSERT_FALSE(HasFailure());
    EXPECT_EQ(status()["live_view"]["listen"], "[::]:" + std::to_string(port));
    EXPECT_EQ(page_, "http://[::1]:" + std::to_string(port) + "/?token=" + token_);
    EXPECT_EQ(websocket_, "ws://[::1]:" + std::to_string(port) + "/?token=" + token_);
    EXPECT_EQ(httpGet(port, "/?token=" + token_).rfind("HTTP/1.1 200", 0), 0u);
    service_.reset();
    std::ifstream in(dir_.file("stereod.log"));
    const std::string log((std::istreambuf_iterator<char>(in)), {});
    EXPECT_NE(log.find("live view listening on [::]:" + std::to_string(port)), std::string::npos)
        << log;
    EXPECT_NE(log.find("[warning] live view: [::]:" + std::to_string(port) +
                       " is reached from beyond this machine"),
              std::string::npos)
        << log;
    EXPECT_EQ(log.find(token_), std::string::npos) << "the token is in the log";
}

// `stereoctl view` with a display opens a browser on a file of the user's that leads to
// the page, never on the address itself: a command line (xdg-open's, the browser's) is
// visible to every user of the machine, and the token in it would be too.
TEST_F(LiveViewE2e, ViewOpensTheBrowserThroughAPrivateFile)
{
    const uint16_t port = freePort();
    startService("127.0.0.1:" + std::to_string(port));
    ASSERT_FALSE(HasFailure());
    const std::string bin = dir_.file("bin");
    const std::string runtime = dir_.file("run");
    std::filesystem::create_directory(bin);
    std::filesystem::create_directory(runtime);
    const std::string opened = dir_.file("opened.txt");
    {
        std::ofstream fake(bin + "/xdg-open");
        fake << "#!/bin/sh\necho \"$@\" > " << opened << "\n";
    }
    std::filesystem::permissions(bin + "/xdg-open", std::filesystem::perms::owner_all);
    const char* path = std::getenv("PATH");
    const ProcessResult view =
        runProcess({test::stereoctlPath(), "--socket", socket_, "view"},
                   {"DISPLAY=:0", "XDG_RUNTIME_DIR=" + runtime,
                    "PATH=" + bin + ":" + (path != nullptr ? path : "/usr/bin:/bin")});
    ASSERT_EQ(view.exit_code, 0) << view.err;
    std::string argument;
    for (int i = 0; i < 50 && argument.empty(); ++i) { // xdg-open runs detached
        std::ifstream in(opened);
        std::getline(in, argument);
        std::this_thread::sleep_for(100ms);
    }
    ASSERT_EQ(argument.rfind("file://" + runtime + "/stereod-view-", 0), 0u) << argument;
    EXPECT_EQ(argument.find(token_), std::string::npos) << "the token is on a command line";
    const std::string file = argument.substr(7);
    EXPECT_EQ(std::filesystem::status(file).permissions() & std::filesystem::perms::all,
              std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
    std::ifstream in(file);
    const std::string html((std::istreambuf_iterator<char>(in)), {});
    EXPECT_NE(html.find("url=" + page_), std::string::npos) << html;
}

} // namespace
} // namespace stereod
