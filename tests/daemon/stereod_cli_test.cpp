// The `stereod` binary as users run it: its command line, its exit codes for each kind of
// start-up problem, and a run on a replayed tsukuba folder that ends with SIGTERM.

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include "pipeline/calibration.hpp"
#include "tests/support/bags.hpp"
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

std::vector<std::string> lines(const std::string& text)
{
    std::vector<std::string> out;
    std::istringstream stream(text);
    for (std::string line; std::getline(stream, line);)
        out.push_back(line);
    return out;
}

class StereodCli : public ::testing::Test {
  protected:
    void SetUp() override
    {
        // A plain folder of one left/right pair, by links to the shared data.
        replay_ = dir_.file("rec");
        std::filesystem::create_directory(replay_);
        std::filesystem::create_symlink(kTsukuba + "/im3.png", replay_ + "/left0.png");
        std::filesystem::create_symlink(kTsukuba + "/im4.png", replay_ + "/right0.png");
        calibration_ = dir_.file("tsukuba.yaml");
        saveCalibration(makeRectifiedCalibration(cv::Size(384, 288), 615.0, 0.013), calibration_);
        socket_ = dir_.file("run/stereod.sock");
    }

    ProcessResult run(std::vector<std::string> arguments)
    {
        arguments.insert(arguments.begin(), stereodPath());
        return runProcess(arguments);
    }

    // The log of the service started on the replay with this configuration, until it
    // listens, then stopped: what it says as it sets up. Fails the test on a bad exit.
    std::string startUpLog(const std::string& config_text)
    {
        const std::string config = dir_.file("startup.yaml");
        std::ofstream(config) << config_text << "source:\n  replay:\n    loop: false\n";
        const std::string log_path = dir_.file("stereod.log");
        ChildProcess service({stereodPath(), "--config", config, "--replay", replay_, "--calib",
                              calibration_, "--socket", socket_},
                             log_path);
        const auto log = [&] {
            std::ifstream file(log_path);
            return std::string(std::istreambuf_iterator<char>(file), {});
        };
        EXPECT_TRUE(waitUntil([&] {
            return log().find("listening on") != std::string::npos || !service.running();
        })) << log();
        service.sendSignal(SIGTERM);
        const std::optional<int> status = service.waitFor(10s);
        EXPECT_TRUE(status.has_value());
        EXPECT_TRUE(status && WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << log();
        return log();
    }

    TempDir dir_;
    std::string replay_;
    std::string calibration_;
    std::string socket_;
};

TEST_F(StereodCli, HelpListsTheOptionsAndExitCodes)
{
    const ProcessResult result = run({"--help"});
    EXPECT_EQ(result.exit_code, 0) << result.err;
    for (const char* option : {"--config", "--check-config", "--replay", "--calib", "--socket",
                               "--log-level", "Exit codes", ".mcap"})
        EXPECT_NE(result.out.find(option), std::string::npos) << option;
}

TEST_F(StereodCli, BadArgumentsGiveOneLineAndExitTwo)
{
    for (const std::vector<std::string>& arguments : {std::vector<std::string>{"--bogus"},
                                                      {"--log-level", "loud"},
                                                      {"--replay"},
                                                      {"--check-config", "a.yaml", "--replay", "b"},
                                                      {"positional"}}) {
        const ProcessResult result = run(arguments);
        EXPECT_EQ(result.exit_code, 2) << arguments[0] << ": " << result.err;
        EXPECT_EQ(lines(result.err).size(), 1u) << result.err;
        EXPECT_EQ(result.err.rfind("stereod: ", 0), 0u) << result.err;
    }
}

TEST_F(StereodCli, EmptyPathsAreBadArgumentsNotTheDefaults)
{
    for (const char* option : {"--socket", "--replay", "--calib", "--config", "--check-config"}) {
        std::vector<std::string> arguments = {option, ""};
        if (std::string(option) != "--check-config" && std::string(option) != "--replay")
            arguments.insert(arguments.end(), {"--replay", replay_});
        const ProcessResult result = run(arguments);
        EXPECT_EQ(result.exit_code, 2) << option << ": " << result.err;
        EXPECT_EQ(lines(result.err).size(), 1u) << result.err;
        EXPECT_NE(result.err.find(option), std::string::npos) << result.err;
        EXPECT_NE(result.err.find("empty path"), std::string::npos) << result.err;
    }
}

TEST_F(StereodCli, CheckConfigNamesEveryProblemWithItsLine)
{
    const std::string good = dir_.file("good.yaml");
    std::ofstream(good) << "nearest:\n  percentile: 10\n";
    const ProcessResult valid = run({"--check-config", good});
    EXPECT_EQ(valid.exit_code, 0) << valid.err;

    const std::string bad = dir_.file("bad.yaml");
    std::ofstream(bad) << "nearest:\n  percentile: 500\npublish:\n  depth_max_hz: -1\n";
    const ProcessResult invalid = run({"--check-config", bad});
    EXPECT_EQ(invalid.exit_code, 3);
    const std::vector<std::string> problems = lines(invalid.err);
    ASSERT_EQ(problems.size(), 2u) << invalid.err;
    EXPECT_EQ(problems[0].rfind(bad + ":2:", 0), 0u) << problems[0];
    EXPECT_NE(problems[0].find("nearest.percentile"), std::string::npos) << problems[0];
    EXPECT_EQ(problems[1].rfind(bad + ":4:", 0), 0u) << problems[1];

    EXPECT_EQ(run({"--check-config", dir_.file("missing.yaml")}).exit_code, 3);
}

TEST_F(StereodCli, CheckConfigChecksTheSettingsAgainstTheCalibrationAsStartUpDoes)
{
    // Valid as a file; with the calibration it names, 1024 disparities leave no column of
    // the 384 px wide frames: start-up refuses it (3), and so does --check-config.
    // (OpenCV's SGBM: census-sgm refuses more than 256 in the file already.)
    const std::string wide = dir_.file("wide.yaml");
    std::ofstream(wide) << "calibration: " << calibration_ << "\n"
                        << "nearest:\n  min_valid_fraction: 0.9\n"
                        << "matcher:\n  algorithm: sgbm\n  num_disparities: 1024\n";
    const ProcessResult checked = run({"--check-config", wide});
    EXPECT_EQ(checked.exit_code, 3) << checked.out << checked.err;
    EXPECT_NE(checked.err.find("matcher.num_disparities"), std::string::npos) << checked.err;
    EXPECT_NE(checked.err.find(calibration_), std::string::npos) << checked.err;
    const ProcessResult started = run({"--config", wide, "--replay", replay_, "--socket", socket_});
    EXPECT_EQ(started.exit_code, 3) << started.err;
    EXPECT_NE(started.err.find("matcher.num_disparities"), std::string::npos) << started.err;

    // A calibration named but missing is the calibration problem start-up calls it (4).
    const std::string missing = dir_.file("missing-calibration.yaml");
    std::ofstream(missing) << "calibration: " << dir_.file("nowhere.yaml") << "\n";
    EXPECT_EQ(run({"--check-config", missing}).exit_code, 4);

    // The same settings within the frame are valid with the calibration.
    const std::string fits = dir_.file("fits.yaml");
    std::ofstream(fits) << "calibration: " << calibration_ << "\n"
                        << "matcher:\n  num_disparities: 64\n";
    const ProcessResult valid = run({"--check-config", fits});
    EXPECT_EQ(valid.exit_code, 0) << valid.err;
    EXPECT_NE(valid.out.find(calibration_), std::string::npos) << valid.out;
}

TEST_F(StereodCli, EachStartUpProblemHasItsExitCode)
{
    // 3: the configuration.
    const std::string bad = dir_.file("bad.yaml");
    std::ofstream(bad) << "nearest:\n  percentile: 500\n";
    ProcessResult result =
        run({"--config", bad, "--replay", replay_, "--calib", calibration_, "--socket", socket_});
    EXPECT_EQ(result.exit_code, 3) << result.err;
    EXPECT_NE(result.err.find("nearest.percentile"), std::string::npos) << result.err;

    // 4: a calibration given but missing, unreadable or not of the frames' size (none at
    // all is the uncalibrated mode, tests/ctl/record_e2e_test.cpp).
    result = run({"--replay", replay_, "--calib", dir_.file("missing.yaml"), "--socket", socket_});
    EXPECT_EQ(result.exit_code, 4) << result.err;
    EXPECT_NE(result.err.find("missing.yaml"), std::string::npos) << result.err;
    const std::string garbage = dir_.file("garbage.yaml");
    std::ofstream(garbage) << "stereod_calibration: 1\nkind: rectified\n";
    result = run({"--replay", replay_, "--calib", garbage, "--socket", socket_});
    EXPECT_EQ(result.exit_code, 4) << result.err;
    EXPECT_NE(result.err.find("garbage.yaml"), std::string::npos) << result.err;
    const std::string other_size = dir_.file("vga.yaml");
    saveCalibration(makeRectifiedCalibration(cv::Size(640, 480), 615.0, 0.013), other_size);
    result = run({"--replay", replay_, "--calib", other_size, "--socket", socket_});
    EXPECT_EQ(result.exit_code, 4) << result.err;
    EXPECT_NE(result.err.find("640x480"), std::string::npos) << result.err;

    // 5: the source: no such recording, or nothing readable in it.
    result = run({"--replay", dir_.file("nowhere"), "--calib", calibration_, "--socket", socket_});
    EXPECT_EQ(result.exit_code, 5) << result.err;
    EXPECT_NE(result.err.find("nowhere"), std::string::npos) << result.err;
    const std::string empty = dir_.file("empty");
    std::filesystem::create_directory(empty);
    result = run({"--replay", empty, "--calib", calibration_, "--socket", socket_});
    EXPECT_EQ(result.exit_code, 5) << result.err;

    // 6: the socket.
    const std::string blocker = dir_.file("file");
    std::ofstream(blocker) << "x";
    result = run({"--replay", replay_, "--calib", calibration_, "--socket", blocker + "/s.sock"});
    EXPECT_EQ(result.exit_code, 6) << result.err;
    EXPECT_NE(result.err.find(blocker), std::string::npos) << result.err;
    EXPECT_FALSE(std::filesystem::exists(socket_));
}

// Issue 23: bags that lie about their images crashed stereod at start-up (SIGSEGV in
// cvtColor; OpenCV's bare "_step >= minstep" and exit 1, no file named) or made it
// allocate what a zstd frame header states (std::bad_alloc). Each is now the source's
// start-up problem, exit 5, with the bag and the reason.
TEST_F(StereodCli, BagsThatLieAreRefusedWithTheirReasonNotACrash)
{
    const auto lying = [](const char* encoding, uint32_t width, uint32_t step, int64_t stamp_ns) {
        test::ImageMessage m;
        m.stamp_ns = stamp_ns;
        m.encoding = encoding;
        m.width = width;
        m.height = 1;
        m.step = step;
        m.data.assign(64, '\x40');
        return m;
    };
    struct Case {
        std::string name;
        std::string bytes_or_empty; // a bag given as bytes, else written from `pair`
        std::pair<test::ImageMessage, test::ImageMessage> pair;
        std::string why;
    };
    const std::vector<Case> cases = {
        {"rgba8.mcap",
         "",
         {lying("rgba8", 1u << 30, 0, 1'000'000'000), lying("rgba8", 1u << 30, 0, 1'000'000'000)},
         "1073741824x1 pixels, more than a frame may have"},
        {"rgb8.mcap",
         "",
         {lying("rgb8", 0x55555556u, 2, 1'000'000'000),
          lying("rgb8", 0x55555556u, 2, 1'000'000'000)},
         "1431655766x1 pixels, more than a frame may have"},
        {"zstd.mcap",
         test::chunkBag(test::lyingZstdFrame(uint64_t{1} << 40), uint64_t{1} << 40),
         {},
         "more than a chunk may hold"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        const std::string bag = dir_.file(c.name);
        if (c.bytes_or_empty.empty())
            test::writeStereoBag(bag, {c.pair});
        else
            std::ofstream(bag, std::ios::binary) << c.bytes_or_empty;
        const ProcessResult result = run({"--replay", bag, "--socket", socket_});
        EXPECT_EQ(result.signal, 0) << result.err;
        EXPECT_EQ(result.exit_code, 5) << result.err;
        EXPECT_NE(result.err.find(bag), std::string::npos) << result.err;
        EXPECT_NE(result.err.find(c.why), std::string::npos) << result.err;
    }
}

TEST_F(StereodCli, ServesAReplayAndStopsOnSigterm)
{
    // The recording's own calibration.yaml is used when --calib is not given.
    std::filesystem::copy_file(calibration_, replay_ + "/calibration.yaml");
    ChildProcess service(
        {stereodPath(), "--replay", replay_, "--socket", socket_, "--log-level", "debug"},
        dir_.file("stereod.log"));
    const auto log = [&] {
        std::ifstream file(dir_.file("stereod.log"));
        return std::string(std::istreambuf_iterator<char>(file), {});
    };
    std::unique_ptr<TestClient> client = test::connectWhenListening(service, socket_);
    ASSERT_TRUE(client) << "stereod exited during start-up:\n" << log();
    Json reading;
    ASSERT_TRUE(waitUntil([&] {
        reading = client->request({{"cmd", "distance"}})["reading"];
        return reading["valid"] == true;
    })) << reading.dump()
        << "\n"
        << log();
    EXPECT_NEAR(reading["distance_m"].get<double>(), 0.57, 0.05);

    // SIGHUP without a configuration file: refused, logged, and the service goes on.
    service.sendSignal(SIGHUP);
    EXPECT_EQ(client->request({{"cmd", "hello"}})["ok"], true);

    service.sendSignal(SIGTERM);
    const std::optional<int> status = service.waitFor(10s);
    ASSERT_TRUE(status.has_value()) << "stereod still running 10 s after SIGTERM";
    ASSERT_TRUE(WIFEXITED(*status)) << "killed by signal " << WTERMSIG(*status);
    EXPECT_EQ(WEXITSTATUS(*status), 0) << log();
    EXPECT_FALSE(std::filesystem::exists(socket_));
    EXPECT_TRUE(client->waitForClose());
    const std::string text = log();
    EXPECT_NE(text.find("disparity range: "), std::string::npos) << text;
    EXPECT_NE(text.find("SIGTERM"), std::string::npos) << text;
}

// Whether `pid` has SIGTERM blocked (from /proc/PID/status): its own code has run.
bool blocksSigterm(pid_t pid)
{
    std::ifstream status("/proc/" + std::to_string(pid) + "/status");
    for (std::string line; std::getline(status, line);) {
        if (line.rfind("SigBlk:", 0) == 0) {
            const unsigned long long mask = std::stoull(line.substr(7), nullptr, 16);
            return (mask & (1ull << (SIGTERM - 1))) != 0;
        }
    }
    return false;
}

TEST_F(StereodCli, SigtermStopsAStartUpBlockedInItsSourceWithinOneSecond)
{
    // frames.csv is a FIFO nobody writes: opening it blocks start-up for ever.
    const std::string recording = dir_.file("fifo");
    std::filesystem::create_directory(recording);
    ASSERT_EQ(::mkfifo((recording + "/frames.csv").c_str(), 0600), 0);
    const auto log = [&] {
        std::ifstream file(dir_.file("stereod.log"));
        return std::string(std::istreambuf_iterator<char>(file), {});
    };
    // At once when the process's own code has run (the libraries' initialisers still
    // ahead of it), and later, while start-up waits in the open().
    for (const auto delay : {0ms, 300ms, 1000ms}) {
        ChildProcess service(
            {stereodPath(), "--replay", recording, "--calib", calibration_, "--socket", socket_},
            dir_.file("stereod.log"));
        ASSERT_TRUE(
            waitUntil([&] { return blocksSigterm(service.pid()) || !service.running(); }, 10s));
        std::this_thread::sleep_for(delay);
        ASSERT_TRUE(service.running()) << log();
        const auto signalled = std::chrono::steady_clock::now();
        service.sendSignal(SIGTERM);
        const std::optional<int> status = service.waitFor(5s);
        const double stop_s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - signalled).count();
        ASSERT_TRUE(status.has_value())
            << "still running 5 s after SIGTERM, " << delay.count() << " ms after start:\n"
            << log();
        ASSERT_TRUE(WIFEXITED(*status)) << "killed by signal " << WTERMSIG(*status) << " "
                                        << delay.count() << " ms after start";
        EXPECT_EQ(WEXITSTATUS(*status), 0) << log();
        EXPECT_LT(stop_s, 1.0) << delay.count() << " ms after start";
        EXPECT_FALSE(std::filesystem::exists(socket_));
    }
}

TEST_F(StereodCli, WarnsWhenTheDisparityCapHidesTheClosestDistance)
{
    // 615 px * 0.013 m / 0.01 m = 800 px of disparity wanted, 64 allowed.
    const std::string text =
        startUpLog("matcher:\n  min_depth_m: 0.01\n  max_num_disparities: 64\n");
    const std::size_t warning = text.find("cannot see closer than ");
    ASSERT_NE(warning, std::string::npos) << text;
    EXPECT_NE(text.find(" m with 64 disparities", warning), std::string::npos) << text;
}

// A region from the image's left edge: its first columns hold no match in the right image
// as near as the range measures, and the service says so when it starts.
TEST_F(StereodCli, WarnsWhenTheRegionMeetsTheLeftEdgeWithinTheRange)
{
    const std::string text =
        startUpLog("nearest:\n  roi: {x: 0.0, y: 0.25, width: 0.5, height: 0.5}\n");
    const std::size_t warning = text.find("[warning] nearest.roi: its columns 0 to ");
    ASSERT_NE(warning, std::string::npos) << text;
    EXPECT_NE(text.find("outside the right camera's view", warning), std::string::npos) << text;
    // Said once, when the chain is set up.
    EXPECT_EQ(text.find("[warning] nearest.roi:", warning + 1), std::string::npos) << text;
}

} // namespace
} // namespace stereod
