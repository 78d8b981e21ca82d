#pragma once
// The fixture of the `stereoctl record` end-to-end tests (record_e2e_test.cpp,
// record_depth_e2e_test.cpp): stereod replays a recording made from Middlebury tsukuba
// (each pair a different brightness, so that pairs can be told apart by their pixels, and
// stamps that identify them), and the tests check what comes out against what went in.

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <signal.h>

#include "ctl/client.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/calibration_formats.hpp"
#include "replay/mcap_recording.hpp"
#include "replay/recording.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod::record_e2e {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;
using test::ChildProcess;
using test::ProcessResult;
using test::runProcess;
using test::stereoctlPath;
using test::stereodPath;
namespace fs = std::filesystem;

inline const std::string kTsukuba = test::tsukubaDir();
inline const cv::Size kSize(384, 288);
constexpr double kFocalPx = 615.0;
constexpr double kBaselineM = 0.013;
constexpr int kSourcePairs = 6;
// 20 pairs per second, each right frame a few microseconds after its left one: stamps no
// clock of this machine would give, so equal stamps mean the recorded ones went through.
constexpr int64_t kFirstStampNs = 7'000'000'123;
constexpr int64_t kPeriodNs = 50'000'000;
constexpr auto kStartLimit = 60s;

struct SourcePair {
    cv::Mat left, right;
    int64_t left_stamp_ns = 0, right_stamp_ns = 0;
};

inline bool sameImage(const cv::Mat& a, const cv::Mat& b)
{
    return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

// Defined below the fixture, which uses it.
inline Json firstReading(const std::string& socket, ChildProcess& service, const std::string& log);

class RecordE2e : public ::testing::Test {
  protected:
    void SetUp() override
    {
        const cv::Mat left = cv::imread(kTsukuba + "/im3.png", cv::IMREAD_GRAYSCALE);
        const cv::Mat right = cv::imread(kTsukuba + "/im4.png", cv::IMREAD_GRAYSCALE);
        ASSERT_FALSE(left.empty());
        ASSERT_FALSE(right.empty());
        calibration_ = dir_.file("calib.yaml");
        saveCalibration(makeRectifiedCalibration(kSize, kFocalPx, kBaselineM), calibration_);
        for (int i = 0; i < kSourcePairs; ++i) {
            SourcePair pair;
            // Darker by 3 grey levels per pair: still the scene, but every pair its own.
            left.convertTo(pair.left, CV_8U, 1.0, -3.0 * i);
            right.convertTo(pair.right, CV_8U, 1.0, -3.0 * i);
            pair.left_stamp_ns = kFirstStampNs + i * kPeriodNs;
            pair.right_stamp_ns = pair.left_stamp_ns + 1000 + i;
            source_.push_back(pair);
        }
    }

    void TearDown() override
    {
        if (service_ && service_->running()) {
            service_->sendSignal(SIGTERM);
            service_->waitFor(10s);
        }
        if (HasFailure()) {
            std::cerr << "--- stereod log ---\n" << readFile(log_) << "------------------\n";
        }
    }

    static std::string readFile(const std::string& path)
    {
        std::ifstream in(path, std::ios::binary);
        std::stringstream text;
        text << in.rdbuf();
        return text.str();
    }

    // The folder of the Node.js interop scripts (tests/mcap_interop), or empty when node
    // is not installed (the caller skips). Node without the packages is a failure.
    static std::string interopScripts()
    {
        const std::string dir = std::string(STEREOD_SOURCE_DIR) + "/tests/mcap_interop";
        if (std::string(STEREOD_NODE).empty())
            return {};
        EXPECT_TRUE(std::filesystem::exists(dir + "/node_modules/@mcap/core/package.json"))
            << "run scripts/setup-node.sh";
        return dir;
    }

    // Writes the source recording (with calibration.yaml when `calibrated`) and starts
    // stereod on it; returns once it answers `hello`.
    void startService(bool calibrated)
    {
        recording_ = dir_.file("src");
        {
            RecordingWriter writer(recording_, calibrated ? calibration_ : std::string());
            for (const SourcePair& pair : source_)
                writer.write(pair.left, pair.right, pair.left_stamp_ns, pair.right_stamp_ns);
        }
        socket_ = dir_.file("s.sock");
        log_ = dir_.file("stereod.log");
        service_ = std::make_unique<ChildProcess>(
            std::vector<std::string>{stereodPath(), "--replay", recording_, "--socket", socket_},
            log_);
        const auto deadline = std::chrono::steady_clock::now() + kStartLimit;
        std::string problem;
        while (std::chrono::steady_clock::now() < deadline) {
            ASSERT_TRUE(service_->running()) << "stereod exited during start-up";
            try {
                ProtocolClient client(socket_, 2000ms);
                if (client.request({{"cmd", "hello"}}).value("ok", false))
                    return;
            } catch (const std::exception& e) {
                problem = e.what();
            }
            std::this_thread::sleep_for(20ms);
        }
        FAIL() << "stereod never answered: " << problem;
    }

    // The source pair with these stamps, or nullptr.
    const SourcePair* pairWithStamps(int64_t left_stamp_ns, int64_t right_stamp_ns) const
    {
        for (const SourcePair& pair : source_) {
            if (pair.left_stamp_ns == left_stamp_ns && pair.right_stamp_ns == right_stamp_ns)
                return &pair;
        }
        return nullptr;
    }

    // Reads a u8_gray payload announced by `descriptor`.
    static cv::Mat readGray(ProtocolClient& client, const Json& descriptor)
    {
        EXPECT_EQ(descriptor.value("format", ""), "u8_gray");
        cv::Mat image(descriptor.value("height", 0), descriptor.value("width", 0), CV_8UC1);
        EXPECT_EQ(descriptor.value("bytes", std::size_t{0}), image.total());
        client.readPayload(image.data, image.total());
        return image;
    }

    // Every recorded pair is a source pair: same stamps, same pixels.
    void expectSourcePairs(const std::string& dir, std::size_t expected_at_least)
    {
        const Recording recording = openRecording(dir, 10.0);
        EXPECT_EQ(recording.bad_rows, 0u);
        EXPECT_GE(recording.entries.size(), expected_at_least);
        for (const RecordingEntry& entry : recording.entries) {
            const SourcePair* source = pairWithStamps(entry.left_stamp_ns, entry.right_stamp_ns);
            ASSERT_NE(source, nullptr)
                << "row " << entry.index << ": stamps " << entry.left_stamp_ns << "/"
                << entry.right_stamp_ns << " are no recorded pair's";
            EXPECT_TRUE(sameImage(cv::imread(entry.left_path, cv::IMREAD_UNCHANGED), source->left))
                << entry.left_path;
            EXPECT_TRUE(
                sameImage(cv::imread(entry.right_path, cv::IMREAD_UNCHANGED), source->right))
                << entry.right_path;
        }
    }

    // A second stereod replaying `recording` (no --calib: a bag brings its camera_info)
    // until its first reading; that reading and the service's whole log once it stopped.
    struct Replayed {
        Json reading;
        std::string log;
    };
    Replayed replayOnce(const std::string& recording, const std::string& name)
    {
        const std::string log = dir_.file(name + ".log");
        const std::string socket = dir_.file(name + ".sock");
        ChildProcess replay({stereodPath(), "--replay", recording, "--socket", socket}, log);
        Replayed out{firstReading(socket, replay, log), {}};
        replay.sendSignal(SIGTERM);
        replay.waitFor(10s);
        out.log = readFile(log);
        return out;
    }

    ProcessResult ctl(std::vector<std::string> args, const std::vector<std::string>& env = {}) const
    {
        args.insert(args.begin(), stereoctlPath());
        args.push_back("--socket");
        args.push_back(socket_);
        return runProcess(args, env);
    }

    test::TempDir dir_;
    std::vector<SourcePair> source_;
    std::string calibration_, recording_, socket_, log_;
    std::unique_ptr<ChildProcess> service_;
};

// The wall clock now (CLOCK_REALTIME), ns since the Unix epoch.
inline int64_t wallClockNowNs()
{
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
}

// Every pair of the bag is a source pair (its pixels: each source pair has its own
// brightness), stamped in the service's one time base: the wall clock when the replay
// delivered it (within the last `within` of now), the pairs in order, the right frame the
// source's own skew after the left, even across the replay's loops. Returns how many
// pairs there are.
inline std::size_t expectBagOfSourcePairs(const std::string& path,
                                          const std::vector<SourcePair>& source,
                                          std::chrono::nanoseconds within = 10min)
{
    const int64_t now_ns = wallClockNowNs();
    mcap::Reader reader(path);
    const McapStereoIndex index = indexMcapStereo(reader, "", "");
    EXPECT_EQ(index.left_topic, kMcapLeftImageTopic);
    int64_t previous_ns = 0;
    for (const McapPair& p : index.pairs) {
        cv::Mat left, right;
        std::string why;
        EXPECT_TRUE(decodeMcapImage(reader, p.left, left, why)) << why;
        EXPECT_TRUE(decodeMcapImage(reader, p.right, right, why)) << why;
        const auto match = std::find_if(source.begin(), source.end(), [&](const SourcePair& s) {
            return sameImage(left, s.left) && sameImage(right, s.right);
        });
        EXPECT_NE(match, source.end()) << "a pair of the bag is no source pair";
        if (match == source.end())
            continue;
        EXPECT_EQ(p.right_stamp_ns - p.left_stamp_ns, match->right_stamp_ns - match->left_stamp_ns);
        EXPECT_GT(p.left_stamp_ns, previous_ns) << "the stamps step back";
        EXPECT_LE(p.left_stamp_ns, now_ns);
        EXPECT_GT(p.left_stamp_ns, now_ns - within.count()) << "not the wall clock";
        previous_ns = p.left_stamp_ns;
    }
    return index.pairs.size();
}

// The source pair whose left image is `left`, or nullptr.
inline const SourcePair* pairWithLeft(const std::vector<SourcePair>& source, const cv::Mat& left)
{
    for (const SourcePair& pair : source) {
        if (sameImage(pair.left, left))
            return &pair;
    }
    return nullptr;
}

// The first reading of the service on `socket` that is not "no frame yet".
inline Json firstReading(const std::string& socket, ChildProcess& service, const std::string& log)
{
    const auto deadline = std::chrono::steady_clock::now() + kStartLimit;
    while (std::chrono::steady_clock::now() < deadline && service.running()) {
        try {
            ProtocolClient client(socket, 2000ms);
            Json reading = client.request({{"cmd", "distance"}}).value("reading", Json::object());
            if (reading.value("reason", Json::object()).value("code", "") != "no_frame_yet")
                return reading;
        } catch (const std::exception&) {
        }
        std::this_thread::sleep_for(20ms);
    }
    ADD_FAILURE() << "no reading from " << socket << "\n"
                  << "see " << log;
    return Json::object();
}

} // namespace stereod::record_e2e
