// The live view under load: eight of Foxglove's own clients subscribed to every channel
// and reading all they are sent, plus one that subscribes and never reads
// (tests/live_view/load.mjs), for 30 s against a `stereod` replaying at a camera's pace.
// The worker keeps its frame rate (within 10 %), the service's memory stays bounded, and
// the client that never reads is closed and counted while the others get their messages.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/daemon/live_view_service.hpp"

namespace stereod {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

constexpr int kReaders = 8;
constexpr int kLoadSeconds = 30;
constexpr double kCameraFps = 15.0;

// The resident memory of a process, in MiB (VmRSS of /proc/PID/status).
double residentMiB(pid_t pid)
{
    std::ifstream in("/proc/" + std::to_string(pid) + "/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("VmRSS:", 0) == 0)
            return std::stod(line.substr(6)) / 1024.0;
    return 0.0;
}

class LiveViewLoad : public test::LiveViewE2e {
  protected:
    // Frames the worker finished, and when that was asked.
    std::pair<uint64_t, Clock::time_point> frames()
    {
        const uint64_t n = status()["pipeline"]["frames"].get<uint64_t>();
        return {n, Clock::now()};
    }
    static double fps(const std::pair<uint64_t, Clock::time_point>& a,
                      const std::pair<uint64_t, Clock::time_point>& b)
    {
        return static_cast<double>(b.first - a.first) /
               std::chrono::duration<double>(b.second - a.second).count();
    }
};

TEST_F(LiveViewLoad, EightReadersAndOneStuckClientLeaveTheWorkerItsRate)
{
    if (std::string(STEREOD_NODE).empty())
        GTEST_SKIP() << "node is not installed";
    ASSERT_TRUE(
        std::filesystem::exists(test::kClientScripts + "/node_modules/@foxglove/ws-protocol"))
        << "the live view's client packages are missing: run scripts/setup-node.sh";
    const std::string config = dir_.file("camera-pace.yaml");
    std::ofstream(config) << "source:\n  replay:\n    fps: " << kCameraFps << "\n";
    const uint16_t port = test::freePort();
    startService("127.0.0.1:" + std::to_string(port), config);
    ASSERT_FALSE(HasFailure());

    // The worker's rate with nobody watching.
    std::this_thread::sleep_for(2s);
    const auto quiet_start = frames();
    std::this_thread::sleep_for(10s);
    const auto quiet_end = frames();
    const double quiet_fps = fps(quiet_start, quiet_end);
    const double quiet_mib = residentMiB(service_->pid());

    test::ChildProcess load({STEREOD_NODE, test::kClientScripts + "/load.mjs", websocket_,
                             std::to_string(kReaders), std::to_string(kLoadSeconds)},
                            dir_.file("load.log"));
    std::this_thread::sleep_for(3s); // the clients connect and subscribe
    const auto load_start = frames();
    std::vector<double> mib;
    for (int s = 3; s < kLoadSeconds - 1; ++s) {
        std::this_thread::sleep_for(1s);
        mib.push_back(residentMiB(service_->pid()));
    }
    const auto load_end = frames();
    const double load_fps = fps(load_start, load_end);
    const Json live = status()["live_view"];
    const auto line = load.readLine(30s);
    ASSERT_TRUE(line) << "load.mjs printed nothing; see " << dir_.file("load.log");
    const Json got = Json::parse(*line);

    const double peak_mib = *std::max_element(mib.begin(), mib.end());
    const auto half = mib.begin() + static_cast<std::ptrdiff_t>(mib.size() / 2);
    const double first_half_peak = *std::max_element(mib.begin(), half);
    const double second_half_peak = *std::max_element(half, mib.end());
    uint64_t bytes = 0;
    for (const Json& reader : got["readers"])
        bytes += reader["bytes"].get<uint64_t>();
    std::cout << "live view load: worker " << quiet_fps << " fps alone, " << load_fps
              << " fps under load; resident " << quiet_mib << " MiB alone, peak " << peak_mib
              << " MiB (first half " << first_half_peak << ", second half " << second_half_peak
              << "); " << bytes / kLoadSeconds / 1e6 << " MB/s to " << kReaders
              << " readers; frames dropped " << live["frames_dropped"] << ", clients dropped "
              << live["clients_dropped"] << "\nper reader: " << got["readers"][0].dump() << "\n";

    EXPECT_NEAR(quiet_fps, kCameraFps, kCameraFps * 0.1) << "the replay is not at its pace";
    EXPECT_GE(load_fps, 0.9 * quiet_fps);
    // Bounded: what the clients have not read yet is capped (4 MiB each before frames
    // are skipped), so the memory does not grow with time.
    EXPECT_LT(peak_mib, quiet_mib + 100.0);
    EXPECT_LT(second_half_peak, first_half_peak + 16.0);
    // The stuck client: closed, counted, and its frames counted as dropped.
    EXPECT_TRUE(got["stuck"]["subscribed"].get<bool>());
    EXPECT_TRUE(got["stuck"]["closed"].get<bool>()) << got["stuck"].dump();
    EXPECT_EQ(live["clients_dropped"].get<uint64_t>(), 1u);
    EXPECT_GT(live["frames_dropped"].get<uint64_t>(), 0u);
    EXPECT_EQ(live["clients"].get<uint64_t>(), static_cast<uint64_t>(kReaders));
    // Every reader got every channel; the frame channels at a steady rate.
    ASSERT_EQ(got["readers"].size(), static_cast<std::size_t>(kReaders));
    for (const Json& reader : got["readers"]) {
        EXPECT_FALSE(reader["closed"].get<bool>());
        EXPECT_EQ(reader["counts"].size(), 9u) << reader.dump();
        EXPECT_GE(reader["counts"].value("/stereo/depth", 0), 3 * kLoadSeconds) << reader.dump();
        EXPECT_GE(reader["counts"].value("/stereo/points", 0), 3 * kLoadSeconds);
        EXPECT_GE(reader["counts"].value("/stereo/status", 0), kLoadSeconds - 5);
    }
}

} // namespace
} // namespace stereod
