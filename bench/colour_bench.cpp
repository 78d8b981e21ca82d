// colour_bench: what carrying the left camera's colour costs the pipeline at 640x480, per
// stage, beside the grey stages it rides along with: the colour left rectified through
// the same fixed-point maps (Rectifier, CV_8UC3), the cloud's colours (cloudColours), and
// StereoProcessor::process() with and without the colour image. The plausible rig of the
// benchmarks (bench_data: f = 0.9 x width, 0.5 degree rotation, 6 cm baseline) and the
// Aloe photograph in colour, simulated as the rig's raw left view. Every case counts the
// allocations per frame (bench/alloc_counter). Results: bench/README.md, "Colour".

#include <cstdint>
#include <stdexcept>
#include <string>

#include <benchmark/benchmark.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench/alloc_counter.hpp"
#include "bench/bench_data.hpp"
#include "pipeline/rectifier.hpp"
#include "pipeline/stereo_processor.hpp"
#include "pipeline/triangulation.hpp"

namespace {

using namespace stereod;

const cv::Size kSize(640, 480);

struct Inputs {
    StereoCalibration calibration;
    bench::ImagePair raw; // grey, the matcher's input
    cv::Mat raw_left_colour;
};

// The colour photograph through the same simulated raw view as the grey pair: each
// channel warped like the grey image (simulateRawPair works on one channel).
const Inputs& inputs()
{
    static const Inputs in = [] {
        Inputs made;
        made.calibration = bench::makePlausibleRigCalibration(kSize);
        const bench::ImagePair scene = bench::loadScene(bench::scenes()[0], kSize);
        made.raw = bench::simulateRawPair(made.calibration, scene);
        const cv::Mat photo =
            cv::imread(std::string(STEREOD_OPENCV_SAMPLES_DIR) + "/aloeL.jpg", cv::IMREAD_COLOR);
        if (photo.empty())
            throw std::runtime_error("OpenCV sample aloeL.jpg missing");
        cv::Mat colour;
        cv::resize(photo, colour, kSize, 0, 0, cv::INTER_AREA);
        cv::Mat planes[3];
        cv::split(colour, planes);
        for (cv::Mat& plane : planes) {
            bench::ImagePair pair{plane, plane};
            plane = bench::simulateRawPair(made.calibration, pair).left;
        }
        cv::merge(planes, 3, made.raw_left_colour);
        return made;
    }();
    return in;
}

template <typename Work> void timed(benchmark::State& state, Work&& work)
{
    work(); // the first frame makes the outputs
    uint64_t cpp = 0, mat = 0, frames = 0;
    for (auto _ : state) {
        const bench::AllocationWindow window;
        work();
        cpp += window.cppAllocations();
        mat += window.matAllocations();
        ++frames;
    }
    state.counters["allocs_per_frame"] = static_cast<double>(cpp) / static_cast<double>(frames);
    state.counters["mat_allocs_per_frame"] = static_cast<double>(mat) / static_cast<double>(frames);
}

void BM_RectifyLeftGrey(benchmark::State& state)
{
    const Rectifier rectifier(inputs().calibration);
    cv::Mat out;
    timed(state, [&] { rectifier.rectifyLeft(inputs().raw.left, out); });
}

void BM_RectifyLeftColour(benchmark::State& state)
{
    const Rectifier rectifier(inputs().calibration);
    cv::Mat out;
    timed(state, [&] { rectifier.rectifyLeft(inputs().raw_left_colour, out); });
}

// The processor's stage timings, averaged, as counters (ms per frame).
void process(benchmark::State& state, bool colour)
{
    ProcessorSettings settings;
    settings.matcher.num_disparities = 128;
    StereoProcessor processor(inputs().calibration, settings);
    DepthResult result;
    const cv::Mat none;
    const cv::Mat& left_colour = colour ? inputs().raw_left_colour : none;
    StageTimings sum;
    uint64_t frame = 0;
    timed(state, [&] {
        processor.process(inputs().raw.left, left_colour, inputs().raw.right, 0, frame++, result);
        sum.rectify_ms += result.timings.rectify_ms;
        sum.colour_ms += result.timings.colour_ms;
        sum.match_ms += result.timings.match_ms;
        sum.cloud_ms += result.timings.cloud_ms;
        sum.cloud_colour_ms += result.timings.cloud_colour_ms;
    });
    const double n = static_cast<double>(frame);
    state.counters["rectify_ms"] = sum.rectify_ms / n;
    state.counters["colour_ms"] = sum.colour_ms / n;
    state.counters["match_ms"] = sum.match_ms / n;
    state.counters["cloud_ms"] = sum.cloud_ms / n;
    state.counters["cloud_colour_ms"] = sum.cloud_colour_ms / n;
    state.counters["points"] = static_cast<double>(result.cloud.size());
}

void BM_ProcessGrey(benchmark::State& state)
{
    process(state, false);
}
void BM_ProcessColour(benchmark::State& state)
{
    process(state, true);
}

BENCHMARK(BM_RectifyLeftGrey)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RectifyLeftColour)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ProcessGrey)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
BENCHMARK(BM_ProcessColour)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

} // namespace

int main(int argc, char** argv)
{
    stereod::bench::installCountingMatAllocator();
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv))
        return 2;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
