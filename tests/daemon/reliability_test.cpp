// The reliability suite: `stereod` as a separate process, replaying a recording that holds
// a corrupt and a missing image, under load from many clients at once, under a storm of
// SIGHUPs and stopped by SIGTERM in the middle of it. Every assertion is about
// correctness (every request answered, with the right reply, nothing dropped, memory
// bounded); how fast the service answers is measured by bench/socket_load.cpp.

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include "pipeline/calibration.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/process.hpp"
#include "tests/support/service_doubles.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

using test::ChildProcess;
using test::Json;
using test::ProcessResult;
using test::runProcess;
using test::stereodPath;
using test::TempDir;
using test::TestClient;
using test::waitUntil;
using namespace std::chrono_literals;

const std::string kTsukuba = test::tsukubaDir();
const cv::Size kSize(384, 288);
constexpr std::size_t kDepthBytes = 384 * 288 * 2;
constexpr int kPairs = 6;
constexpr int kCorruptPair = 2; // its left image is not a PNG
constexpr int kMissingPair = 4; // its right image is not there
// GCC says so with __SANITIZE_*__, clang (which builds the sanitizer runs) with
// __has_feature.
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define STEREOD_TEST_SANITIZED 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__) || defined(STEREOD_TEST_SANITIZED)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

// Resident memory of a process, in KiB (VmRSS of /proc/PID/status).
int64_t residentKiB(pid_t pid)
{
    std::ifstream status("/proc/" + std::to_string(pid) + "/status");
    for (std::string line; std::getline(status, line);) {
        if (line.rfind("VmRSS:", 0) == 0)
            return std::stoll(line.substr(6));
    }
    return -1;
}

// What a group of load clients saw: replies counted, and the first problems in words.
class LoadReport {
  public:
    void problem(const std::string& text)
    {
        const std::lock_guard lock(mutex_);
        if (problems_.size() < 20)
            problems_.push_back(text);
        ++problem_count_;
    }
    std::string problems() const
    {
        const std::lock_guard lock(mutex_);
        std::string text;
        for (const auto& problem : problems_)
            text += problem + "\n";
        return text;
    }
    uint64_t problemCount() const
    {
        const std::lock_guard lock(mutex_);
        return problem_count_;
    }

    std::atomic<uint64_t> answered{0};
    std::atomic<uint64_t> rounds_done{0}; // rounds completed by every thread, summed

  private:
    mutable std::mutex mutex_;
    std::vector<std::string> problems_;
    uint64_t problem_count_ = 0;
};

// `clients` connections asking `distance` in a loop, spread over a few threads; each
// round sends one request on every connection of a thread, then reads every reply. Every
// reply must echo its id and carry a valid reading no older than the last one the
// connection got. With `until_closed`, the service closing a connection ends that
// connection's load (a stop); otherwise it is a problem.
class DistanceLoad {
  public:
    DistanceLoad(const std::string& socket_path, int clients, int threads, bool until_closed)
        : until_closed_(until_closed)
    {
        for (int i = 0; i < clients; ++i)
            connections_.push_back(std::make_unique<TestClient>(socket_path));
        for (int t = 0; t < threads; ++t)
            threads_.emplace_back([this, t, threads] { run(t, threads); });
    }
    ~DistanceLoad() { stop(); }

    void stop()
    {
        stop_.store(true);
        for (std::thread& thread : threads_) {
            if (thread.joinable())
                thread.join();
        }
    }

    uint64_t requests() const { return connections_.size(); }
    LoadReport report;

  private:
    void run(int first, int step)
    {
        std::vector<std::size_t> mine;
        for (std::size_t i = static_cast<std::size_t>(first); i < connections_.size();
             i += static_cast<std::size_t>(step))
            mine.push_back(i);
        std::vector<int64_t> last_frame(connections_.size(), -1);
        std::vector<bool> closed(connections_.size(), false);
        uint64_t sequence = 0;
        while (!stop_.load()) {
            ++sequence;
            for (const std::size_t i : mine) {
                if (closed[i])
                    continue;
                try {
                    connections_[i]->sendJson({{"cmd", "distance"},
                                               {"max_age_ms", 600000},
                                               {"id", Json::array({i, sequence})}});
                } catch (const std::exception& e) {
                    closed[i] = true;
                    if (!until_closed_)
                        report.problem("client " + std::to_string(i) + ": " + e.what());
                }
            }
            for (const std::size_t i : mine) {
                if (closed[i])
                    continue;
                try {
                    const Json reply = connections_[i]->readJson();
                    const Json reading = reply.value("reading", Json::object());
                    const int64_t frame = reading.value("frame", int64_t{-1});
                    if (reply.value("ok", false) != true ||
                        reply.value("id", Json()) != Json::array({i, sequence}) ||
                        reading.value("valid", false) != true ||
                        !reading["distance_m"].is_number() || frame < last_frame[i]) {
                        report.problem("client " + std::to_string(i) + ": " + reply.dump());
                    } else {
                        ++report.answered;
                    }
                    last_frame[i] = frame;
                } catch (const std::exception& e) {
                    closed[i] = true;
                    const bool clean_close =
                        std::string(e.what()).find("closed") != std::string::npos ||
                        std::string(e.what()).find("recv") != std::string::npos;
                    if (!until_closed_ || !clean_close)
                        report.problem("client " + std::to_string(i) + ": " + e.what());
                }
            }
            if (std::all_of(mine.begin(), mine.end(), [&](std::size_t i) { return closed[i]; }))
                break;
            ++report.rounds_done;
        }
    }

    bool until_closed_;
    std::atomic<bool> stop_{false};
    std::vector<std::unique_ptr<TestClient>> connections_;
    std::vector<std::thread> threads_;
};

// A depth subscriber that reads every event and checks its payload size.
class DepthReader {
  public:
    explicit DepthReader(const std::string& socket_path) : client_(socket_path)
    {
        const Json reply = client_.request({{"cmd", "subscribe"}, {"stream", "depth"}});
        EXPECT_EQ(reply["ok"], true) << reply.dump();
        thread_ = std::thread([this] { run(); });
    }
    ~DepthReader() { stop(); }

    void stop()
    {
        stop_.store(true);
        if (thread_.joinable())
            thread_.join();
    }

    std::atomic<uint64_t> events{0};
    LoadReport report;

  private:
    void run()
    {
        while (!stop_.load()) {
            try {
                const Json event = client_.readJson();
                if (event.value("event", "") != "depth" ||
                    event.value("bytes", std::size_t{0}) != kDepthBytes) {
                    report.problem(event.dump());
                    return;
                }
                client_.readBytes(kDepthBytes);
                ++events;
            } catch (const std::exception& e) {
                if (!stop_.load())
                    report.problem(e.what());
                return;
            }
        }
    }

    TestClient client_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

class Reliability : public ::testing::Test {
  protected:
    void SetUp() override
    {
        // A recording of six pairs, 100 ms apart, one with a corrupt and one with a
        // missing image; the good ones are links to the shared data.
        recording_ = dir_.file("rec");
        std::filesystem::create_directories(recording_ + "/left");
        std::filesystem::create_directories(recording_ + "/right");
        std::ofstream index(recording_ + "/frames.csv");
        index << "index,left_stamp_ns,right_stamp_ns,left,right\n";
        for (int i = 0; i < kPairs; ++i) {
            const std::string left = "left/" + std::to_string(i) + ".png";
            const std::string right = "right/" + std::to_string(i) + ".png";
            const int64_t stamp_ns = 1'000'000'000 + int64_t{i} * 100'000'000;
            index << i << ',' << stamp_ns << ',' << stamp_ns << ',' << left << ',' << right << '\n';
            if (i == kCorruptPair)
                std::ofstream(recording_ + "/" + left) << "\x89PNG\r\n\x1a\n truncated";
            else
                std::filesystem::create_symlink(kTsukuba + "/im3.png", recording_ + "/" + left);
            if (i != kMissingPair)
                std::filesystem::create_symlink(kTsukuba + "/im4.png", recording_ + "/" + right);
        }
        calibration_ = dir_.file("calib.yaml");
        saveCalibration(makeRectifiedCalibration(kSize, 615.0, 0.013), calibration_);
        socket_ = dir_.file("s.sock");
        config_ = dir_.file("stereod.yaml");
        log_ = dir_.file("stereod.log");
        writeConfig(5.0);
    }

    void TearDown() override
    {
        if (service_ && service_->running()) {
            service_->sendSignal(SIGTERM);
            service_->waitFor(10s);
        }
        if (HasFailure())
            std::cerr << "--- stereod log (tail) ---\n" << logTail() << "------------------\n";
    }

    // The configuration; `percentile` is a live setting the SIGHUP storm flips.
    void writeConfig(double percentile) const
    {
        std::ofstream file(config_ + ".new");
        file << "source:\n  replay:\n    path: " << recording_ << "\n"
             << "calibration: " << calibration_ << "\n"
             << "socket:\n  path: " << socket_ << "\n  max_clients: 300\n"
             << "publish:\n  max_client_backlog_bytes: 4194304\n"
             << "nearest:\n  percentile: " << percentile << "\n";
        file.close();
        // Renamed into place: a reload never reads a half-written file.
        std::filesystem::rename(config_ + ".new", config_);
    }

    void startService()
    {
        service_ = std::make_unique<ChildProcess>(
            std::vector<std::string>{stereodPath(), "--config", config_}, log_);
        Json reading;
        ASSERT_TRUE(waitUntil(
            [&] {
                if (!service_->running())
                    return true;
                try {
                    TestClient client(socket_);
                    reading =
                        client.request({{"cmd", "distance"}, {"max_age_ms", 600000}})["reading"];
                    return reading["valid"] == true;
                } catch (const std::exception&) {
                    return false;
                }
            },
            60s))
            << reading.dump();
        ASSERT_TRUE(service_->running()) << "stereod exited during start-up:\n" << logTail();
    }

    Json status()
    {
        TestClient client(socket_);
        return client.request({{"cmd", "status"}})["status"];
    }

    uint64_t frames() { return status()["pipeline"]["frames"].get<uint64_t>(); }

    std::string log() const
    {
        std::ifstream in(log_);
        std::stringstream text;
        text << in.rdbuf();
        return text.str();
    }

    std::string logTail() const
    {
        const std::string text = log();
        return text.size() > 6000 ? text.substr(text.size() - 6000) : text;
    }

    TempDir dir_;
    std::string recording_;
    std::string calibration_;
    std::string socket_;
    std::string config_;
    std::string log_;
    std::unique_ptr<ChildProcess> service_;
};

TEST_F(Reliability, CorruptAndMissingImagesAreSkippedCountedAndTheServiceRuns)
{
    startService();
    // Once round the recording at least: both bad pairs seen.
    Json state;
    ASSERT_TRUE(waitUntil([&] {
        state = status();
        uint64_t bad = 0;
        for (const Json& camera : state["source"]["cameras"])
            bad += camera["bad_frames"].get<uint64_t>();
        return bad >= 2 && state["pipeline"]["frames"].get<uint64_t>() >= 4;
    })) << state.dump();
    EXPECT_EQ(state["source"]["state"], "running") << state["source"].dump();
    TestClient client(socket_);
    const Json reading = client.request({{"cmd", "distance"}, {"max_age_ms", 600000}})["reading"];
    EXPECT_EQ(reading["valid"], true) << reading.dump();
    const std::string text = log();
    EXPECT_NE(text.find("left/" + std::to_string(kCorruptPair) + ".png"), std::string::npos)
        << logTail();
    EXPECT_NE(text.find("right/" + std::to_string(kMissingPair) + ".png"), std::string::npos)
        << logTail();
}

TEST_F(Reliability, CalibrationOfTheRecordingThatDoesNotFitItsFramesIsRefused)
{
    saveCalibration(makeRectifiedCalibration(cv::Size(640, 480), 615.0, 0.013),
                    recording_ + "/calibration.yaml");
    const ProcessResult result =
        runProcess({stereodPath(), "--replay", recording_, "--socket", socket_});
    EXPECT_EQ(result.exit_code, 4) << result.err;
    EXPECT_NE(result.err.find("640x480"), std::string::npos) << result.err;
    EXPECT_NE(result.err.find("384x288"), std::string::npos) << result.err;
    EXPECT_FALSE(std::filesystem::exists(socket_));
}

TEST_F(Reliability, ManyClientsAskingWhileSubscribersReadAndOneNeverReads)
{
    constexpr int kClients = 256;
    constexpr uint64_t kRounds = 12; // per thread: 256 x 12 = 3072 requests at least
    constexpr int kThreads = 16;
    startService();
    const pid_t pid = service_->pid();
    const int64_t resident_before_kib = residentKiB(pid);

    // Subscribes to depth frames (221 kB each) and never reads one.
    TestClient sleeper(socket_);
    sleeper.sendJson({{"cmd", "subscribe"}, {"stream", "depth"}});
    DepthReader reader_a(socket_);
    DepthReader reader_b(socket_);
    const uint64_t frames_before = frames();

    DistanceLoad load(socket_, kClients, kThreads, false);
    // Until every thread did its rounds and the worker processed ten more pairs meanwhile
    // (the sleeper has fallen behind by then).
    uint64_t frames_during = frames_before;
    ASSERT_TRUE(waitUntil(
        [&] {
            if (load.report.problemCount() > 0)
                return true;
            frames_during = frames();
            return load.report.rounds_done.load() >= kRounds * kThreads &&
                   frames_during >= frames_before + 10;
        },
        120s))
        << "rounds done: " << load.report.rounds_done.load() << ", frames " << frames_before
        << " -> " << frames_during;
    const Json state = status();
    load.stop();
    reader_a.stop();
    reader_b.stop();

    EXPECT_EQ(load.report.problemCount(), 0u) << load.report.problems();
    EXPECT_GE(load.report.answered.load(), kRounds * kClients);
    EXPECT_EQ(reader_a.report.problemCount() + reader_b.report.problemCount(), 0u)
        << reader_a.report.problems() << reader_b.report.problems();
    EXPECT_GT(reader_a.events.load(), 0u);
    EXPECT_GT(reader_b.events.load(), 0u);
    // All still connected (the status client included), but perhaps the sleeper.
    EXPECT_EQ(state["clients"]["connected"].get<int>() +
                  state["clients"]["disconnected_slow"].get<int>(),
              kClients + 3 + 1)
        << state["clients"].dump();
    // The sleeper lost frames, or was dropped past the backlog bound; nobody else did.
    EXPECT_GT(state["clients"]["frames_dropped"].get<uint64_t>() +
                  state["clients"]["disconnected_slow"].get<uint64_t>(),
              0u)
        << state["clients"].dump();
    // Memory stays bounded: the sleeper's backlog is capped at 4 MiB and replies are sent
    // as they are made. (ASan keeps freed memory in quarantine, hence its larger bound.)
    const int64_t growth_kib = residentKiB(pid) - resident_before_kib;
    EXPECT_LT(growth_kib, kSanitized ? 512 * 1024 : 96 * 1024) << "KiB";
    EXPECT_TRUE(service_->running());
}

TEST_F(Reliability, SighupStormUnderLoadDropsNothing)
{
    constexpr int kClients = 32;
    constexpr int kSignals = 40;
    startService();
    DistanceLoad load(socket_, kClients, 4, false);
    DepthReader reader(socket_);
    for (int i = 0; i < kSignals; ++i) {
        writeConfig(i % 2 == 0 ? 6.0 : 5.0);
        service_->sendSignal(SIGHUP);
        std::this_thread::sleep_for(10ms);
    }
    // The last reload is through; requests go on meanwhile.
    TestClient client(socket_);
    const Json reload = client.request({{"cmd", "reload"}});
    EXPECT_EQ(reload["ok"], true) << reload.dump();
    const uint64_t answered = load.report.answered.load();
    ASSERT_TRUE(waitUntil([&] { return load.report.answered.load() > answered + kClients; }));
    load.stop();
    reader.stop();
    EXPECT_EQ(load.report.problemCount(), 0u) << load.report.problems();
    EXPECT_EQ(reader.report.problemCount(), 0u) << reader.report.problems();
    EXPECT_TRUE(service_->running());
    EXPECT_EQ(status()["clients"]["disconnected_slow"], 0);
    // Signals may merge while one is handled, but reloads happened, and none failed.
    const std::string text = log();
    EXPECT_NE(text.find("changed: [nearest.percentile]"), std::string::npos) << logTail();
    EXPECT_EQ(text.find("reload refused"), std::string::npos) << logTail();
}

TEST_F(Reliability, SigtermUnderLoadExitsCleanlyAndRemovesTheSocket)
{
    constexpr int kClients = 64;
    startService();
    DistanceLoad load(socket_, kClients, 8, true);
    DepthReader reader(socket_);
    ASSERT_TRUE(waitUntil([&] { return load.report.answered.load() >= 4 * kClients; }));

    const auto signalled = std::chrono::steady_clock::now();
    service_->sendSignal(SIGTERM);
    const std::optional<int> status = service_->waitFor(10s);
    const auto took = std::chrono::steady_clock::now() - signalled;
    ASSERT_TRUE(status.has_value()) << "stereod still running 10 s after SIGTERM";
    ASSERT_TRUE(WIFEXITED(*status)) << "killed by signal " << WTERMSIG(*status);
    EXPECT_EQ(WEXITSTATUS(*status), 0) << logTail();
    // The bound is 1 s; sanitizer builds run several times slower.
    EXPECT_LT(took, kSanitized ? 5s : 1s)
        << std::chrono::duration_cast<std::chrono::milliseconds>(took).count() << " ms";
    EXPECT_FALSE(std::filesystem::exists(socket_));
    // Every client got whole, correct replies until the service closed its connection.
    load.stop();
    reader.stop();
    EXPECT_EQ(load.report.problemCount(), 0u) << load.report.problems();
}

} // namespace
} // namespace stereod
