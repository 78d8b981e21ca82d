// stereod_bench: what each stage of the stereo pipeline costs on real images with our
// census-sgm matcher and with OpenCV's matchers, next to each matcher alone on the same
// rectified pair, the capture-to-publish latency, and whether process() allocates in
// steady state.
//
// Benchmarks (names are key:value paths, so --benchmark_filter can pick any subset):
//   pipeline/scene:S/size:WxH/disp:N/matcher:M  StereoProcessor::process() on a raw pair,
//                                               then the publish stage
//   alone/scene:S/size:WxH/disp:N/matcher:M     the matcher alone on the rectified pair:
//                                               sgm::CensusSgm::compute() (census-sgm) or
//                                               cv::StereoSGBM / cv::StereoBM compute()
//   compare/scene:S/size:WxH/disp:N             our pipeline, census-sgm alone, SGBM 3-way
//                                               alone, SGBM 5-path alone and our pipeline
//                                               with the guided search, interleaved frame
//                                               by frame: the ratios
//   opencv/scene:S/size:WxH/stage:rectify       cv::remap of both images alone, same maps
// After the run, markdown tables put them side by side, with the ratios of our pipeline
// and matcher to OpenCV's SGBM alone (bench/README.md explains them).

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <sys/resource.h>
#include <unistd.h>

#include "bench/alloc_counter.hpp"
#include "bench/bench_data.hpp"
#include "bench/latency_log.hpp"
#include "bench/publish_stage.hpp"
#include "bench/summary_table.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/census_sgm_matcher.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/matcher_defaults.hpp"
#include "pipeline/nearest_object.hpp"
#include "pipeline/sgm/census_sgm.hpp"
#include "pipeline/stereo_processor.hpp"

namespace stereod::bench {
namespace {

// OpenCV's thread pool and census-sgm's matcher alone both get two threads, so that the
// matchers alone are compared on equal terms (and on the 2-core machines the numbers in
// bench/README.md come from). The pipeline's census-sgm keeps the service default,
// matcher.threads 0: the cores the process may run on (capped at 8).
constexpr int kMatcherThreads = 2;
// Frames processed and published before timing: the first sizes every buffer, and with
// no reader the publisher's writer alternates between two of its three slots.
constexpr int kWarmupFrames = 4;

// Wall time of the work alone, and the capture stamps: CLOCK_MONOTONIC, in nanoseconds,
// the clock V4L2 stamps frames with.
int64_t monotonicNs() noexcept
{
    timespec now{};
    clock_gettime(CLOCK_MONOTONIC, &now);
    return static_cast<int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec;
}

double peakRssMb()
{
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return static_cast<double>(usage.ru_maxrss) * 1024.0 / 1e6; // ru_maxrss is in KiB
}

// One matcher as the service selects it.
struct MatcherChoice {
    const char* label; // matcherName()'s name; the planar tuning as census-sgm-planar (filters)
    MatcherKind kind;
    SgbmMode sgbm_mode;
    MatcherTuning tuning = MatcherTuning::Natural;
    bool guided = false; // matcher.guided_search
};

// census-sgm with the guided search (matcher.guided_search).
const MatcherChoice kGuidedChoice{kOurMatcherGuided, MatcherKind::CensusSgm, SgbmMode::Sgbm,
                                  MatcherTuning::Natural, true};

// census-sgm's planar tuning runs on the chessboard rig only: the man-made scene it is for;
// the patterns tuning, made for scenes holding both, on every scene.
const std::vector<MatcherChoice> kMatchers = {
    {kOurMatcher, MatcherKind::CensusSgm, SgbmMode::Sgbm},
    {kOurMatcherPlanar, MatcherKind::CensusSgm, SgbmMode::Sgbm, MatcherTuning::Planar},
    {kOurMatcherPatterns, MatcherKind::CensusSgm, SgbmMode::Sgbm, MatcherTuning::Patterns},
    kGuidedChoice,
    {kSgbm5Path, MatcherKind::Sgbm, SgbmMode::Sgbm},
    {kSgbm3Way, MatcherKind::Sgbm, SgbmMode::ThreeWay},
    {"bm", MatcherKind::Bm, SgbmMode::Sgbm},
};

// One scene at one size and disparity range: a group of rows in the summary.
struct Case {
    const Scene* scene = nullptr;
    cv::Size size;
    int num_disparities = 0;
};

// The cases of the issue: 640x480 with 64 and 128 disparities, 1280x720 with 128 and
// 256, all on aloe. 640x480 with 128, the case of the target, also runs on
// tsukuba, venus and the chessboard rig (at its own size); the rig also with 96, the range
// the service's default configuration gives it (min_depth_m 0.5 m), so that the service's
// own figures (bench/service_compare.sh) have a benchmark case to be set beside. Fewer
// scenes elsewhere keep a default run within about three minutes on two shared cores.
std::vector<Case> cases()
{
    const std::vector<Scene>& all = scenes();
    const Scene* aloe = &all.front();
    std::vector<Case> list;
    list.push_back({aloe, {640, 480}, 64});
    for (const Scene& scene : all) {
        list.push_back({&scene, {640, 480}, 128});
    }
    list.push_back({&chessboardScene(), {640, 480}, 96});
    list.push_back({&chessboardScene(), {640, 480}, 128});
    list.push_back({aloe, {1280, 720}, 128});
    list.push_back({aloe, {1280, 720}, 256});
    return list;
}

std::string key(const Scene& scene, cv::Size size)
{
    return "scene:" + scene.name + "/size:" + std::to_string(size.width) + "x" +
           std::to_string(size.height);
}

std::string key(const Case& c)
{
    return key(*c.scene, c.size) + "/disp:" + std::to_string(c.num_disparities);
}

std::string key(const Case& c, const MatcherChoice& m)
{
    return key(c) + "/matcher:" + m.label;
}

// The service's defaults, with the matcher and disparity range of the case.
ProcessorSettings settingsFor(const Case& c, const MatcherChoice& m)
{
    ProcessorSettings settings;
    settings.matcher = matcherDefaults(m.kind, m.sgbm_mode, m.tuning);
    if (c.num_disparities > 0)
        settings.matcher.num_disparities = c.num_disparities;
    settings.matcher.guided_search = m.guided;
    settings.compute_cloud = true;
    return settings;
}

// Everything a scene at one size needs, built once per process: building it costs far
// more than a frame (undistortPoints over every pixel, or the chessboard calibration).
struct SceneInputs {
    StereoCalibration calibration;
    ImagePair raw;       // what the rig captures: the pipeline's input
    RectifyMaps maps;    // the maps the pipeline's rectify stage uses
    ImagePair rectified; // rectified with those maps: the matchers' input
};

const SceneInputs& sceneInputs(const Scene& scene, cv::Size size)
{
    static std::map<std::string, std::unique_ptr<SceneInputs>> cache;
    std::unique_ptr<SceneInputs>& slot = cache[key(scene, size)];
    if (!slot) {
        auto inputs = std::make_unique<SceneInputs>();
        if (scene.raw_rig_views) {
            inputs->calibration = chessboardRigCalibration();
            if (toCv(inputs->calibration.rectified.image_size) != size) {
                throw std::runtime_error(
                    scene.name + ": the rig is calibrated at " +
                    std::to_string(inputs->calibration.rectified.image_size.width) + "x" +
                    std::to_string(inputs->calibration.rectified.image_size.height) +
                    ", not at the case's size");
            }
            inputs->raw = loadScene(scene, size);
        } else {
            inputs->calibration = makePlausibleRigCalibration(size);
            validateCalibration(inputs->calibration, "plausible rig " + key(scene, size));
            inputs->raw = simulateRawPair(inputs->calibration, loadScene(scene, size));
        }
        inputs->maps = makeRectifyMaps(inputs->calibration);
        rectifyPair(inputs->maps, inputs->raw, inputs->rectified);
        slot = std::move(inputs);
    }
    return *slot;
}

// A processor and a publisher that have seen kWarmupFrames frames, so what follows is
// steady state. Google Benchmark calls a benchmark function several times (to size the
// iteration count, and once per repetition); the last rig is kept so that warm-up happens
// once per case.
struct PipelineRig {
    std::string key;
    std::unique_ptr<StereoProcessor> processor;
    std::unique_ptr<PublishStage> publish;
    uint64_t next_frame = 0;
};

PipelineRig& pipelineRig(const Case& c, const MatcherChoice& m)
{
    static std::unique_ptr<PipelineRig> rig;
    if (!rig || rig->key != key(c, m)) {
        rig.reset(); // free the previous case's buffers before allocating new ones
        const SceneInputs& inputs = sceneInputs(*c.scene, c.size);
        auto fresh = std::make_unique<PipelineRig>();
        fresh->key = key(c, m);
        fresh->processor = std::make_unique<StereoProcessor>(inputs.calibration, settingsFor(c, m));
        fresh->publish = std::make_unique<PublishStage>();
        for (int i = 0; i < kWarmupFrames; ++i) {
            fresh->processor->process(inputs.raw.left, inputs.raw.right, monotonicNs(),
                                      fresh->next_frame++, fresh->publish->writeResult());
            if (fresh->publish->writeResult().reading.reason == NoReadingReason::BadFrame) {
                throw std::runtime_error("the pipeline rejected the frame pair (bad_frame)");
            }
            fresh->publish->run();
        }
        rig = std::move(fresh);
    }
    return *rig;
}

// Per-frame sums over the timed iterations, turned into per-frame counters at the end.
class FrameTally {
  public:
    void add(double wall_ms, const AllocationWindow& window)
    {
        ++frames_;
        wall_ms_ += wall_ms;
        cpp_allocs_ += window.cppAllocations();
        mat_allocs_ += window.matAllocations();
    }

    void addPipeline(const StageTimings& timings, double process_ms, double publish_ms)
    {
        stages_.rectify_ms += timings.rectify_ms;
        stages_.match_ms += timings.match_ms;
        stages_.depth_ms += timings.depth_ms;
        stages_.nearest_ms += timings.nearest_ms;
        stages_.cloud_ms += timings.cloud_ms;
        stages_.extended_range_ms += timings.extended_range_ms;
        stages_.near_field_probe_ms += timings.near_field_probe_ms;
        process_ms_ += process_ms;
        publish_ms_ += publish_ms;
    }

    // wall_ms under `time_name`, fps, allocations; the stages when addPipeline() was used.
    void report(benchmark::State& state, const std::string& time_name, bool pipeline) const
    {
        if (frames_ == 0) {
            return;
        }
        const double n = static_cast<double>(frames_);
        if (pipeline) {
            state.counters["rectify_ms"] = stages_.rectify_ms / n;
            state.counters["match_ms"] = stages_.match_ms / n;
            state.counters["depth_ms"] = stages_.depth_ms / n;
            state.counters["nearest_ms"] = stages_.nearest_ms / n;
            state.counters["cloud_ms"] = stages_.cloud_ms / n;
            state.counters["extended_ms"] = stages_.extended_range_ms / n;
            state.counters["probe_ms"] = stages_.near_field_probe_ms / n;
            state.counters["stages_ms"] = stages_.totalMs() / n;
            state.counters["process_ms"] = process_ms_ / n;
            state.counters["publish_ms"] = publish_ms_ / n;
        }
        state.counters[time_name] = wall_ms_ / n;
        state.counters["fps"] = 1e3 * n / wall_ms_;
        state.counters["allocs_per_frame"] = static_cast<double>(cpp_allocs_) / n;
        state.counters["mat_allocs_per_frame"] = static_cast<double>(mat_allocs_) / n;
        state.counters["peak_rss_mb"] = peakRssMb();
    }

  private:
    uint64_t frames_ = 0;
    double wall_ms_ = 0.0;
    double process_ms_ = 0.0;
    double publish_ms_ = 0.0;
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
        const int64_t start_ns = monotonicNs();
        work();
        const double ms = static_cast<double>(monotonicNs() - start_ns) * 1e-6;
        state.SetIterationTime(ms * 1e-3);
        tally.add(ms, window);
    }
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

// One frame as the service's worker handles it: the pair is stamped with CLOCK_MONOTONIC
// just before process() (where a camera's kernel stamp would put it), processed straight
// into the publisher's write slot and published. Latency: from that stamp to the result
// handed to the publisher.
void benchPipeline(benchmark::State& state, const Case& c, const MatcherChoice& m,
                   const std::string& name, LatencyLog& latency)
{
    PipelineRig* rig = nullptr;
    try {
        rig = &pipelineRig(c, m);
    } catch (const std::exception& e) {
        state.SkipWithError(e.what());
        return;
    }
    const ImagePair& raw = sceneInputs(*c.scene, c.size).raw;
    LatencyLog::Samples* samples = latency.find(name);
    const size_t first_sample = samples->ms.size();
    FrameTally tally;
    for (auto _ : state) {
        const AllocationWindow window;
        const int64_t stamp_ns = monotonicNs();
        DepthResult& result = rig->publish->writeResult();
        rig->processor->process(raw.left, raw.right, stamp_ns, rig->next_frame++, result);
        const int64_t processed_ns = monotonicNs();
        const int64_t captured_ns = result.stamp_ns;
        const StageTimings timings = result.timings;
        rig->publish->run();
        const int64_t published_ns = monotonicNs();

        const double process_ms = static_cast<double>(processed_ns - stamp_ns) * 1e-6;
        const double publish_ms = static_cast<double>(published_ns - processed_ns) * 1e-6;
        state.SetIterationTime(static_cast<double>(published_ns - stamp_ns) * 1e-9);
        tally.addPipeline(timings, process_ms, publish_ms);
        tally.add(process_ms + publish_ms, window);
        samples->add(static_cast<double>(published_ns - captured_ns) * 1e-6);
    }
    tally.report(state, "total_ms", true);
    const LatencyLog::Summary this_call = latency.summarize(name, first_sample);
    state.counters["latency_p50_ms"] = this_call.p50_ms;
    state.counters["latency_p99_ms"] = this_call.p99_ms;
    state.counters["num_disparities"] = rig->processor->disparityRange().num_disparities;
    state.SetLabel(rig->processor->matcherName());
}

// cv::StereoBM / cv::StereoSGBM with the parameters the pipeline's settings give them.
cv::Ptr<cv::StereoMatcher> makeOpenCvMatcher(const MatcherSettings& settings,
                                             const DisparityRange& range)
{
    const MatcherSettings s = effectiveMatcherSettings(settings);
    if (s.kind == MatcherKind::Bm) {
        cv::Ptr<cv::StereoBM> bm = cv::StereoBM::create(range.num_disparities, s.block_size);
        bm->setMinDisparity(range.min_disparity);
        bm->setUniquenessRatio(*s.uniqueness_ratio);
        bm->setSpeckleWindowSize(*s.speckle_window_px);
        // StereoBM applies the speckle range to its fixed-point output as is (SGBM scales
        // it by 16 itself), so the same range in pixels is 16 x speckle_range_px here.
        bm->setSpeckleRange(*s.speckle_range_px * cv::StereoMatcher::DISP_SCALE);
        bm->setDisp12MaxDiff(*s.lr_max_diff_px);
        bm->setPreFilterCap(s.pre_filter_cap);
        bm->setTextureThreshold(s.texture_threshold);
        return bm;
    }
    // OpenCV's mode for each SgbmMode, in the enum's order (Sgbm, ThreeWay, Hh, Hh4).
    constexpr int kModes[] = {cv::StereoSGBM::MODE_SGBM, cv::StereoSGBM::MODE_SGBM_3WAY,
                              cv::StereoSGBM::MODE_HH, cv::StereoSGBM::MODE_HH4};
    const int mode = kModes[static_cast<int>(s.sgbm_mode)];
    return cv::StereoSGBM::create(range.min_disparity, range.num_disparities, s.block_size, *s.p1,
                                  *s.p2, *s.lr_max_diff_px, s.pre_filter_cap, *s.uniqueness_ratio,
                                  *s.speckle_window_px, *s.speckle_range_px, mode);
}

// census-sgm's core as the pipeline runs it for this case (the range is fixed by
// num_disparities, so the calibration does not enter: its extended range and near-field
// probe over the default region), but kMatcherThreads threads.
sgm::PyramidSgmSettings censusAloneSettings(const Case& c, const MatcherChoice& m)
{
    const MatcherSettings settings = settingsFor(c, m).matcher;
    DisparityRange range;
    range.min_disparity = settings.min_disparity;
    range.num_disparities = settings.num_disparities.value_or(0);
    sgm::PyramidSgmSettings core = pyramidSgmSettings(settings, range);
    core.full.width = c.size.width;
    core.full.height = c.size.height;
    core.full.threads = kMatcherThreads;
    return core;
}

// The region the pipeline's probe looks at: the nearest object's default one.
sgm::PixelRect probeRegion(const ImagePair& pair)
{
    const cv::Rect r = regionPixels(NearestSettings{}.roi, pair.left.size());
    return {r.x, r.y, r.width, r.height};
}

// census-sgm's core alone on the rectified pair, into caller-owned arrays. Kept between
// the calls of one benchmark (it starts its threads and allocates when built).
struct CensusAlone {
    std::string key;
    std::unique_ptr<sgm::PyramidSgm> core;
    std::vector<float> disparity_px;
    std::vector<uint8_t> confidence;
    std::vector<uint8_t> near_field;

    sgm::PyramidSgmOutput output()
    {
        return {disparity_px.data(), confidence.data(), near_field.data()};
    }
};

// A census-sgm core for the case, run once on the rectified pair. Throws
// std::invalid_argument (settings) or std::runtime_error (a pair it cannot take).
std::unique_ptr<CensusAlone> makeCensusAlone(const Case& c, const MatcherChoice& m,
                                             const ImagePair& pair)
{
    if (!pair.left.isContinuous() || !pair.right.isContinuous()) {
        throw std::runtime_error("the rectified pair is not continuous");
    }
    auto alone = std::make_unique<CensusAlone>();
    alone->key = key(c, m);
    alone->core = std::make_unique<sgm::PyramidSgm>(censusAloneSettings(c, m));
    const size_t pixels = pair.left.total();
    alone->disparity_px.resize(pixels);
    alone->confidence.resize(pixels);
    alone->near_field.resize(pixels);
    alone->core->compute(pair.left.data, pair.left.step, pair.right.data, pair.right.step,
                         probeRegion(pair), alone->output());
    return alone;
}

void benchCensusAlone(benchmark::State& state, const Case& c, const MatcherChoice& m)
{
    const SceneInputs* inputs = sceneInputsOrSkip(state, *c.scene, c.size);
    if (inputs == nullptr) {
        return;
    }
    static std::unique_ptr<CensusAlone> kept;
    const ImagePair& pair = inputs->rectified;
    if (!kept || kept->key != key(c, m)) {
        kept.reset();
        try {
            kept = makeCensusAlone(c, m, pair);
        } catch (const std::exception& e) {
            state.SkipWithError(e.what());
            return;
        }
    }
    CensusAlone& alone = *kept;
    const sgm::PyramidSgmOutput out = alone.output();
    const sgm::PixelRect region = probeRegion(pair);
    FrameTally tally;
    double extended_ms = 0.0, probe_ms = 0.0;
    timeFrames(state, tally, [&] {
        alone.core->compute(pair.left.data, pair.left.step, pair.right.data, pair.right.step,
                            region, out);
        extended_ms += alone.core->timings().extended_ms;
        probe_ms += alone.core->timings().probe_ms;
    });
    tally.report(state, "match_ms", false);
    const double frames = std::max(1.0, static_cast<double>(state.iterations()));
    state.counters["extended_ms"] = extended_ms / frames;
    state.counters["probe_ms"] = probe_ms / frames;
    state.counters["searched_share"] = alone.core->searchedShare();
    state.counters["num_disparities"] = alone.core->settings().full.num_disparities;
    state.counters["threads"] = alone.core->settings().full.threads;
    state.counters["memory_mb"] =
        static_cast<double>(sgm::pyramidSgmMemoryBytes(alone.core->settings())) / 1e6;
    state.SetLabel(std::string("census-sgm ") + alone.core->target());
}

void benchOpenCvAlone(benchmark::State& state, const Case& c, const MatcherChoice& m)
{
    const SceneInputs* inputs = sceneInputsOrSkip(state, *c.scene, c.size);
    if (inputs == nullptr) {
        return;
    }
    const MatcherSettings settings = settingsFor(c, m).matcher;
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
    state.SetLabel(m.label);
}

// The ratios of the summary, measured on a shared, noisy machine: each iteration runs,
// one after the other on the same pair, our whole pipeline (process() + publish with
// census-sgm), census-sgm's core alone, SGBM 3-way alone, SGBM 5-path alone and our whole
// pipeline with the guided search, so that load from outside hits all five alike. The
// ratios are of the sums over a repetition.
constexpr int kCompared = 5; // what CompareRig::run() times

struct CompareRig {
    std::string key;
    std::unique_ptr<StereoProcessor> processor;
    std::unique_ptr<StereoProcessor> guided;
    std::unique_ptr<PublishStage> publish;
    uint64_t next_frame = 0;
    std::unique_ptr<CensusAlone> census;
    cv::Ptr<cv::StereoMatcher> three_way;
    cv::Ptr<cv::StereoMatcher> five_path;
    cv::Mat disparity_fixed16; // CV_16SC1, 16 x disparity in pixels; SGBM's output

    // One frame of each; milliseconds of each in `ms` (pipeline, census, 3-way, 5-path,
    // guided pipeline).
    void run(const SceneInputs& inputs, double ms[kCompared])
    {
        const int64_t t0 = monotonicNs();
        processor->process(inputs.raw.left, inputs.raw.right, t0, next_frame++,
                           publish->writeResult());
        publish->run();
        const int64_t t1 = monotonicNs();
        const ImagePair& pair = inputs.rectified;
        census->core->compute(pair.left.data, pair.left.step, pair.right.data, pair.right.step,
                              probeRegion(pair), census->output());
        const int64_t t2 = monotonicNs();
        three_way->compute(pair.left, pair.right, disparity_fixed16);
        const int64_t t3 = monotonicNs();
        five_path->compute(pair.left, pair.right, disparity_fixed16);
        const int64_t t4 = monotonicNs();
        guided->process(inputs.raw.left, inputs.raw.right, t4, next_frame++,
                        publish->writeResult());
        publish->run();
        const int64_t t5 = monotonicNs();
        ms[0] = static_cast<double>(t1 - t0) * 1e-6;
        ms[1] = static_cast<double>(t2 - t1) * 1e-6;
        ms[2] = static_cast<double>(t3 - t2) * 1e-6;
        ms[3] = static_cast<double>(t4 - t3) * 1e-6;
        ms[4] = static_cast<double>(t5 - t4) * 1e-6;
    }
};

CompareRig& compareRig(const Case& c)
{
    static std::unique_ptr<CompareRig> rig;
    if (!rig || rig->key != key(c)) {
        rig.reset();
        const SceneInputs& inputs = sceneInputs(*c.scene, c.size);
        auto fresh = std::make_unique<CompareRig>();
        fresh->key = key(c);
        const MatcherChoice& ours = kMatchers[0];
        fresh->processor =
            std::make_unique<StereoProcessor>(inputs.calibration, settingsFor(c, ours));
        fresh->guided =
            std::make_unique<StereoProcessor>(inputs.calibration, settingsFor(c, kGuidedChoice));
        fresh->publish = std::make_unique<PublishStage>();
        fresh->census = makeCensusAlone(c, ours, inputs.rectified);
        for (const MatcherChoice& m : kMatchers) {
            if (m.label != std::string(kSgbm3Way) && m.label != std::string(kSgbm5Path)) {
                continue;
            }
            const MatcherSettings settings = settingsFor(c, m).matcher;
            const DisparityRange range =
                chooseDisparityRange(settings, inputs.calibration.rectified);
            (m.sgbm_mode == SgbmMode::ThreeWay ? fresh->three_way : fresh->five_path) =
                makeOpenCvMatcher(settings, range);
        }
        double ms[kCompared];
        for (int i = 0; i < kWarmupFrames; ++i) {
            fresh->run(inputs, ms);
        }
        rig = std::move(fresh);
    }
    return *rig;
}

void benchCompare(benchmark::State& state, const Case& c)
{
    CompareRig* rig = nullptr;
    try {
        rig = &compareRig(c);
    } catch (const std::exception& e) {
        state.SkipWithError(e.what());
        return;
    }
    const SceneInputs& inputs = sceneInputs(*c.scene, c.size);
    double sums[kCompared] = {};
    uint64_t frames = 0;
    for (auto _ : state) {
        double ms[kCompared];
        rig->run(inputs, ms);
        double total = 0.0;
        for (int i = 0; i < kCompared; ++i) {
            sums[i] += ms[i];
            total += ms[i];
        }
        state.SetIterationTime(total * 1e-3);
        ++frames;
    }
    if (frames == 0) {
        return;
    }
    const double n = static_cast<double>(frames);
    state.counters["pipeline_ms"] = sums[0] / n;
    state.counters["census_alone_ms"] = sums[1] / n;
    state.counters["sgbm3way_alone_ms"] = sums[2] / n;
    state.counters["sgbm5path_alone_ms"] = sums[3] / n;
    state.counters["pipeline_per_3way"] = sums[0] / sums[2];
    state.counters["census_per_3way"] = sums[1] / sums[2];
    state.counters["census_per_5path"] = sums[1] / sums[3];
    state.counters["guided_pipeline_ms"] = sums[4] / n;
    state.counters["guided_pipeline_per_3way"] = sums[4] / sums[2];
    state.counters["peak_rss_mb"] = peakRssMb();
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

void registerBenchmarks(SummaryTable& table, LatencyLog& latency)
{
    std::vector<std::string> remaps_registered;
    for (const Case& c : cases()) {
        SummaryCase summary;
        summary.scene = c.scene->name;
        summary.size = c.size;
        summary.num_disparities = c.num_disparities;
        summary.remap_benchmark = "opencv/" + key(*c.scene, c.size) + "/stage:rectify";
        if (std::find(remaps_registered.begin(), remaps_registered.end(),
                      summary.remap_benchmark) == remaps_registered.end()) {
            remaps_registered.push_back(summary.remap_benchmark);
            benchmark::RegisterBenchmark(summary.remap_benchmark.c_str(), benchOpenCvRemap,
                                         *c.scene, c.size)
                ->UseManualTime()
                ->Unit(benchmark::kMillisecond);
        }
        for (const MatcherChoice& m : kMatchers) {
            if (m.tuning == MatcherTuning::Planar && c.scene != &chessboardScene()) {
                continue;
            }
            const std::string pipeline = "pipeline/" + key(c, m);
            const std::string alone = "alone/" + key(c, m);
            latency.reserve(pipeline);
            benchmark::RegisterBenchmark(pipeline.c_str(),
                                         [c, m, pipeline, &latency](benchmark::State& state) {
                                             benchPipeline(state, c, m, pipeline, latency);
                                         })
                ->UseManualTime()
                ->Unit(benchmark::kMillisecond);
            if (m.kind == MatcherKind::CensusSgm) {
                benchmark::RegisterBenchmark(alone.c_str(), benchCensusAlone, c, m)
                    ->UseManualTime()
                    ->Unit(benchmark::kMillisecond);
            } else {
                benchmark::RegisterBenchmark(alone.c_str(), benchOpenCvAlone, c, m)
                    ->UseManualTime()
                    ->Unit(benchmark::kMillisecond);
            }
            summary.rows.push_back({m.label, pipeline, alone});
        }
        summary.compare_benchmark = "compare/" + key(c);
        benchmark::RegisterBenchmark(summary.compare_benchmark.c_str(), benchCompare, c)
            ->UseManualTime()
            ->Unit(benchmark::kMillisecond);
        summary.census_memory_bytes =
            static_cast<double>(sgm::pyramidSgmMemoryBytes(censusAloneSettings(c, kMatchers[0])));
        table.addCase(std::move(summary));
    }
}

std::string loadAverage()
{
    double load[3] = {0.0, 0.0, 0.0};
    if (getloadavg(load, 3) != 3) {
        return "unknown";
    }
    char text[64];
    std::snprintf(text, sizeof text, "%.2f, %.2f, %.2f", load[0], load[1], load[2]);
    return text;
}

} // namespace
} // namespace stereod::bench

int main(int argc, char** argv)
{
    using namespace stereod::bench;
    installCountingMatAllocator();
    cv::setNumThreads(kMatcherThreads);
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) {
        return 2;
    }
    benchmark::AddCustomContext(
        "allocs_per_frame",
        "C++ allocations only (replaced global operator new), counted over the timed "
        "process() + publish calls on every thread; OpenCV's cv::fastMalloc does not go "
        "through operator new, so cv::Mat buffers are counted separately in "
        "mat_allocs_per_frame (a counting cv::MatAllocator); malloc() inside libraries is "
        "not seen");
    benchmark::AddCustomContext(
        "calibration",
        "aloe, tsukuba, venus: a plausible rig built in code (f = 0.9 x width, small k1/k2, "
        "0.5 degree rotation, 6 cm baseline), not a measured one; chessboard: the real rig "
        "of OpenCV's chessboard pairs, calibrated by pipeline/chessboard_calibration from "
        "its 13 pairs (9x6, 25 mm squares), raw pair 01 as input");
    benchmark::AddCustomContext("publish", PublishStage::description());
    benchmark::AddCustomContext("latency",
                                "CLOCK_MONOTONIC stamp just before process() to the result "
                                "handed to the publisher (after publish())");
    benchmark::AddCustomContext("opencv_threads",
                                std::to_string(cv::getNumThreads()) + " (cv::setNumThreads(" +
                                    std::to_string(kMatcherThreads) +
                                    "), for the pipeline and the matchers alone)");
    benchmark::AddCustomContext(
        "census_sgm_threads", "pipeline: matcher.threads 0 = the cores available, " +
                                  std::to_string(stereod::censusSgmSettings({}, {0, 64}).threads) +
                                  " here; alone: " + std::to_string(kMatcherThreads));
    benchmark::AddCustomContext("cores_available", std::to_string(stereod::availableCores()));

    SummaryTable table;
    LatencyLog latency;
    registerBenchmarks(table, latency);
    const int options = benchmark::ConsoleReporter::OO_Tabular |
                        (isatty(STDOUT_FILENO) ? benchmark::ConsoleReporter::OO_Color : 0);
    SummaryReporter reporter(table,
                             static_cast<benchmark::ConsoleReporter::OutputOptions>(options));
    benchmark::RunSpecifiedBenchmarks(&reporter);
    benchmark::Shutdown();
    table.printMarkdown(std::cout, latency);
    std::cout << "\nContext: " << stereod::availableCores() << " cores available; OpenCV "
              << cv::getNumThreads() << " threads; census-sgm alone " << kMatcherThreads
              << " threads, in the pipeline " << stereod::censusSgmSettings({}, {0, 64}).threads
              << "; load average at the end " << loadAverage() << "; peak RSS of the process "
              << fixed(peakRssMb(), 1) << " MB (getrusage, at the end).\n";
    table.printTarget(std::cout);
    // A benchmark that could not run makes the whole run fail, so that scripts notice.
    return table.printErrors(std::cerr) == 0 ? 0 : 1;
}
