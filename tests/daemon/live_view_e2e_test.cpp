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
    ProtocolClient client(socket_, 30000ms);
    const Json snapshot = client.request({{"cmd", "snapshot"}, {"items", Json::array({"depth"})}});
    ASSERT_EQ(snapshot["depth_valid"], true) << snapshot.dump();
    cv::Mat depth_mm(288, 384, CV_16UC1);
    ASSERT_EQ(snapshot["payloads"][0]["bytes"], depth_mm.total() * 2);
    client.readPayload(depth_mm.data, depth_mm.total() * 2);
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
    // The page at the address `stereoctl view` prints.
    Json openPage(const std::string& screenshot)
    {
        const ProcessResult page =
            runProcess({STEREOD_NODE, kClientScripts + "/page.mjs", page_, screenshot});
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
    const Json shown = openPage(screenshot);
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
    const Json shown = openPage(std::string(STEREOD_BINARY_DIR) + "/live-view-no-reading.png");
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
    EXPECT_LT(busy_cpu, idle_cpu + 0.6)
        << "idle " << idle_cpu << " s, with 260 connections " << busy_cpu << " s of CPU in 2 s";
    ProtocolClient client(socket_, 10000ms);
    EXPECT_TRUE(client.request({{"cmd", "distance"}})["reading"].value("valid", false));
    const Json live = status()["live_view"];
    EXPECT_LE(live["clients"].get<uint64_t>(), 16u) << live.dump();
    EXPECT_GE(live["refused"].get<uint64_t>(), 1u) << live.dump();

    connections.clear();
    std::this_thread::sleep_for(2s);
    const uint64_t frames_after = frames();
    std::this_thread::sleep_for(1s);
    EXPECT_GE(frames(), frames_after + 3);
    EXPECT_TRUE(client.request({{"cmd", "distance"}})["reading"].value("valid", false));
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
