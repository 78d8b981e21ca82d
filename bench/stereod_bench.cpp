// stereod_bench: what each stage of the stereo pipeline costs on real images, next to
// OpenCV's matcher alone, and whether process() allocates in steady state.
//
// Benchmarks (names are key:value paths, so --benchmark_filter can pick any subset):
//   pipeline/scene:S/size:WxH/matcher:M/disp:N  StereoProcessor::process() on a raw pair
//   opencv/scene:S/size:WxH/stage:rectify       cv::remap of both images alone, same maps
//   opencv/scene:S/size:WxH/matcher:M/disp:N    cv::StereoBM / cv::StereoSGBM compute()
//                                               alone, same rectified input, same parameters
//   publish/scene:S/size:WxH                    the hand-over of a result to the I/O side
// After the run, markdown tables put them side by side (bench/README.md explains them).

#include <chrono>
#include <cstdint>
#include <exception>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <unistd.h>

#include "bench/alloc_counter.hpp"
#include "bench/bench_data.hpp"
#include "bench/publish_stage.hpp"
#include "bench/summary_table.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/stereo_processor.hpp"

namespace stereod::bench {
namespace {

using Clock = std::chrono::steady_clock;

const std::vector<cv::Size> kSizes = {{640, 480}, {1280, 720}};
const std::vector<MatcherKind> kMatchers = {MatcherKind::Bm, MatcherKind::Sgbm};
const std::vector<int> kDisparities = {64, 128};
// Nominal capture period, for the stamps the pipeline carries along (30 fps).
constexpr int64_t kFramePeriodNs = 33'333'333;

struct Case {
    const Scene* scene = nullptr;
    cv::Size size;
    MatcherKind matcher = MatcherKind::Sgbm;
    int num_disparities = 0;
};

std::string key(const Scene& scene, cv::Size size)
{
    return "scene:" + scene.name + "/size:" + std::to_string(size.width) + "x" +
           std::to_string(size.height);
}

const char* matcherLabel(MatcherKind kind)
{
    return kind == MatcherKind::Bm ? "bm" : "sgbm";
}

std::string key(const Case& c)
{
    return key(*c.scene, c.size) + "/matcher:" + matcherLabel(c.matcher) +
           "/disp:" + std::to_string(c.num_disparities);
}

// The service's defaults, with the matcher and disparity range of the case.
ProcessorSettings settingsFor(const Case& c)
{
    ProcessorSettings settings;
    settings.matcher.kind = c.matcher;
    settings.matcher.num_disparities = c.num_disparities;
    settings.compute_cloud = true;
    return settings;
}

// Everything a scene at one size needs, built once per process: building it costs far
// more than a frame (undistortPoints over every pixel).
struct SceneInputs {
    StereoCalibration calibration;
    ImagePair raw;       // what the plausible rig would capture: the pipeline's input
    RectifyMaps maps;    // the maps the pipeline's rectify stage uses
    ImagePair rectified; // rectified with those maps: the matchers' input
};

const SceneInputs& sceneInputs(const Scene& scene, cv::Size size)
{
    static std::map<std::string, std::unique_ptr<SceneInputs>> cache;
    std::unique_ptr<SceneInputs>& slot = cache[key(scene, size)];
    if (!slot) {
        auto inputs = std::make_unique<SceneInputs>();
        inputs->calibration = makePlausibleRigCalibration(size);
        validateCalibration(inputs->calibration, "plausible rig " + key(scene, size));
        inputs->raw = simulateRawPair(inputs->calibration, loadScene(scene, size));
        inputs->maps = makeRectifyMaps(inputs->calibration);
        rectifyPair(inputs->maps, inputs->raw, inputs->rectified);
        slot = std::move(inputs);
    }
    return *slot;
}

// A processor that has seen its first frame, so what follows is steady state. Google
// Benchmark calls a benchmark function several times (to size the iteration count, and
// once per repetition); the last rig is kept so that warm-up happens once per case.
struct PipelineRig {
    std::string key;
    std::unique_ptr<StereoProcessor> processor;
    DepthResult result;
    uint64_t next_frame = 0;

    void processNext(const ImagePair& raw)
    {
        processor->process(raw.left, raw.right, static_cast<int64_t>(next_frame) * kFramePeriodNs,
                           next_frame, result);
        ++next_frame;
    }
};

PipelineRig& pipelineRig(const Case& c)
{
    static std::unique_ptr<PipelineRig> rig;
    if (!rig || rig->key != key(c)) {
        rig.reset(); // free the previous case's buffers before allocating new ones
        const SceneInputs& inputs = sceneInputs(*c.scene, c.size);
        auto fresh = std::make_unique<PipelineRig>();
        fresh->key = key(c);
        fresh->processor = std::make_unique<StereoProcessor>(inputs.calibration, settingsFor(c));
        fresh->processNext(inputs.raw);
        rig = std::move(fresh);
    }
    return *rig;
}

// Per-frame sums over the timed iterations, turned into per-frame counters at the end.
class FrameTally {
  public:
    void add(double wall_s, const AllocationWindow& window)
    {
        ++frames_;
        wall_ms_ += wall_s * 1e3;
        cpp_allocs_ += window.cppAllocations();
        mat_allocs_ += window.matAllocations();
    }

    void addStages(const StageTimings& timings)
    {
        stages_.rectify_ms += timings.rectify_ms;
        stages_.match_ms += timings.match_ms;
        stages_.depth_ms += timings.depth_ms;
        stages_.nearest_ms += timings.nearest_ms;
        stages_.cloud_ms += timings.cloud_ms;
    }

    // wall_ms under `time_name`, fps, allocations; the stages when addStages() was used.
    void report(benchmark::State& state, const std::string& time_name, bool with_stages) const
    {
        if (frames_ == 0) {
            return;
        }
        const double n = static_cast<double>(frames_);
        if (with_stages) {
            state.counters["rectify_ms"] = stages_.rectify_ms / n;
            state.counters["match_ms"] = stages_.match_ms / n;
            state.counters["depth_ms"] = stages_.depth_ms / n;
            state.counters["nearest_ms"] = stages_.nearest_ms / n;
            state.counters["cloud_ms"] = stages_.cloud_ms / n;
            state.counters["total_ms"] = stages_.totalMs() / n;
        }
        state.counters[time_name] = wall_ms_ / n;
        state.counters["fps"] = 1e3 * n / wall_ms_;
        state.counters["allocs_per_frame"] = static_cast<double>(cpp_allocs_) / n;
        state.counters["mat_allocs_per_frame"] = static_cast<double>(mat_allocs_) / n;
    }

  private:
    uint64_t frames_ = 0;
    double wall_ms_ = 0.0;
    uint64_t cpp_allocs_ = 0;
    uint64_t mat_allocs_ = 0;
    StageTimings stages_;
};

// Times `work` once per iteration into `tally` (manual time: the work only, none of the
// benchmark's own bookkeeping).
template <typename Work> void timeFrames(benchmark::State& state, FrameTally& tally, Work&& work)
{
    for (auto _ : state) {
        const AllocationWindow window;
        const Clock::time_point start = Clock::now();
        work();
        const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
        state.SetIterationTime(seconds);
        tally.add(seconds, window);
    }
}

void benchPipeline(benchmark::State& state, const Case& c)
{
    PipelineRig* rig = nullptr;
    try {
        rig = &pipelineRig(c);
    } catch (const std::exception& e) {
        state.SkipWithError(e.what());
        return;
    }
    if (rig->result.reading.reason == NoReadingReason::BadFrame) {
        state.SkipWithError("the pipeline rejected the frame pair (bad_frame)");
        return;
    }
    const ImagePair& raw = sceneInputs(*c.scene, c.size).raw;
    FrameTally tally;
    // Summing five doubles inside the timed window costs nanoseconds against milliseconds.
    timeFrames(state, tally, [&] {
        rig->processNext(raw);
        tally.addStages(rig->result.timings);
    });
    tally.report(state, "wall_ms", true);
    state.counters["num_disparities"] = rig->processor->disparityRange().num_disparities;
    state.SetLabel(rig->processor->matcherName());
}

// cv::StereoBM / cv::StereoSGBM with the parameters the pipeline's settings give them.
cv::Ptr<cv::StereoMatcher> makeOpenCvMatcher(const MatcherSettings& s, const DisparityRange& range)
{
    const int channels = 1; // grayscale input
    if (s.kind == MatcherKind::Bm) {
        cv::Ptr<cv::StereoBM> bm = cv::StereoBM::create(range.num_disparities, s.block_size);
        bm->setMinDisparity(range.min_disparity);
        bm->setUniquenessRatio(s.uniqueness_ratio);
        bm->setSpeckleWindowSize(s.speckle_window_px);
        // StereoBM applies the speckle range to its fixed-point output as is (SGBM scales
        // it by 16 itself), so the same range in pixels is 16 x speckle_range_px here.
        bm->setSpeckleRange(s.speckle_range_px * cv::StereoMatcher::DISP_SCALE);
        bm->setDisp12MaxDiff(s.lr_max_diff_px);
        bm->setPreFilterCap(s.pre_filter_cap);
        bm->setTextureThreshold(s.texture_threshold);
        return bm;
    }
    const int area = channels * s.block_size * s.block_size;
    const int p1 = s.p1 > 0 ? s.p1 : 8 * area;
    const int p2 = s.p2 > 0 ? s.p2 : 32 * area;
    // OpenCV's mode for each SgbmMode, in the enum's order (Sgbm, ThreeWay, Hh, Hh4).
    constexpr int kModes[] = {cv::StereoSGBM::MODE_SGBM, cv::StereoSGBM::MODE_SGBM_3WAY,
                              cv::StereoSGBM::MODE_HH, cv::StereoSGBM::MODE_HH4};
    const int mode = kModes[static_cast<int>(s.sgbm_mode)];
    return cv::StereoSGBM::create(range.min_disparity, range.num_disparities, s.block_size, p1, p2,
                                  s.lr_max_diff_px, s.pre_filter_cap, s.uniqueness_ratio,
                                  s.speckle_window_px, s.speckle_range_px, mode);
}

// The scene's inputs, or nullptr after skipping the benchmark with the reason.
const SceneInputs* sceneInputsOrSkip(benchmark::State& state, const Scene& scene, cv::Size size)
{
    try {
        return &sceneInputs(scene, size);
    } catch (const std::exception& e) {
        state.SkipWithError(e.what());
        return nullptr;
    }
}

void benchOpenCvRemap(benchmark::State& state, const Scene& scene, cv::Size size)
{
    const SceneInputs* inputs = sceneInputsOrSkip(state, scene, size);
    if (inputs == nullptr) {
        return;
    }
    ImagePair rectified;
    rectifyPair(inputs->maps, inputs->raw, rectified); // output buffers are sized here
    FrameTally tally;
    timeFrames(state, tally, [&] { rectifyPair(inputs->maps, inputs->raw, rectified); });
    tally.report(state, "rectify_ms", false);
}

void benchOpenCvMatcher(benchmark::State& state, const Case& c)
{
    const SceneInputs* inputs = sceneInputsOrSkip(state, *c.scene, c.size);
    if (inputs == nullptr) {
        return;
    }
    const MatcherSettings settings = settingsFor(c).matcher;
    const DisparityRange range = chooseDisparityRange(settings, inputs->calibration.rectified);
    const cv::Ptr<cv::StereoMatcher> matcher = makeOpenCvMatcher(settings, range);
    cv::Mat disparity_fixed16; // CV_16SC1, 16 x disparity in pixels
    matcher->compute(inputs->rectified.left, inputs->rectified.right, disparity_fixed16);

    FrameTally tally;
    timeFrames(state, tally, [&] {
        matcher->compute(inputs->rectified.left, inputs->rectified.right, disparity_fixed16);
    });
    tally.report(state, "match_ms", false);
    state.counters["num_disparities"] = range.num_disparities;
}

void benchPublish(benchmark::State& state, const Scene& scene, cv::Size size)
{
    // A real result to hand over: SGBM with the larger disparity range on the scene.
    const Case c{&scene, size, MatcherKind::Sgbm, kDisparities.back()};
    std::unique_ptr<PublishStage> publish;
    try {
        publish = std::make_unique<PublishStage>(pipelineRig(c).result);
    } catch (const std::exception& e) {
        state.SkipWithError(e.what());
        return;
    }
    FrameTally tally;
    timeFrames(state, tally, [&] { publish->run(); });
    tally.report(state, "publish_ms", false);
}

void registerBenchmarks(SummaryTable& table)
{
    for (const Scene& scene : scenes()) {
        for (const cv::Size size : kSizes) {
            const std::string remap = "opencv/" + key(scene, size) + "/stage:rectify";
            const std::string publish = "publish/" + key(scene, size);
            benchmark::RegisterBenchmark(remap.c_str(), benchOpenCvRemap, scene, size)
                ->UseManualTime()
                ->Unit(benchmark::kMillisecond);
            for (const int disparities : kDisparities) {
                for (const MatcherKind matcher : kMatchers) {
                    const Case c{&scene, size, matcher, disparities};
                    const std::string pipeline = "pipeline/" + key(c);
                    const std::string opencv = "opencv/" + key(c);
                    benchmark::RegisterBenchmark(pipeline.c_str(), benchPipeline, c)
                        ->UseManualTime()
                        ->Unit(benchmark::kMillisecond);
                    benchmark::RegisterBenchmark(opencv.c_str(), benchOpenCvMatcher, c)
                        ->UseManualTime()
                        ->Unit(benchmark::kMillisecond);
                    table.addRow({scene.name, size, disparities, matcherLabel(matcher), pipeline,
                                  remap, opencv, publish});
                }
            }
            benchmark::RegisterBenchmark(publish.c_str(), benchPublish, scene, size)
                ->UseManualTime()
                ->Unit(benchmark::kMicrosecond);
        }
    }
}

} // namespace
} // namespace stereod::bench

int main(int argc, char** argv)
{
    using namespace stereod::bench;
    installCountingMatAllocator();
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) {
        return 2;
    }
    benchmark::AddCustomContext(
        "allocs_per_frame",
        "C++ allocations only (replaced global operator new), counted over the 2nd..Nth "
        "process() calls on every thread; OpenCV's cv::fastMalloc does not go through "
        "operator new, so cv::Mat buffers are counted separately in mat_allocs_per_frame "
        "(a counting cv::MatAllocator); malloc() inside libraries is not seen");
    benchmark::AddCustomContext("calibration",
                                "a plausible rig built in code (f = 0.9 x width, small k1/k2, "
                                "0.5 degree rotation, 6 cm baseline), not a measured one");
    benchmark::AddCustomContext("publish", PublishStage::description());
    benchmark::AddCustomContext("opencv_threads", std::to_string(cv::getNumThreads()));

    SummaryTable table;
    registerBenchmarks(table);
    const int options = benchmark::ConsoleReporter::OO_Tabular |
                        (isatty(STDOUT_FILENO) ? benchmark::ConsoleReporter::OO_Color : 0);
    SummaryReporter reporter(table,
                             static_cast<benchmark::ConsoleReporter::OutputOptions>(options));
    benchmark::RunSpecifiedBenchmarks(&reporter);
    benchmark::Shutdown();
    table.printMarkdown(std::cout);
    // A benchmark that could not run makes the whole run fail, so that scripts notice.
    return table.printErrors(std::cerr) == 0 ? 0 : 1;
}
