#include "bench/summary_table.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

namespace stereod::bench {

namespace {

// A missing value is NaN: it stays NaN through arithmetic and prints as "-".
constexpr double kMissing = std::numeric_limits<double>::quiet_NaN();

double counter(const benchmark::UserCounters* counters, const std::string& name)
{
    if (counters == nullptr) {
        return kMissing;
    }
    const auto it = counters->find(name);
    return it == counters->end() ? kMissing : static_cast<double>(it->second.value);
}

std::string fixed(double value, int decimals)
{
    if (std::isnan(value)) {
        return "-";
    }
    char text[32];
    std::snprintf(text, sizeof text, "%.*f", decimals, value);
    return text;
}

} // namespace

void SummaryTable::addRow(SummaryRow row)
{
    rows_.push_back(std::move(row));
}

void SummaryTable::record(const benchmark::BenchmarkReporter::Run& run)
{
    Measured& kept = measured_[run.run_name.function_name];
    if (run.error_occurred) {
        kept.error = run.error_message;
        return;
    }
    const bool is_median = run.run_type == benchmark::BenchmarkReporter::Run::RT_Aggregate &&
                           run.aggregate_name == "median";
    const bool is_plain = run.run_type == benchmark::BenchmarkReporter::Run::RT_Iteration;
    if (is_median || (is_plain && !kept.median)) {
        kept.counters = run.counters;
        kept.median = is_median;
    }
}

const SummaryTable::Measured* SummaryTable::find(const std::string& benchmark_name) const
{
    const auto it = measured_.find(benchmark_name);
    if (it == measured_.end() || !it->second.error.empty()) {
        return nullptr;
    }
    return &it->second;
}

SummaryTable::RowData SummaryTable::rowData(const SummaryRow& row) const
{
    RowData data;
    const auto take = [&data, this](const std::string& name) -> const benchmark::UserCounters* {
        const Measured* measured = find(name);
        if (measured == nullptr) {
            return nullptr;
        }
        data.all_medians = data.all_medians && measured->median;
        return &measured->counters;
    };
    data.pipeline = take(row.pipeline_benchmark);
    data.remap = take(row.opencv_remap_benchmark);
    data.matcher = take(row.opencv_matcher_benchmark);
    data.publish = take(row.publish_benchmark);
    return data;
}

void SummaryTable::printMarkdown(std::ostream& out) const
{
    const bool any = std::any_of(rows_.begin(), rows_.end(), [this](const SummaryRow& row) {
        return find(row.pipeline_benchmark) != nullptr;
    });
    if (!any) {
        return;
    }
    printTimings(out);
    printAllocations(out);
}

void SummaryTable::printTimings(std::ostream& out) const
{
    out << "\n| scene | size | disparities | matcher | rectify | match | depth | nearest | cloud "
           "| publish | total ms | fps | OpenCV remap ms | OpenCV alone ms | OpenCV alone fps |\n"
           "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    bool all_medians = true;
    for (const SummaryRow& row : rows_) {
        const RowData d = rowData(row);
        if (d.pipeline == nullptr) {
            continue;
        }
        all_medians = all_medians && d.all_medians;
        // The worker's cost of a frame: process() wall time plus the hand-over.
        const double publish_ms = counter(d.publish, "publish_ms");
        const double total_ms = counter(d.pipeline, "wall_ms") + publish_ms;
        out << "| " << row.scene << " | " << row.size.width << "x" << row.size.height << " | "
            << row.num_disparities << " | " << row.matcher << " | "
            << fixed(counter(d.pipeline, "rectify_ms"), 2) << " | "
            << fixed(counter(d.pipeline, "match_ms"), 2) << " | "
            << fixed(counter(d.pipeline, "depth_ms"), 2) << " | "
            << fixed(counter(d.pipeline, "nearest_ms"), 2) << " | "
            << fixed(counter(d.pipeline, "cloud_ms"), 2) << " | " << fixed(publish_ms, 2) << " | "
            << fixed(total_ms, 2) << " | " << fixed(1e3 / total_ms, 1) << " | "
            << fixed(counter(d.remap, "rectify_ms"), 2) << " | "
            << fixed(counter(d.matcher, "match_ms"), 2) << " | "
            << fixed(counter(d.matcher, "fps"), 1) << " |\n";
    }
    out << "\nMilliseconds per frame, "
        << (all_medians ? "medians of the repetitions" : "from a single run (no medians)")
        << ". total = process() wall time + publish; fps = 1000 / total. OpenCV remap: "
           "cv::remap of both images with the pipeline's maps; OpenCV alone: the same "
           "matcher's compute() on the same rectified pair.\n";
}

void SummaryTable::printAllocations(std::ostream& out) const
{
    out << "\n| scene | size | disparities | matcher | process() | in OpenCV matcher "
           "| rest of process() | cv::remap x2 alone (not used) |\n"
           "|---|---|---:|---|---:|---:|---:|---:|\n";
    const auto pair = [](double cpp, double mat) { return fixed(cpp, 1) + " / " + fixed(mat, 1); };
    for (const SummaryRow& row : rows_) {
        const RowData d = rowData(row);
        if (d.pipeline == nullptr) {
            continue;
        }
        const double cpp = counter(d.pipeline, "allocs_per_frame");
        const double mat = counter(d.pipeline, "mat_allocs_per_frame");
        const double remap_cpp = counter(d.remap, "allocs_per_frame");
        const double remap_mat = counter(d.remap, "mat_allocs_per_frame");
        const double matcher_cpp = counter(d.matcher, "allocs_per_frame");
        const double matcher_mat = counter(d.matcher, "mat_allocs_per_frame");
        out << "| " << row.scene << " | " << row.size.width << "x" << row.size.height << " | "
            << row.num_disparities << " | " << row.matcher << " | " << pair(cpp, mat) << " | "
            << pair(matcher_cpp, matcher_mat) << " | "
            << pair(cpp - matcher_cpp, mat - matcher_mat) << " | " << pair(remap_cpp, remap_mat)
            << " |\n";
    }
    out << "\nAllocations per steady-state frame, C++ / cv::Mat: operator new calls (every "
           "thread) / new cv::Mat buffers (a counting cv::MatAllocator; each also costs one "
           "operator new for its header). C++ allocations only: malloc() and cv::fastMalloc() "
           "called directly inside a library are not seen. \"In OpenCV matcher\" is the same "
           "compute() made alone; \"rest\" is what the pipeline's own code adds. The last "
           "column is what cv::remap would cost: the rectify stage uses its own remap.\n";
}

int SummaryTable::printErrors(std::ostream& out) const
{
    int errors = 0;
    for (const auto& [name, measured] : measured_) {
        if (!measured.error.empty()) {
            out << name << ": " << measured.error << "\n";
            ++errors;
        }
    }
    return errors;
}

void SummaryReporter::ReportRuns(const std::vector<Run>& runs)
{
    for (const Run& run : runs) {
        table_.record(run);
    }
    benchmark::ConsoleReporter::ReportRuns(runs);
}

} // namespace stereod::bench
