// stereod and stereoctl together, as separate processes: the service replays a recording
// made from Middlebury tsukuba, and every client command runs against it; then the
// service's robustness (junk requests, many clients, a subscriber that never reads) and
// its shutdown.

#include <atomic>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <signal.h>
#include <sys/wait.h>

#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/depth_io.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
// Replies are held non-const here: operator[] with a missing key is undefined behaviour
// on a const object, while on a non-const one it reads null and fails the check.
using Json = nlohmann::ordered_json;
using test::ChildProcess;
using test::ProcessResult;
using test::runProcess;
using test::stereoctlPath;
using test::stereodPath;

const std::string kTsukuba = test::tsukubaDir();
const cv::Size kTsukubaSize(384, 288);
constexpr int kRecordedPairs = 3;
// Liveness bounds, generous for sanitizer builds: reaching them means "never happened".
constexpr auto kStartLimit = 60s;
constexpr auto kEventLimit = 30s;

// The distance of a plain `stereoctl distance` line, "0.873 m\n" (three decimals), or
// nullopt when the line has another form.
std::optional<double> parseDistance(const std::string& line)
{
    const std::size_t point = line.find('.');
    const std::size_t unit = line.find(" m\n");
    if (point == std::string::npos || point == 0 || unit != point + 4 || unit + 3 != line.size()) {
        return std::nullopt;
    }
    for (std::size_t i = 0; i < unit; ++i) {
        if (i != point && !std::isdigit(static_cast<unsigned char>(line[i]))) {
            return std::nullopt;
        }
    }
    return std::stod(line.substr(0, unit));
}

class StereodE2e : public ::testing::Test {
  protected:
    void SetUp() override
    {
        // A plain folder of left*/right* pairs, replayed in a loop at the nominal rate.
        recording_ = dir_.file("rec");
        std::filesystem::create_directory(recording_);
        for (int i = 0; i < kRecordedPairs; ++i) {
            std::filesystem::copy_file(kTsukuba + "/im3.png",
                                       recording_ + "/left" + std::to_string(i) + ".png");
            std::filesystem::copy_file(kTsukuba + "/im4.png",
                                       recording_ + "/right" + std::to_string(i) + ".png");
        }
        calibration_ = dir_.file("calib.yaml");
        saveCalibration(
            makeRectifiedCalibration(kTsukubaSize, test::kTsukubaFocalPx, test::kTsukubaBaselineM),
            calibration_);
        socket_ = dir_.file("s.sock");
        log_ = dir_.file("stereod.log");
        service_ = std::make_unique<ChildProcess>(
            std::vector<std::string>{stereodPath(), "--replay", recording_, "--calib", calibration_,
                                     "--socket", socket_},
            log_);
        waitUntilProducing();
    }

    void TearDown() override
    {
        if (service_ && service_->running()) {
            service_->sendSignal(SIGTERM);
            service_->waitFor(10s);
        }
        if (HasFailure()) {
            std::cerr << "--- stereod log ---\n" << serviceLog() << "------------------\n";
        }
    }

    std::string serviceLog() const
    {
        std::ifstream in(log_);
        std::stringstream text;
        text << in.rdbuf();
        return text.str();
    }

    // Until `distance` gives a reading from a processed frame.
    void waitUntilProducing()
    {
        const auto deadline = std::chrono::steady_clock::now() + kStartLimit;
        std::string last_problem;
        while (std::chrono::steady_clock::now() < deadline) {
            ASSERT_TRUE(service_->running()) << "stereod exited during start-up:\n" << serviceLog();
            try {
                ProtocolClient client(socket_, 2000ms);
                Json reply = client.request({{"cmd", "distance"}});
                Json reading = reply.value("reading", Json::object());
                if (reading.value("reason", Json::object()).value("code", "") != "no_frame_yet") {
                    return;
                }
                last_problem = "no frame yet";
            } catch (const std::exception& e) {
                last_problem = e.what();
            }
            std::this_thread::sleep_for(20ms);
        }
        FAIL() << "stereod never produced a reading: " << last_problem << "\n" << serviceLog();
    }

    ProcessResult ctl(std::vector<std::string> args) const
    {
        args.insert(args.begin(), stereoctlPath());
        args.insert(args.end(), {"--socket", socket_});
        return runProcess(args);
    }

    Json request(const Json& request) const
    {
        ProtocolClient client(socket_, 5000ms);
        return client.request(request);
    }

    // Waits until the service has processed `frames` more pairs.
    uint64_t waitForFramesAfter(uint64_t frame, uint64_t frames) const
    {
        const auto deadline = std::chrono::steady_clock::now() + kEventLimit;
        while (std::chrono::steady_clock::now() < deadline) {
            const uint64_t now = request({{"cmd", "distance"}})["reading"]["frame"].get<uint64_t>();
            if (now >= frame + frames) {
                return now;
            }
            std::this_thread::sleep_for(20ms);
        }
        ADD_FAILURE() << "the service stopped producing after frame " << frame;
        return frame;
    }

    test::TempDir dir_;
    std::string recording_;
    std::string calibration_;
    std::string socket_;
    std::string log_;
    std::unique_ptr<ChildProcess> service_;
};

TEST_F(StereodE2e, DistanceIsTheOfflineReadingOfTheSamePair)
{
    const ProcessResult run = ctl({"distance"});
    ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
    const std::optional<double> parsed = parseDistance(run.out);
    ASSERT_TRUE(parsed.has_value()) << "not \"D.DDD m\": " << run.out;
    const double distance_m = *parsed;
    // The centre region's nearest objects, the lamp and the head, lie at true disparities
    // of about 10..14 px: between 0.57 and 0.80 m on this rig.
    EXPECT_GT(distance_m, test::kTsukubaFocalPx * test::kTsukubaBaselineM / 16.0);
    EXPECT_LT(distance_m, test::kTsukubaFocalPx * test::kTsukubaBaselineM / 9.0);

    // The service and `stereoctl depth` run the same processor with the same defaults.
    const ProcessResult offline =
        runProcess({stereoctlPath(), "depth", recording_ + "/left0.png", recording_ + "/right0.png",
                    "--calib", calibration_, "--json"});
    ASSERT_EQ(offline.exit_code, 0) << offline.err;
    const double offline_m = Json::parse(offline.out)["reading"]["distance_m"].get<double>();
    EXPECT_NEAR(distance_m, offline_m, 0.0015);
}

TEST_F(StereodE2e, DistanceJsonIsTheReadingObject)
{
    const ProcessResult run = ctl({"distance", "--json"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    Json reading = Json::parse(run.out);
    for (const char* key :
         {"valid", "distance_m", "stamp_ns", "age_ms", "frame", "valid_fraction"}) {
        EXPECT_TRUE(reading.contains(key)) << key << " missing from " << run.out;
    }
    EXPECT_TRUE(reading["valid"].get<bool>());
    EXPECT_GT(reading["stamp_ns"].get<int64_t>(), 0);
    EXPECT_GE(reading["age_ms"].get<double>(), 0.0);
    EXPECT_GT(reading["valid_fraction"].get<double>(), 0.5);
}

TEST_F(StereodE2e, ReadingOlderThanAllowedIsStaleWithExitTwo)
{
    // Processing alone takes longer than a microsecond: every reading is older than this.
    ProcessResult run = ctl({"distance", "--max-age-ms", "0.001"});
    EXPECT_EQ(run.exit_code, 2) << run.out << run.err;
    EXPECT_EQ(run.out.rfind("no reading: ", 0), 0u) << run.out;

    run = ctl({"distance", "--max-age-ms", "0.001", "--json"});
    EXPECT_EQ(run.exit_code, 2);
    Json reading = Json::parse(run.out);
    EXPECT_FALSE(reading["valid"].get<bool>());
    EXPECT_TRUE(reading["distance_m"].is_null());
    EXPECT_EQ(reading["reason"]["code"], "stale");
    // The stale reading still says how old it is.
    EXPECT_GT(reading["age_ms"].get<double>(), 0.001);
}

TEST_F(StereodE2e, StatusSummaryAndJson)
{
    ProcessResult run = ctl({"status"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    for (const char* part : {"source: replay", "camera", "pairing skew", "pipeline:", "match",
                             "total", "calibration: rectified", "clients:", "reading:"}) {
        EXPECT_NE(run.out.find(part), std::string::npos) << part << " missing from\n" << run.out;
    }

    run = ctl({"status", "--json"});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    Json status = Json::parse(run.out);
    EXPECT_EQ(status["source"]["kind"], "replay");
    EXPECT_TRUE(status["source"]["cameras"].is_array());
    EXPECT_GT(status["pipeline"]["frames"].get<uint64_t>(), 0u);
    EXPECT_TRUE(status["pipeline"]["stage_ms"].contains("match"));
    const int num_disparities = status["pipeline"]["num_disparities"].get<int>();
    EXPECT_GT(num_disparities, 0);
    EXPECT_EQ(num_disparities % 16, 0);
    // Close enough to see tsukuba's nearest object (15 px of disparity).
    EXPECT_LE(status["pipeline"]["closest_depth_m"].get<double>(),
              test::kTsukubaFocalPx * test::kTsukubaBaselineM / 15.0);
    EXPECT_DOUBLE_EQ(status["calibration"]["focal_px"].get<double>(), test::kTsukubaFocalPx);
    EXPECT_GE(status["clients"]["connected"].get<int>(), 1);
}

TEST_F(StereodE2e, SnapshotWritesReadableFiles)
{
    const std::string depth = dir_.file("depth.png");
    const std::string disparity = dir_.file("disparity.pfm");
    const std::string cloud = dir_.file("cloud.ply");
    const std::string colormap = dir_.file("colormap.png");
    const std::string left = dir_.file("left.png");
    const ProcessResult run = ctl({"snapshot", "--depth", depth, "--disparity", disparity,
                                   "--cloud", cloud, "--colormap", colormap, "--left", left});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    for (const std::string& path : {depth, disparity, cloud, colormap, left}) {
        EXPECT_NE(run.out.find(path), std::string::npos) << path << " not reported:\n" << run.out;
    }

    const cv::Mat depth_mm = cv::imread(depth, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(depth_mm.type(), CV_16UC1);
    EXPECT_EQ(depth_mm.size(), kTsukubaSize);
    EXPECT_GT(cv::countNonZero(depth_mm), static_cast<int>(depth_mm.total() / 2));
    const cv::Mat disparity_px = readDisparity(disparity);
    EXPECT_EQ(disparity_px.size(), kTsukubaSize);
    // Depth and disparity of one frame agree: Z = f*B/d, to the millimetre of the PNG.
    const cv::Point probe(kTsukubaSize.width / 2, kTsukubaSize.height / 2);
    const float d = disparity_px.at<float>(probe);
    if (std::isfinite(d) && d > 0.0f) {
        EXPECT_NEAR(depth_mm.at<uint16_t>(probe),
                    1000.0 * test::kTsukubaFocalPx * test::kTsukubaBaselineM / d, 1.0);
    }
    // Tsukuba's left image is in colour, and so is the rectified left of its replay.
    const cv::Mat left_image = cv::imread(left, cv::IMREAD_UNCHANGED);
    EXPECT_EQ(left_image.type(), CV_8UC3);
    EXPECT_EQ(left_image.size(), kTsukubaSize);
    const cv::Mat colormap_image = cv::imread(colormap, cv::IMREAD_UNCHANGED);
    EXPECT_EQ(colormap_image.type(), CV_8UC3);
    EXPECT_EQ(colormap_image.size(), kTsukubaSize);
    std::ifstream ply(cloud, std::ios::binary);
    std::string magic;
    std::getline(ply, magic);
    EXPECT_EQ(magic, "ply");
}

// source.replay.colour none: the same colour recording replays grey, with no colour item
// (0 x 0, no point coloured), as a grey recording's replay; left (the default, the
// fixture's service) gives them.
TEST_F(StereodE2e, ReplayColourNoneGivesNoColourItems)
{
    const Json items = Json::array({"left_colour", "raw_left_colour", "cloud", "cloud_colour"});
    const Json coloured = request({{"cmd", "snapshot"}, {"items", items}});
    ASSERT_EQ(coloured["ok"], true) << coloured.dump();
    EXPECT_EQ(coloured["payloads"][0]["bytes"], kTsukubaSize.area() * 3);
    EXPECT_EQ(coloured["payloads"][3]["points"], coloured["payloads"][2]["points"]);

    const std::string config = dir_.file("grey.yaml");
    std::ofstream(config) << "source:\n  replay:\n    colour: none\n";
    const std::string socket = dir_.file("grey.sock");
    ChildProcess grey({stereodPath(), "--config", config, "--replay", recording_, "--calib",
                       calibration_, "--socket", socket},
                      dir_.file("grey.log"));
    const auto deadline = std::chrono::steady_clock::now() + kStartLimit;
    Json snapshot;
    while (std::chrono::steady_clock::now() < deadline && grey.running()) {
        try {
            ProtocolClient client(socket, 5000ms);
            snapshot = client.request({{"cmd", "snapshot"}, {"items", items}});
            if (snapshot.value("ok", false))
                break;
        } catch (const std::exception&) {
        }
        std::this_thread::sleep_for(20ms);
    }
    grey.sendSignal(SIGTERM);
    grey.waitFor(10s);
    ASSERT_EQ(snapshot.value("ok", false), true) << snapshot.dump();
    const Json& payloads = snapshot["payloads"];
    for (const std::size_t colour_item : {0u, 1u, 3u}) {
        EXPECT_EQ(payloads[colour_item]["bytes"], 0) << payloads[colour_item].dump();
    }
    EXPECT_GT(payloads[2]["points"].get<std::size_t>(), 1000u);
    EXPECT_EQ(payloads[3]["points"], 0);
}

TEST_F(StereodE2e, WatchPrintsOneLinePerReadingUntilInterrupted)
{
    ChildProcess watch({stereoctlPath(), "watch", "--socket", socket_}, dir_.file("watch.log"));
    uint64_t previous_frame = 0;
    for (int i = 0; i < 2; ++i) {
        const std::optional<std::string> line = watch.readLine(kEventLimit);
        ASSERT_TRUE(line.has_value()) << "watch printed " << i << " lines";
        // "frame 118  0.569 m  age 37 ms  valid 97 %"
        unsigned long long frame = 0;
        char distance[32] = {};
        double age_ms = 0.0, valid_percent = 0.0;
        ASSERT_EQ(std::sscanf(line->c_str(), "frame %llu %31s m age %lf ms valid %lf %%", &frame,
                              distance, &age_ms, &valid_percent),
                  4)
            << *line;
        EXPECT_TRUE(parseDistance(std::string(distance) + " m\n").has_value()) << *line;
        EXPECT_GT(valid_percent, 50.0) << *line;
        if (i > 0) {
            EXPECT_GT(frame, previous_frame);
        }
        previous_frame = frame;
    }
    watch.sendSignal(SIGINT);
    const std::optional<int> status = watch.waitFor(kEventLimit);
    ASSERT_TRUE(status.has_value()) << "watch did not end on SIGINT";
    ASSERT_TRUE(WIFEXITED(*status)) << "watch was killed by signal " << WTERMSIG(*status);
    EXPECT_EQ(WEXITSTATUS(*status), 0);
}

TEST_F(StereodE2e, JunkRequestsGetErrorRepliesAndTheServiceStillAnswers)
{
    {
        ProtocolClient client(socket_, 5000ms);
        const std::vector<std::pair<std::string, std::string>> junk = {
            {"this is not json", "bad_json"},
            {"[1, 2, 3]", "bad_json"},
            {"{\"cmd\": 42}", "bad_request"},
            {"{}", "bad_request"},
            {"{\"cmd\": \"teleport\"}", "unknown_command"},
            {"{\"cmd\": \"distance\", \"max_age_ms\": -5}", "bad_request"},
            {"{\"cmd\": \"snapshot\", \"items\": [\"soul\"]}", "bad_request"},
            {"{\"cmd\": \"subscribe\", \"stream\": \"gossip\"}", "bad_request"},
            {"\xff\xfe{\"cmd\"", "bad_json"},
            {std::string("{\"cmd\": \"hel\0lo\"}", 17), "bad_json"},
        };
        for (const auto& [line, code] : junk) {
            client.sendRaw(line + "\n");
            Json reply = client.readJson();
            EXPECT_FALSE(reply["ok"].get<bool>()) << line;
            EXPECT_EQ(reply["error"]["code"], code) << line << " -> " << reply.dump();
            EXPECT_TRUE(reply["error"]["message"].is_string());
        }
        // The same connection still works, and ids are echoed.
        client.sendRaw("{\"cmd\": \"teleport\", \"id\": 7}\n");
        EXPECT_EQ(client.readJson()["id"], 7);
        Json hello = client.request({{"cmd", "hello"}, {"id", "h1"}});
        EXPECT_EQ(hello["protocol"], 1);
        EXPECT_EQ(hello["id"], "h1");
    }
    {
        // An oversized line: an error reply, then the connection closes.
        ProtocolClient client(socket_, 5000ms);
        client.sendRaw(std::string(70000, 'x') + "\n");
        Json reply = client.readJson();
        EXPECT_EQ(reply["error"]["code"], "request_too_large");
        EXPECT_THROW(client.readLine(), ClientError);
    }
    {
        // A client that vanishes halfway through a line.
        ProtocolClient client(socket_, 5000ms);
        client.sendRaw("{\"cmd\": \"dista");
    }
    const ProcessResult run = ctl({"distance"});
    EXPECT_EQ(run.exit_code, 0) << run.err;
    EXPECT_TRUE(service_->running());
}

TEST_F(StereodE2e, ThirtyTwoClientsAtOnce)
{
    constexpr int kClients = 32;
    std::vector<ProtocolClient> clients;
    for (int i = 0; i < kClients; ++i) {
        clients.emplace_back(socket_, 10000ms); // all connected before any asks
    }
    std::atomic<int> answered{0};
    std::vector<std::string> failures(kClients);
    std::vector<std::thread> threads;
    for (int i = 0; i < kClients; ++i) {
        threads.emplace_back([&, i] {
            try {
                Json distance =
                    clients[static_cast<std::size_t>(i)].request({{"cmd", "distance"}, {"id", i}});
                Json status = clients[static_cast<std::size_t>(i)].request({{"cmd", "status"}});
                if (distance["id"] == i && distance["reading"]["valid"].get<bool>() &&
                    status["status"].is_object()) {
                    answered.fetch_add(1);
                } else {
                    failures[static_cast<std::size_t>(i)] = distance.dump();
                }
            } catch (const std::exception& e) {
                failures[static_cast<std::size_t>(i)] = e.what();
            }
        });
    }
    for (std::thread& t : threads) {
        t.join();
    }
    EXPECT_EQ(answered.load(), kClients);
    for (int i = 0; i < kClients; ++i) {
        EXPECT_TRUE(failures[static_cast<std::size_t>(i)].empty())
            << "client " << i << ": " << failures[static_cast<std::size_t>(i)];
    }
}

TEST_F(StereodE2e, DepthSubscriberThatNeverReadsSlowsNobody)
{
    ProtocolClient sleeper(socket_, 5000ms);
    Json subscribed = sleeper.request({{"cmd", "subscribe"}, {"stream", "depth"}});
    EXPECT_EQ(subscribed["stream"], "depth");
    // From here on the sleeper reads nothing, while each depth event is 221 kB.

    const uint64_t start = request({{"cmd", "distance"}})["reading"]["frame"].get<uint64_t>();
    const uint64_t later = waitForFramesAfter(start, 10);
    EXPECT_GE(later, start + 10);

    Json clients = request({{"cmd", "status"}})["status"]["clients"];
    // The service kept going by dropping the sleeper's frames or the sleeper itself.
    EXPECT_GT(clients["frames_dropped"].get<uint64_t>() +
                  clients["disconnected_slow"].get<uint64_t>(),
              0u)
        << clients.dump();
    const ProcessResult run = ctl({"distance"});
    EXPECT_EQ(run.exit_code, 0) << run.err;
}

TEST_F(StereodE2e, SigtermStopsCleanlyAndClientsSeeTheServiceGo)
{
    ChildProcess watch({stereoctlPath(), "watch", "--socket", socket_}, dir_.file("watch.log"));
    ASSERT_TRUE(watch.readLine(kEventLimit).has_value());

    service_->sendSignal(SIGTERM);
    const std::optional<int> status = service_->waitFor(2s);
    ASSERT_TRUE(status.has_value()) << "stereod still running 2 s after SIGTERM";
    ASSERT_TRUE(WIFEXITED(*status)) << "stereod killed by signal " << WTERMSIG(*status);
    EXPECT_EQ(WEXITSTATUS(*status), 0) << serviceLog();
    EXPECT_FALSE(std::filesystem::exists(socket_)) << "the socket file is left behind";

    // The watcher notices: exit 3, saying the service went away.
    const std::optional<int> watch_status = watch.waitFor(kEventLimit);
    ASSERT_TRUE(watch_status.has_value());
    ASSERT_TRUE(WIFEXITED(*watch_status));
    EXPECT_EQ(WEXITSTATUS(*watch_status), 3);
    std::ifstream watch_log(dir_.file("watch.log"));
    std::string message;
    std::getline(watch_log, message);
    EXPECT_NE(message.find(socket_), std::string::npos) << message;

    // And a new client cannot reach it: exit 3, naming the socket and the reason.
    const ProcessResult run = ctl({"distance"});
    EXPECT_EQ(run.exit_code, 3);
    EXPECT_NE(run.err.find(socket_), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("No such file or directory"), std::string::npos) << run.err;
}

} // namespace
} // namespace stereod
