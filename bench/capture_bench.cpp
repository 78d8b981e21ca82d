// capture_bench: what live capture costs, from the driver's "frame done" to a stereo pair
// in the PairRing, for YUYV and MJPEG at 640x480 and 1280x720, against the fake V4L2
// device (tests/fake_v4l2/) at 30 fps.
//
// The production path runs unchanged: StereoCameraSource -> two V4l2Cameras (libv4l2,
// mmap buffers, poll, luma copy or TurboJPEG decode into a pool buffer) -> StereoSyncThread
// -> PairRing. The consumer (this thread) pops each pair and releases it at once.
//
// - latency: CLOCK_MONOTONIC at pop minus the pair's capture stamp (the left frame's
//   kernel stamp, which the fake takes when it marks the buffer DONE, as a driver does at
//   end of frame). p50, p99 and max over the measured pairs.
// - CPU per frame: process CPU time minus the fake's producer threads ("fake-v4l2": they
//   stand in for the camera's DMA) minus this consumer thread, divided by the frames
//   captured (two per pair). It is the capture threads' and the sync thread's work.
//
// Usage: capture_bench [--seconds S] (default 5 per case, after 1 s of warm-up).

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <dirent.h>
#include <time.h>
#include <unistd.h>

#include "capture/frame.hpp"
#include "capture/stereo_camera_source.hpp"
#include "tests/fake_v4l2/fake_v4l2.hpp"

namespace {

namespace fs = std::filesystem;
using namespace stereod;

struct Case {
    const char* format; // fourcc in the fake's description
    PixelFormatChoice choice;
    int width;
    int height;
};

struct Result {
    Case c;
    uint64_t pairs = 0;
    double seconds = 0.0;
    double latency_p50_ms = 0.0;
    double latency_p99_ms = 0.0;
    double latency_max_ms = 0.0;
    double cpu_ms_per_frame = 0.0;
    double cpu_percent = 0.0; // of one core, for both cameras and the sync
    uint64_t unpaired = 0;
    std::string error;
};

int64_t clockNs(clockid_t clock)
{
    timespec ts{};
    clock_gettime(clock, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// CPU time (ns) of this process's threads named `name`, from /proc/self/task/*/stat.
int64_t threadsCpuNs(const std::string& name)
{
    const long ticks = sysconf(_SC_CLK_TCK);
    int64_t total = 0;
    for (const fs::directory_entry& task : fs::directory_iterator("/proc/self/task")) {
        std::ifstream comm(task.path() / "comm");
        std::string thread_name;
        std::getline(comm, thread_name);
        if (thread_name != name)
            continue;
        std::ifstream stat_file(task.path() / "stat");
        std::string stat;
        std::getline(stat_file, stat);
        // Fields after the ")" closing the name: state is field 3, utime 14, stime 15.
        const size_t close = stat.rfind(')');
        if (close == std::string::npos)
            continue;
        std::vector<std::string> fields;
        std::string field;
        for (size_t i = close + 2; i <= stat.size(); ++i) {
            if (i == stat.size() || stat[i] == ' ') {
                fields.push_back(field);
                field.clear();
            } else {
                field += stat[i];
            }
        }
        if (fields.size() > 12)
            total += (std::stoll(fields[11]) + std::stoll(fields[12])) * 1'000'000'000 / ticks;
    }
    return total;
}

double percentile(std::vector<double> values, double q)
{
    if (values.empty())
        return 0.0;
    std::sort(values.begin(), values.end());
    const size_t index =
        std::min(values.size() - 1, static_cast<size_t>(q * static_cast<double>(values.size())));
    return values[index];
}

Result run(const Case& c, double seconds, const fs::path& dir)
{
    Result result;
    result.c = c;
    const std::string samples = STEREOD_OPENCV_SAMPLES_DIR;
    const fs::path description = dir / "devices.yaml";
    {
        std::ofstream out(description);
        out << "devices:\n";
        for (const char* side : {"L", "R"}) {
            out << "  - path: /dev/video-bench-" << side << "\n"
                << "    images: " << samples << "/aloe" << side << ".jpg\n"
                << "    fps: 30\n"
                << "    jitter_ms: 0.5\n"
                << "    phase_ms: " << (side[0] == 'L' ? 0.0 : 1.0) << "\n"
                << "    formats:\n"
                << "      - fourcc: " << c.format << "\n"
                << "        sizes: [" << c.width << "x" << c.height << "]\n";
        }
    }
    if (stereod_fake_v4l2_load(description.c_str()) != 0) {
        result.error = stereod_fake_v4l2_last_error();
        return result;
    }
    StereoCameraOptions options;
    const std::size_t ring_capacity = 2;
    for (CameraSettings* camera : {&options.left, &options.right}) {
        camera->format = c.choice;
        camera->width = c.width;
        camera->height = c.height;
        camera->fps = 30.0;
        camera->buffer_count =
            cameraBufferCount(ring_capacity, options.sync, options.inbox_capacity);
    }
    options.left.device = "/dev/video-bench-L";
    options.right.device = "/dev/video-bench-R";
    {
        StereoCameraSource source(options);
        PairRing ring(ring_capacity);
        if (source.start(ring) != 0) {
            result.error = source.status().last_error;
            stereod_fake_v4l2_unload();
            return result;
        }
        const int64_t warm_until = monotonicNowNs() + 1'000'000'000;
        while (monotonicNowNs() < warm_until)
            ring.pop();
        const uint64_t unpaired_before = source.status().unpaired_dropped;
        std::vector<double> latencies_ms;
        latencies_ms.reserve(static_cast<size_t>(seconds * 40));
        const int64_t start_ns = monotonicNowNs();
        const int64_t cpu_start = clockNs(CLOCK_PROCESS_CPUTIME_ID);
        const int64_t fake_start = threadsCpuNs("fake-v4l2");
        const int64_t self_start = clockNs(CLOCK_THREAD_CPUTIME_ID);
        const int64_t end_ns = start_ns + static_cast<int64_t>(seconds * 1e9);
        int64_t now_ns = start_ns;
        while (now_ns < end_ns) {
            std::optional<StereoPair> pair = ring.pop();
            now_ns = monotonicNowNs();
            if (!pair)
                break;
            latencies_ms.push_back(static_cast<double>(now_ns - pair->stampNs()) / 1e6);
        }
        const int64_t cpu_ns = clockNs(CLOCK_PROCESS_CPUTIME_ID) - cpu_start -
                               (threadsCpuNs("fake-v4l2") - fake_start) -
                               (clockNs(CLOCK_THREAD_CPUTIME_ID) - self_start);
        result.seconds = static_cast<double>(now_ns - start_ns) / 1e9;
        result.unpaired = source.status().unpaired_dropped - unpaired_before;
        source.stop();
        result.pairs = latencies_ms.size();
        result.latency_p50_ms = percentile(latencies_ms, 0.5);
        result.latency_p99_ms = percentile(latencies_ms, 0.99);
        result.latency_max_ms = latencies_ms.empty()
                                    ? 0.0
                                    : *std::max_element(latencies_ms.begin(), latencies_ms.end());
        if (result.pairs > 0) {
            result.cpu_ms_per_frame =
                static_cast<double>(cpu_ns) / 1e6 / (2.0 * static_cast<double>(result.pairs));
            result.cpu_percent = 100.0 * static_cast<double>(cpu_ns) / 1e9 / result.seconds;
        }
    }
    stereod_fake_v4l2_unload();
    return result;
}

} // namespace

int main(int argc, char** argv)
{
    double seconds = 5.0;
    for (int i = 1; i < argc; ++i) {
        if (std::strcmp(argv[i], "--seconds") == 0 && i + 1 < argc) {
            seconds = std::atof(argv[++i]);
        } else {
            std::fprintf(stderr, "capture_bench: unknown argument '%s' (expected --seconds S)\n",
                         argv[i]);
            return 2;
        }
    }
    if (seconds <= 0.0) {
        std::fprintf(stderr, "capture_bench: --seconds must be > 0\n");
        return 2;
    }
    const fs::path dir = fs::temp_directory_path() / ("capture_bench_" + std::to_string(getpid()));
    fs::create_directories(dir);
    const Case cases[] = {
        {"YUYV", PixelFormatChoice::Yuyv, 640, 480},
        {"YUYV", PixelFormatChoice::Yuyv, 1280, 720},
        {"MJPG", PixelFormatChoice::Mjpeg, 640, 480},
        {"MJPG", PixelFormatChoice::Mjpeg, 1280, 720},
    };
    std::vector<Result> results;
    for (const Case& c : cases) {
        std::fprintf(stderr, "capture_bench: %s %dx%d for %.1f s...\n", c.format, c.width, c.height,
                     seconds);
        results.push_back(run(c, seconds, dir));
    }
    fs::remove_all(dir);

    int status = 0;
    std::printf(
        "\nCapture to pair, two fake cameras at 30 fps (stamp -> pair popped from the ring)\n\n");
    std::printf("| format | size      | pairs | pairs/s | unpaired | latency p50 ms | p99 ms | max "
                "ms | CPU ms/frame | CPU %% of a core |\n");
    std::printf("|--------|-----------|------:|--------:|---------:|---------------:|-------:|-----"
                "--:|-------------:|----------------:|\n");
    for (const Result& r : results) {
        if (!r.error.empty()) {
            std::printf("| %s | %dx%d | error: %s |\n", r.c.format, r.c.width, r.c.height,
                        r.error.c_str());
            status = 1;
            continue;
        }
        std::printf("| %-6s | %4dx%-4d | %5llu | %7.1f | %8llu | %14.2f | %6.2f | %6.2f | %12.3f | "
                    "%15.1f |\n",
                    r.c.format, r.c.width, r.c.height, static_cast<unsigned long long>(r.pairs),
                    static_cast<double>(r.pairs) / r.seconds,
                    static_cast<unsigned long long>(r.unpaired), r.latency_p50_ms, r.latency_p99_ms,
                    r.latency_max_ms, r.cpu_ms_per_frame, r.cpu_percent);
    }
    return status;
}
