#pragma once
// The markdown tables printed at the end of a benchmark run, per scene, size, disparity
// range and matcher: the pipeline's stages, the publish stage and OpenCV alone (remap,
// matcher) side by side; then the steady-state allocations of process() next to those of
// the OpenCV calls it makes. Values are the medians of the repetitions when the run has aggregates
// (--benchmark_repetitions=N), else the single run's.
//
// Thread-bound: Google Benchmark reports from the thread that runs the benchmarks.

#include <map>
#include <ostream>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/core/types.hpp>

namespace stereod::bench {

// One line of the table and the benchmarks that fill it (by registered name).
struct SummaryRow {
    std::string scene;
    cv::Size size;
    int num_disparities = 0;
    std::string matcher;
    std::string pipeline_benchmark;
    std::string opencv_remap_benchmark;
    std::string opencv_matcher_benchmark;
    std::string publish_benchmark;
};

class SummaryTable {
  public:
    void addRow(SummaryRow row);

    // Keeps the counters of `run`: a "median" aggregate replaces whatever was kept for its
    // benchmark; a plain iteration run is kept only while no median has been seen.
    void record(const benchmark::BenchmarkReporter::Run& run);

    // Rows whose pipeline benchmark ran; "-" where a value is missing (filtered out,
    // failed). Prints nothing when no row ran.
    void printMarkdown(std::ostream& out) const;

    // Benchmarks skipped with an error, one "name: reason" line each, to `out`. Returns
    // how many there were.
    int printErrors(std::ostream& out) const;

  private:
    struct Measured {
        benchmark::UserCounters counters;
        bool median = false;
        std::string error; // non-empty when the benchmark was skipped with an error
    };
    // The counters of one row's benchmarks; nullptr where one did not run.
    struct RowData {
        const benchmark::UserCounters* pipeline = nullptr;
        const benchmark::UserCounters* remap = nullptr;
        const benchmark::UserCounters* matcher = nullptr;
        const benchmark::UserCounters* publish = nullptr;
        bool all_medians = true;
    };
    const Measured* find(const std::string& benchmark_name) const;
    RowData rowData(const SummaryRow& row) const;
    void printTimings(std::ostream& out) const;
    void printAllocations(std::ostream& out) const;

    std::vector<SummaryRow> rows_;
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
