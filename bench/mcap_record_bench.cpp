// mcap_record_bench: how fast `stereoctl record --out FILE.mcap` can write, on one core:
// the bag writer alone (replay/mcap_recording.hpp), fed from memory, with and without
// zstd, with and without each pair's depth and point cloud (--with depth,points).
//
// The pairs are OpenCV's 13 chessboard pairs (raw 640x480 views of a real stereo rig,
// opencv-doc samples); their depth and cloud are what the service's pipeline makes of them
// with the rig's own calibration (bench/bench_data.hpp), computed once before timing; at
// 1280x720 the same, scaled up (scaledTo720p()). The
// bag goes to $TMPDIR (by default /tmp: the page cache, not the disk's speed) and is
// removed after.
//
//   mcap_record_bench [PAIRS]     (default 300 pairs per case)
//
// Prints a table: pairs/s, MB/s of messages in (uncompressed), the share of a core the
// writer needs at 30 pairs/s, and the bag's size per minute at 30 pairs/s.

#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench/bench_data.hpp"
#include "pipeline/stereo_processor.hpp"
#include "replay/mcap_recording.hpp"

namespace stereod::bench {
namespace {

struct RecordedPair {
    cv::Mat left, right;
    cv::Mat depth_m;          // CV_32FC1 metres, 0 = none
    std::vector<float> cloud; // x, y, z, intensity per point
};

std::vector<RecordedPair> chessboardPairs()
{
    const StereoCalibration& calibration = chessboardRigCalibration();
    StereoProcessor processor(calibration, ProcessorSettings{});
    std::vector<RecordedPair> pairs;
    DepthResult result;
    for (int i = 1; i <= 14; ++i) {
        if (i == 10) {
            continue; // no board in pair 10 (see chessboardRigCalibration())
        }
        char name[32];
        RecordedPair pair;
        std::snprintf(name, sizeof name, "/left%02d.jpg", i);
        pair.left =
            cv::imread(STEREOD_OPENCV_SAMPLES_DIR + std::string(name), cv::IMREAD_GRAYSCALE);
        std::snprintf(name, sizeof name, "/right%02d.jpg", i);
        pair.right =
            cv::imread(STEREOD_OPENCV_SAMPLES_DIR + std::string(name), cv::IMREAD_GRAYSCALE);
        if (pair.left.empty() || pair.right.empty()) {
            std::fprintf(stderr, "mcap_record_bench: cannot read the chessboard pair %02d\n", i);
            std::exit(1);
        }
        processor.process(pair.left, pair.right, 0, static_cast<uint64_t>(i), result);
        result.depth_m.copyTo(pair.depth_m);
        const auto* xyzi = reinterpret_cast<const float*>(result.cloud.data());
        pair.cloud.assign(xyzi, xyzi + result.cloud.size() * 4);
        pairs.push_back(std::move(pair));
    }
    return pairs;
}

// The pairs at 1280x720, as a 720p rig would give them in size: images and depth scaled
// up (bilinear; nearest for depth, so that no depth is made up between pixels), and each
// cloud three times over (3 times the pixels, so about 3 times the points). The numbers
// are the 640x480 ones; only their amount, and so the writer's work, is that of 720p.
std::vector<RecordedPair> scaledTo720p(const std::vector<RecordedPair>& pairs)
{
    const cv::Size size(1280, 720);
    std::vector<RecordedPair> scaled;
    for (const RecordedPair& p : pairs) {
        RecordedPair s;
        cv::resize(p.left, s.left, size, 0, 0, cv::INTER_LINEAR);
        cv::resize(p.right, s.right, size, 0, 0, cv::INTER_LINEAR);
        cv::resize(p.depth_m, s.depth_m, size, 0, 0, cv::INTER_NEAREST);
        for (int copy = 0; copy < 3; ++copy) {
            s.cloud.insert(s.cloud.end(), p.cloud.begin(), p.cloud.end());
        }
        scaled.push_back(std::move(s));
    }
    return scaled;
}

double threadCpuSeconds()
{
    timespec t{};
    ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) / 1e9;
}

double wallSeconds()
{
    timespec t{};
    ::clock_gettime(CLOCK_MONOTONIC, &t);
    return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) / 1e9;
}

// What is recorded beside the images.
enum class Results { None, Depth, DepthAndPoints };

void runCase(const std::vector<RecordedPair>& pairs, int count, bool zstd, Results results)
{
    const std::filesystem::path dir =
        std::getenv("TMPDIR") != nullptr ? std::getenv("TMPDIR") : "/tmp";
    const std::string path = (dir / ("mcap_record_bench_" + std::to_string(::getpid()) + ".mcap"));
    mcap::WriterOptions options = McapRecordingWriter::defaultOptions();
    options.compression =
        zstd ? mcap::WriterOptions::Compression::Zstd : mcap::WriterOptions::Compression::None;
    double wall = 0.0, cpu = 0.0;
    uint64_t in_bytes = 0, file_bytes = 0;
    {
        McapRecordingWriter writer(path, options);
        if (results != Results::None) {
            writer.enableDepth();
        }
        if (results == Results::DepthAndPoints) {
            writer.enablePoints();
        }
        const double wall_start = wallSeconds();
        const double cpu_start = threadCpuSeconds();
        constexpr int64_t kPeriodNs = 33'333'333;
        for (int i = 0; i < count; ++i) {
            const RecordedPair& p = pairs[static_cast<std::size_t>(i) % pairs.size()];
            const int64_t stamp_ns = 1'000'000'000 + i * kPeriodNs;
            writer.write(p.left, p.right, stamp_ns, stamp_ns + 1000);
            if (results != Results::None) {
                writer.writeDepth(p.depth_m, stamp_ns);
            }
            if (results == Results::DepthAndPoints) {
                writer.writePoints(p.cloud.data(), p.cloud.size() / 4, stamp_ns);
            }
        }
        writer.close();
        wall = wallSeconds() - wall_start;
        cpu = threadCpuSeconds() - cpu_start;
        in_bytes = writer.file().uncompressedBytes();
        file_bytes = writer.file().bytesWritten();
    }
    std::filesystem::remove(path);
    const double pairs_per_s = count / wall;
    std::printf("| %dx%d | %s | %s | %.0f | %.0f | %.2f of a core | %.0f MB |\n",
                pairs[0].left.cols, pairs[0].left.rows,
                results == Results::None    ? "images"
                : results == Results::Depth ? "images, depth"
                                            : "images, depth, points",
                zstd ? "zstd (level 1)" : "none", pairs_per_s,
                static_cast<double>(in_bytes) / 1e6 / wall, cpu / count * 30.0,
                static_cast<double>(file_bytes) / count * 30.0 * 60.0 / 1e6);
    std::fflush(stdout);
}

} // namespace
} // namespace stereod::bench

int main(int argc, char** argv)
{
    using namespace stereod::bench;
    const int count = argc > 1 ? std::atoi(argv[1]) : 300;
    if (count < 1) {
        std::fprintf(stderr, "usage: mcap_record_bench [PAIRS]\n");
        return 2;
    }
    const std::vector<RecordedPair> pairs = chessboardPairs();
    std::size_t points = 0;
    for (const RecordedPair& p : pairs) {
        points += p.cloud.size() / 4;
    }
    std::printf("%d pairs per case; %zu points per cloud on average\n\n", count,
                points / pairs.size());
    std::printf("| size | recorded | compression | pairs/s | MB/s in | CPU at 30 pairs/s | "
                "per minute at 30 pairs/s |\n|---|---|---|---|---|---|---|\n");
    for (const std::vector<RecordedPair>& set : {pairs, scaledTo720p(pairs)}) {
        for (const Results results : {Results::None, Results::Depth, Results::DepthAndPoints}) {
            for (const bool zstd : {true, false}) {
                runCase(set, count, zstd, results);
            }
        }
    }
    return 0;
}
