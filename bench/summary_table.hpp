#pragma once
// The markdown tables printed at the end of a benchmark run. A case is one scene at one
// size and disparity range; each case has a row per matcher:
//  1. time: the pipeline's stages, the publish stage, total, fps, capture-to-publish
//     latency, and the same matcher alone on the same rectified pair;
//  2. ratios: our whole pipeline and census-sgm alone against OpenCV's SGBM alone (3-way
//     and 5-path), measured interleaved frame by frame in one benchmark per case (so that
//     load from other processes hits both sides alike), and census-sgm's working memory;
//  3. allocations: process() + publish against the matcher alone.
// Then printTarget() states whether the target is met. Values are the medians of
// the repetitions when the run has aggregates (--benchmark_repetitions=N), else the
// single run's; latency percentiles are over every timed frame of a case.
//
// Thread-bound: Google Benchmark reports from the thread that runs the benchmarks.

#include <map>
#include <ostream>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/core/types.hpp>

#include "bench/latency_log.hpp"

namespace stereod::bench {

// The matcher labels the ratios are about (StereoProcessor::matcherName()).
inline constexpr const char* kOurMatcher = "census-sgm";
inline constexpr const char* kOurMatcherPlanar = "census-sgm-planar";
inline constexpr const char* kOurMatcherPatterns = "census-sgm-patterns"; // tuning: patterns
inline constexpr const char* kOurMatcherGuided = "census-sgm-guided";     // matcher.guided_search
inline constexpr const char* kSgbm3Way = "sgbm-3way";
inline constexpr const char* kSgbm5Path = "sgbm";

// `value` with `decimals` decimals; "-" for NaN (a missing value).
std::string fixed(double value, int decimals);

// One matcher of a case and the benchmarks that measure it (by registered name).
struct MatcherRow {
    std::string matcher;            // "census-sgm", "sgbm", "sgbm-3way", "bm"
    std::string pipeline_benchmark; // process() + publish with this matcher
    std::string alone_benchmark;    // the matcher alone on the rectified pair
};

struct SummaryCase {
    std::string scene;
    cv::Size size;
    int num_disparities = 0;
    std::string remap_benchmark;   // cv::remap of both images with the pipeline's maps
    std::string compare_benchmark; // ours and SGBM alone interleaved: the ratios
    std::vector<MatcherRow> rows;
    double census_memory_bytes = 0.0; // censusSgmMemoryBytes() for the case, 2 threads
};

class SummaryTable {
  public:
    void addCase(SummaryCase summary_case);

    // Keeps the counters of `run`: a "median" aggregate replaces whatever was kept for its
    // benchmark; a plain iteration run is kept only while no median has been seen.
    void record(const benchmark::BenchmarkReporter::Run& run);

    // The three tables, for the cases whose pipeline benchmarks ran; "-" where a value is
    // missing (filtered out, failed). Prints nothing when no case ran.
    void printMarkdown(std::ostream& out, const LatencyLog& latency) const;

    // The target, our whole pipeline <= 0.5 x OpenCV SGBM 3-way alone at
    // 640x480 with 128 disparities: one line per scene measured there, met or not met.
    void printTarget(std::ostream& out) const;

    // Benchmarks skipped with an error, one "name: reason" line each, to `out`. Returns
    // how many there were.
    int printErrors(std::ostream& out) const;

  private:
    struct Measured {
        benchmark::UserCounters counters;
        bool median = false;
        std::string error; // non-empty when the benchmark was skipped with an error
    };
    // The counters of a benchmark, nullptr where it did not run; clears `all_medians`
    // when they are not a median.
    const benchmark::UserCounters* counters(const std::string& benchmark_name,
                                            bool& all_medians) const;
    bool ran(const SummaryCase& c) const;
    // Our pipeline / SGBM 3-way alone for a case, from its interleaved benchmark; NaN when
    // it did not run.
    double pipelineTo3Way(const SummaryCase& c) const;
    void printTimings(std::ostream& out, const LatencyLog& latency) const;
    void printRatios(std::ostream& out) const;
    void printAllocations(std::ostream& out) const;

    std::vector<SummaryCase> cases_;
    std::map<std::string, Measured> measured_; // by registered benchmark name
};

// Google Benchmark's console output, plus feeding every run into a SummaryTable.
class SummaryReporter : public benchmark::ConsoleReporter {
  public:
    SummaryReporter(SummaryTable& table, OutputOptions options)
        : benchmark::ConsoleReporter(options), table_(table)
    {
    }

    void ReportRuns(const std::vector<Run>& runs) override;

  private:
    SummaryTable& table_;
};

} // namespace stereod::bench
