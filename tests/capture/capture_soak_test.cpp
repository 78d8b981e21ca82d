// Soak: the two-camera source against the fake V4L2 device at 30 fps for 60 s, with the
// right camera unplugged and replugged every 15 s. Memory (RSS) and open file
// descriptors are sampled at the same point of each cycle (just before the next unplug,
// long after the camera came back): after the first cycle (warm-up: pools, caches,
// logger) neither may grow. Pairs must keep coming in every cycle.
//
// Label "soak": CI runs it once, in the normal pass (not under the sanitizers).

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "capture/stereo_camera_source.hpp"
#include "tests/fake_v4l2/fake_v4l2.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

namespace fs = std::filesystem;

constexpr int kCycles = 4;
constexpr int kCycleSeconds = 15;
constexpr double kFps = 30.0;

long residentKiB()
{
    std::ifstream statm("/proc/self/statm");
    long size_pages = 0;
    long resident_pages = 0;
    statm >> size_pages >> resident_pages;
    return resident_pages * (sysconf(_SC_PAGESIZE) / 1024);
}

int openFds()
{
    int count = 0;
    for ([[maybe_unused]] const fs::directory_entry& entry :
         fs::directory_iterator("/proc/self/fd"))
        ++count;
    return count;
}

TEST(CaptureSoakTest, SixtySecondsAt30FpsWithReplugsGrowNeitherMemoryNorFds)
{
    const fs::path dir = fs::temp_directory_path() / ("capture_soak_" + std::to_string(getpid()));
    fs::create_directories(dir);
    const std::string samples = test::opencvSamplesDir();
    {
        std::ofstream out(dir / "devices.yaml");
        out << "devices:\n";
        for (const char* side : {"L", "R"})
            out << "  - path: /dev/video-soak-" << side << "\n"
                << "    images: " << samples << "/aloe" << side << ".jpg\n"
                << "    fps: " << kFps << "\n"
                << "    jitter_ms: 1\n"
                << "    formats:\n"
                << "      - fourcc: YUYV\n"
                << "        sizes: [640x480]\n";
    }
    ASSERT_EQ(stereod_fake_v4l2_load((dir / "devices.yaml").c_str()), 0)
        << stereod_fake_v4l2_last_error();

    StereoCameraOptions options;
    const std::size_t ring_capacity = 2;
    for (CameraSettings* camera : {&options.left, &options.right}) {
        camera->format = PixelFormatChoice::Yuyv;
        camera->width = 640;
        camera->height = 480;
        camera->fps = kFps;
        camera->buffer_count =
            cameraBufferCount(ring_capacity, options.sync, options.inbox_capacity);
    }
    options.left.device = "/dev/video-soak-L";
    options.right.device = "/dev/video-soak-R";

    std::vector<long> rss_kib;
    std::vector<int> fds;
    std::vector<uint64_t> pairs_per_cycle;
    {
        StereoCameraSource source(options);
        PairRing ring(ring_capacity);
        ASSERT_EQ(source.start(ring), 0) << source.status().last_error;
        uint64_t pairs = 0;
        std::thread consumer([&] {
            while (ring.pop())
                ++pairs; // the pair is released at once, as a fast worker would
        });
        uint64_t pairs_before = 0;
        for (int cycle = 0; cycle < kCycles; ++cycle) {
            // Unplug the right camera for a second at the start of each cycle but the
            // first; sample at the end, long after it came back.
            if (cycle > 0) {
                ASSERT_EQ(stereod_fake_v4l2_unplug("/dev/video-soak-R"), 0);
                std::this_thread::sleep_for(std::chrono::seconds(1));
                ASSERT_EQ(stereod_fake_v4l2_replug("/dev/video-soak-R"), 0);
                std::this_thread::sleep_for(std::chrono::seconds(kCycleSeconds - 1));
            } else {
                std::this_thread::sleep_for(std::chrono::seconds(kCycleSeconds));
            }
            const uint64_t delivered = ring.pushed();
            pairs_per_cycle.push_back(delivered - pairs_before);
            pairs_before = delivered;
            rss_kib.push_back(residentKiB());
            fds.push_back(openFds());
            const SourceStatus status = source.status();
            std::printf("cycle %d: %llu pairs, RSS %ld KiB, %d fds, state %s\n", cycle,
                        static_cast<unsigned long long>(pairs_per_cycle.back()), rss_kib.back(),
                        fds.back(), toString(status.state));
            std::fflush(stdout);
        }
        source.stop();
        ring.stop();
        consumer.join();
        EXPECT_GT(pairs, 0u);
    }
    stereod_fake_v4l2_unload();
    fs::remove_all(dir);

    for (int cycle = 0; cycle < kCycles; ++cycle)
        EXPECT_GT(pairs_per_cycle[static_cast<size_t>(cycle)],
                  static_cast<uint64_t>(kFps * kCycleSeconds / 3))
            << "pairs keep coming in cycle " << cycle;
    for (int cycle = 2; cycle < kCycles; ++cycle) {
        EXPECT_EQ(fds[static_cast<size_t>(cycle)], fds[1]) << "open fds after cycle " << cycle;
        EXPECT_LE(rss_kib[static_cast<size_t>(cycle)], rss_kib[1] + 2048)
            << "RSS grew by more than 2 MiB after warm-up, cycle " << cycle;
    }
}

} // namespace
} // namespace stereod
