// `stereoctl calibrate --live` against a running stereod, as separate processes: the service
// replays OpenCV's 13 real chessboard pairs (640x480, 9x6 inner corners) as a recording
// (frames.csv, left/, right/) in a loop, with no calibration at all (it serves raw frames
// only); the client collects 8 distinct views from its raw stream and calibrates. The
// calibration must meet the calibration issue's targets and load; the saved pairs must be
// the raw frames, bit for bit, and calibrating offline from them must give the same result.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <signal.h>

#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "replay/recording.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;
using test::ChildProcess;
using test::ProcessResult;
using test::runProcess;
using test::stereoctlPath;
using test::stereodPath;

const std::string kSamples = test::opencvSamplesDir() + "/";
const std::vector<int> kSampleIndices = {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14};
// Liveness bound, generous for sanitizer builds: reaching it means "never happened".
constexpr auto kStartLimit = 60s;

cv::Mat sample(const char* side, int index)
{
    char name[32];
    std::snprintf(name, sizeof name, "%s%02d.jpg", side, index);
    return cv::imread(kSamples + name, cv::IMREAD_GRAYSCALE);
}

std::vector<std::string> listFiles(const std::string& dir)
{
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
        names.push_back(entry.path().filename().string());
    }
    std::sort(names.begin(), names.end());
    return names;
}

class LiveCalibrationE2e : public ::testing::Test {
  protected:
    void SetUp() override
    {
        // The 13 pairs as a recording, 100 ms apart, without a calibration.
        recording_ = dir_.file("rec");
        RecordingWriter writer(recording_);
        int64_t stamp_ns = 1'000'000'000;
        for (int index : kSampleIndices) {
            const cv::Mat left = sample("left", index);
            const cv::Mat right = sample("right", index);
            ASSERT_FALSE(left.empty() || right.empty()) << "sample pair " << index;
            writer.write(left, right, stamp_ns, stamp_ns);
            stamp_ns += 100'000'000;
        }
        socket_ = dir_.file("s.sock");
        log_ = dir_.file("stereod.log");
        service_ = std::make_unique<ChildProcess>(
            std::vector<std::string>{stereodPath(), "--replay", recording_, "--socket", socket_},
            log_);
        waitUntilServing();
    }

    void TearDown() override
    {
        if (service_ && service_->running()) {
            service_->sendSignal(SIGTERM);
            service_->waitFor(10s);
        }
        if (HasFailure()) {
            std::ifstream in(log_);
            std::stringstream text;
            text << in.rdbuf();
            std::cerr << "--- stereod log ---\n" << text.str() << "------------------\n";
        }
    }

    // Until the service answers `hello`; it must be running uncalibrated.
    void waitUntilServing()
    {
        const auto deadline = std::chrono::steady_clock::now() + kStartLimit;
        std::string last_problem;
        while (std::chrono::steady_clock::now() < deadline) {
            ASSERT_TRUE(service_->running()) << "stereod exited during start-up";
            try {
                ProtocolClient client(socket_, 2000ms);
                hello_ = client.request({{"cmd", "hello"}});
                return;
            } catch (const std::exception& e) {
                last_problem = e.what();
            }
            std::this_thread::sleep_for(20ms);
        }
        FAIL() << "stereod never answered: " << last_problem;
    }

    std::vector<std::string> liveCommand(const std::string& count, const std::string& out) const
    {
        return {stereoctlPath(), "calibrate",  "--live", "--count",     count, "--board",
                "9x6",           "--square-m", "0.025",  "--out",       out,   "--socket",
                socket_,         "--max-hz",   "10",     "--timeout-s", "120"};
    }

    test::TempDir dir_;
    std::string recording_;
    std::string socket_;
    std::string log_;
    Json hello_;
    std::unique_ptr<ChildProcess> service_;
};

TEST_F(LiveCalibrationE2e, CollectsEightDistinctViewsAndCalibratesWithinTheTargets)
{
    // No calibration anywhere: the service serves raw frames only.
    EXPECT_EQ(hello_.value("calibrated", true), false) << hello_.dump();

    const std::string out = dir_.file("rig.yaml");
    const std::string pairs = dir_.file("pairs");
    std::vector<std::string> argv = liveCommand("8", out);
    argv.insert(argv.end(), {"--save-pairs", pairs, "--json"});
    const ProcessResult run = runProcess(argv);
    ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
    std::cout << run.err;

    Json report = Json::parse(run.out);
    EXPECT_EQ(report["pairs_used"], 8);
    EXPECT_TRUE(report["pairs_rejected"].empty()) << report["pairs_rejected"].dump();
    const double rms_px = report["rms_px"].get<double>();
    const double epipolar_px = report["epipolar_error_px"].get<double>();
    std::printf("live calibration from 8 views: RMS %.3f px, epipolar error %.3f px, baseline "
                "%.4f m\n",
                rms_px, epipolar_px, report["baseline_m"].get<double>());
    EXPECT_LE(rms_px, 0.30);
    EXPECT_LE(epipolar_px, 0.15);
    Json& live = report["live"];
    EXPECT_EQ(live["stopped"], "count");
    EXPECT_EQ(live["accepted"], 8);
    EXPECT_EQ(live["pairs_dir"], pairs);
    // The replay loops over 13 views: whatever came twice was refused, never accepted.
    EXPECT_EQ(live["board_in_both"], live["pairs_seen"]); // every sample shows the board
    EXPECT_EQ(live["board_in_both"].get<int>(), 8 + live["refused_duplicates"].get<int>());
    // The person is told after each verdict what is still missing.
    EXPECT_NE(run.err.find("accepted pair 8/8"), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("  missing: "), std::string::npos) << run.err;

    // The file loads and is the calibration the report describes.
    const StereoCalibration loaded = loadCalibration(out);
    EXPECT_EQ(loaded.kind, StereoCalibration::Kind::Full);
    ASSERT_TRUE(loaded.rms_px.has_value());
    EXPECT_DOUBLE_EQ(*loaded.rms_px, rms_px);
    EXPECT_EQ(loaded.rectified.image_size, (ImageSize{640, 480}));

    // The saved pairs are 8 distinct sample pairs, lossless: each saved image is a sample
    // image bit for bit, left with its own right.
    std::vector<std::string> expected_names;
    for (int i = 1; i <= 8; ++i) {
        char name[32];
        std::snprintf(name, sizeof name, "left_%03d.png", i);
        expected_names.emplace_back(name);
        std::snprintf(name, sizeof name, "right_%03d.png", i);
        expected_names.emplace_back(name);
    }
    std::sort(expected_names.begin(), expected_names.end());
    ASSERT_EQ(listFiles(pairs), expected_names);
    std::set<int> seen;
    for (int i = 1; i <= 8; ++i) {
        char left_name[32], right_name[32];
        std::snprintf(left_name, sizeof left_name, "/left_%03d.png", i);
        std::snprintf(right_name, sizeof right_name, "/right_%03d.png", i);
        const cv::Mat left = cv::imread(pairs + left_name, cv::IMREAD_UNCHANGED);
        const cv::Mat right = cv::imread(pairs + right_name, cv::IMREAD_UNCHANGED);
        ASSERT_EQ(left.type(), CV_8UC1);
        int match = 0;
        for (int index : kSampleIndices) {
            const cv::Mat l = sample("left", index);
            if (l.size() == left.size() && cv::norm(l, left, cv::NORM_INF) == 0.0) {
                match = index;
                EXPECT_EQ(cv::norm(sample("right", index), right, cv::NORM_INF), 0.0)
                    << "pair " << i << ": the right image is not sample " << index << "'s";
            }
        }
        EXPECT_NE(match, 0) << "saved pair " << i << " is not a sample pair bit for bit";
        EXPECT_TRUE(seen.insert(match).second) << "sample " << match << " accepted twice";
    }

    // Offline from the saved pairs: the same corners, the same calibration.
    const std::string again = dir_.file("again.yaml");
    const ProcessResult offline =
        runProcess({stereoctlPath(), "calibrate", "--left", pairs + "/left_*.png", "--right",
                    pairs + "/right_*.png", "--board", "9x6", "--square-m", "0.025", "--out", again,
                    "--json"});
    ASSERT_EQ(offline.exit_code, 0) << offline.err;
    Json offline_report = Json::parse(offline.out);
    EXPECT_NEAR(offline_report["rms_px"].get<double>(), rms_px, 1e-9);
    EXPECT_NEAR(offline_report["epipolar_error_px"].get<double>(), epipolar_px, 1e-9);
}

TEST_F(LiveCalibrationE2e, RefusesAfterTheTimeoutWithTooFewDistinctViews)
{
    // 13 distinct views exist; asking for 20 with 20 needed ends at the timeout, and the
    // calibration refuses as the file-based one does, after the pairs were saved.
    const std::string out = dir_.file("rig.yaml");
    std::vector<std::string> argv = liveCommand("20", out);
    argv.back() = "4"; // --timeout-s
    argv.insert(argv.end(), {"--min-pairs", "20"});
    const ProcessResult run = runProcess(argv);
    EXPECT_EQ(run.exit_code, 2) << run.out << run.err;
    EXPECT_NE(run.err.find("live: timed out after"), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("at least 20 are needed"), std::string::npos) << run.err;
    EXPECT_FALSE(std::filesystem::exists(out));
    const std::vector<std::string> saved = listFiles(dir_.file("rig-pairs"));
    EXPECT_GE(saved.size(), 2u);
    EXPECT_LE(saved.size(), 2u * 13u);
    EXPECT_EQ(saved.size() % 2, 0u);

    // A directory holding pairs already is refused before anything is collected.
    const ProcessResult again = runProcess(liveCommand("8", out));
    EXPECT_EQ(again.exit_code, 2);
    EXPECT_NE(again.err.find("already holds pairs"), std::string::npos) << again.err;
}

TEST(StereoctlCalibrateLive, RefusesBadArgumentsAndAnUnreachableService)
{
    test::TempDir dir;
    const std::string out = dir.file("rig.yaml");
    const std::string socket = dir.file("none.sock");
    const std::vector<std::string> base = {stereoctlPath(), "calibrate", "--live", "--square-m",
                                           "0.025",         "--out",     out,      "--socket",
                                           socket};
    struct Case {
        std::vector<std::string> extra;
        int exit_code;
        const char* message;
    };
    const std::vector<Case> cases = {
        {{"--board", "9x6"}, 2, "--live requires --count"},
        {{"--board", "9x6", "--count", "4"}, 2, "--count 4 is below --min-pairs 6"},
        {{"--board", "9x6", "--count", "8", "--left", "l*.png", "--right", "r*.png"},
         2,
         "excludes"},
        {{"--board", "9x9", "--count", "8"}, 2, "a square grid reads the same"},
        {{"--board", "9x6", "--count", "8"}, 3, "cannot connect to "},
    };
    for (const Case& c : cases) {
        std::vector<std::string> argv = base;
        argv.insert(argv.end(), c.extra.begin(), c.extra.end());
        const ProcessResult run = runProcess(argv);
        EXPECT_EQ(run.exit_code, c.exit_code) << run.err;
        EXPECT_NE(run.err.find(c.message), std::string::npos) << run.err;
        EXPECT_EQ(test::lineCount(run.err), 1u) << run.err;
    }
    // The options of the live form need it.
    const ProcessResult stray =
        runProcess({stereoctlPath(), "calibrate", "--left", "l*.png", "--right", "r*.png",
                    "--board", "9x6", "--square-m", "0.025", "--out", out, "--count", "8"});
    EXPECT_EQ(stray.exit_code, 2);
    EXPECT_NE(stray.err.find("--count requires --live"), std::string::npos) << stray.err;
    // Nothing was created by runs that could not start.
    EXPECT_FALSE(std::filesystem::exists(dir.file("rig-pairs")));
    EXPECT_FALSE(std::filesystem::exists(out));
}

} // namespace
} // namespace stereod
