#include "bench/summary_table.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <utility>

namespace stereod::bench {

namespace {

// A missing value is NaN: it stays NaN through arithmetic and prints as "-".
constexpr double kMissing = std::numeric_limits<double>::quiet_NaN();
// The target: our whole pipeline at most this fraction of SGBM 3-way alone.
constexpr double kTargetRatio = 0.5;
const cv::Size kTargetSize{640, 480};
constexpr int kTargetDisparities = 128;

double counter(const benchmark::UserCounters* counters, const std::string& name)
{
    if (counters == nullptr) {
        return kMissing;
    }
    const auto it = counters->find(name);
    return it == counters->end() ? kMissing : static_cast<double>(it->second.value);
}

std::string sizeText(cv::Size size)
{
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

std::string medianNote(bool all_medians)
{
    return all_medians ? "medians of the repetitions" : "from a single run (no medians)";
}

} // namespace

std::string fixed(double value, int decimals)
{
    if (std::isnan(value)) {
        return "-";
    }
    char text[32];
    std::snprintf(text, sizeof text, "%.*f", decimals, value);
    return text;
}

void SummaryTable::addCase(SummaryCase summary_case)
{
    cases_.push_back(std::move(summary_case));
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

const benchmark::UserCounters* SummaryTable::counters(const std::string& benchmark_name,
                                                      bool& all_medians) const
{
    const auto it = measured_.find(benchmark_name);
    if (it == measured_.end() || !it->second.error.empty()) {
        return nullptr;
    }
    all_medians = all_medians && it->second.median;
    return &it->second.counters;
}

bool SummaryTable::ran(const SummaryCase& c) const
{
    bool ignored = true;
    if (counters(c.compare_benchmark, ignored) != nullptr) {
        return true;
    }
    return std::any_of(c.rows.begin(), c.rows.end(), [&](const MatcherRow& r) {
        return counters(r.pipeline_benchmark, ignored) != nullptr ||
               counters(r.alone_benchmark, ignored) != nullptr;
    });
}

double SummaryTable::pipelineTo3Way(const SummaryCase& c) const
{
    bool ignored = true;
    return counter(counters(c.compare_benchmark, ignored), "pipeline_per_3way");
}

void SummaryTable::printMarkdown(std::ostream& out, const LatencyLog& latency) const
{
    if (std::none_of(cases_.begin(), cases_.end(),
                     [this](const SummaryCase& c) { return ran(c); })) {
        return;
    }
    printTimings(out, latency);
    printRatios(out);
    printAllocations(out);
}

void SummaryTable::printTimings(std::ostream& out, const LatencyLog& latency) const
{
    out << "\n| scene | size | disp | matcher | rectify | match | depth | nearest | cloud "
           "| publish | total ms | fps | latency p50 ms | p99 ms | frames | matcher alone ms "
           "| alone fps | OpenCV remap ms |\n"
           "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
           "---:|\n";
    bool all_medians = true;
    for (const SummaryCase& c : cases_) {
        if (!ran(c)) {
            continue;
        }
        const double remap_ms = counter(counters(c.remap_benchmark, all_medians), "rectify_ms");
        for (const MatcherRow& r : c.rows) {
            const benchmark::UserCounters* p = counters(r.pipeline_benchmark, all_medians);
            const benchmark::UserCounters* alone = counters(r.alone_benchmark, all_medians);
            const double total_ms = counter(p, "total_ms");
            const LatencyLog::Summary lat = latency.summarize(r.pipeline_benchmark);
            out << "| " << c.scene << " | " << sizeText(c.size) << " | " << c.num_disparities
                << " | " << r.matcher << " | " << fixed(counter(p, "rectify_ms"), 2) << " | "
                << fixed(counter(p, "match_ms"), 2) << " | " << fixed(counter(p, "depth_ms"), 2)
                << " | " << fixed(counter(p, "nearest_ms"), 2) << " | "
                << fixed(counter(p, "cloud_ms"), 2) << " | " << fixed(counter(p, "publish_ms"), 2)
                << " | " << fixed(total_ms, 2) << " | " << fixed(1e3 / total_ms, 1) << " | "
                << fixed(lat.p50_ms, 2) << " | " << fixed(lat.p99_ms, 2) << " | " << lat.frames
                << " | " << fixed(counter(alone, "match_ms"), 2) << " | "
                << fixed(counter(alone, "fps"), 1) << " | " << fixed(remap_ms, 2) << " |\n";
        }
    }
    out << "\nMilliseconds per frame, " << medianNote(all_medians)
        << ". total = process() + publish, one after the other as the worker runs them; fps = "
           "1000 / total. Latency: from the pair's CLOCK_MONOTONIC stamp, taken just before "
           "process(), to the result handed to the publisher; percentiles over every timed "
           "frame of the case (frames). Matcher alone: census-sgm's core "
           "(sgm::CensusSgm::compute, 2 threads) or OpenCV's compute() (2 threads) on the same "
           "rectified pair. OpenCV remap: cv::remap of both images with the pipeline's maps.\n";
}

void SummaryTable::printRatios(std::ostream& out) const
{
    out << "\n| scene | size | disp | our pipeline ms | census-sgm alone ms | SGBM 3-way alone ms "
           "| SGBM 5-path alone ms | our pipeline / 3-way alone | census-sgm alone / 3-way alone "
           "| census-sgm alone / 5-path alone | census-sgm memory MB | guided pipeline ms "
           "| guided pipeline / 3-way alone |\n"
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    bool all_medians = true;
    for (const SummaryCase& c : cases_) {
        const benchmark::UserCounters* m = counters(c.compare_benchmark, all_medians);
        if (m == nullptr) {
            continue;
        }
        out << "| " << c.scene << " | " << sizeText(c.size) << " | " << c.num_disparities << " | "
            << fixed(counter(m, "pipeline_ms"), 2) << " | "
            << fixed(counter(m, "census_alone_ms"), 2) << " | "
            << fixed(counter(m, "sgbm3way_alone_ms"), 2) << " | "
            << fixed(counter(m, "sgbm5path_alone_ms"), 2) << " | "
            << fixed(counter(m, "pipeline_per_3way"), 2) << " | "
            << fixed(counter(m, "census_per_3way"), 2) << " | "
            << fixed(counter(m, "census_per_5path"), 2) << " | "
            << fixed(c.census_memory_bytes / 1e6, 1) << " | "
            << fixed(counter(m, "guided_pipeline_ms"), 2) << " | "
            << fixed(counter(m, "guided_pipeline_per_3way"), 2) << " |\n";
    }
    out << "\nInterleaved: every iteration of compare/... runs our whole pipeline (census-sgm, "
           "process() + publish), census-sgm's core alone (2 threads), cv::StereoSGBM "
           "MODE_SGBM_3WAY alone and MODE_SGBM (5 paths) alone, and our whole pipeline with the "
           "guided search (matcher.guided_search), one after the other on the same pair, so "
           "that load from other processes hits all five alike; each ratio is of the sums over "
           "a repetition, "
        << medianNote(all_medians)
        << ". Below 1 where ours is faster. SGBM: the service's default parameters, OpenCV on "
           "2 threads. census-sgm memory: censusSgmMemoryBytes() with the case's settings and "
           "2 threads, MB = 10^6 bytes.\n";
}

void SummaryTable::printAllocations(std::ostream& out) const
{
    out << "\n| scene | size | disp | matcher | process() + publish | matcher alone "
           "| rest of the chain | cv::remap x2 alone (not used) |\n"
           "|---|---|---:|---|---:|---:|---:|---:|\n";
    const auto pair = [](double cpp, double mat) { return fixed(cpp, 1) + " / " + fixed(mat, 1); };
    bool ours_measured = false;
    bool ours_zero = true;
    for (const SummaryCase& c : cases_) {
        if (!ran(c)) {
            continue;
        }
        bool ignored = true;
        const benchmark::UserCounters* remap = counters(c.remap_benchmark, ignored);
        for (const MatcherRow& r : c.rows) {
            const benchmark::UserCounters* p = counters(r.pipeline_benchmark, ignored);
            const benchmark::UserCounters* alone = counters(r.alone_benchmark, ignored);
            const double cpp = counter(p, "allocs_per_frame");
            const double mat = counter(p, "mat_allocs_per_frame");
            const double alone_cpp = counter(alone, "allocs_per_frame");
            const double alone_mat = counter(alone, "mat_allocs_per_frame");
            if (r.matcher == kOurMatcher || r.matcher == kOurMatcherPlanar ||
                r.matcher == kOurMatcherPatterns || r.matcher == kOurMatcherGuided) {
                for (const double v : {cpp, mat, alone_cpp, alone_mat}) {
                    if (!std::isnan(v)) {
                        ours_measured = true;
                        ours_zero = ours_zero && v == 0.0;
                    }
                }
            }
            out << "| " << c.scene << " | " << sizeText(c.size) << " | " << c.num_disparities
                << " | " << r.matcher << " | " << pair(cpp, mat) << " | "
                << pair(alone_cpp, alone_mat) << " | " << pair(cpp - alone_cpp, mat - alone_mat)
                << " | "
                << pair(counter(remap, "allocs_per_frame"), counter(remap, "mat_allocs_per_frame"))
                << " |\n";
        }
    }
    out << "\nAllocations per steady-state frame, C++ / cv::Mat: operator new calls (every "
           "thread) / new cv::Mat buffers (a counting cv::MatAllocator; each also costs one "
           "operator new for its header). C++ allocations only: malloc() and cv::fastMalloc() "
           "called directly inside a library are not seen. \"Matcher alone\" is the same "
           "matcher's compute() made alone; \"rest\" is what the rest of the chain adds. The "
           "last column is what cv::remap would cost: the rectify stage uses its own remap.\n";
    if (ours_measured) {
        out << "\ncensus-sgm steady state (process() + publish, and its core alone): "
            << (ours_zero ? "0 C++ and 0 cv::Mat allocations per frame in every case"
                          : "NOT allocation-free, see the census-sgm rows above")
            << ".\n";
    }
}

void SummaryTable::printTarget(std::ostream& out) const
{
    bool any = false;
    for (const SummaryCase& c : cases_) {
        bool ignored = true;
        if (c.size != kTargetSize || c.num_disparities != kTargetDisparities ||
            counters(c.compare_benchmark, ignored) == nullptr) {
            continue;
        }
        const double ratio = pipelineTo3Way(c);
        if (!any) {
            out << "\nTarget: our whole pipeline <= " << fixed(kTargetRatio, 1)
                << "x OpenCV SGBM 3-way alone at " << sizeText(kTargetSize) << "/"
                << kTargetDisparities << "\n";
            any = true;
        }
        out << "- " << c.scene << ": " << fixed(ratio, 2) << "x: "
            << (std::isnan(ratio)       ? "not measured"
                : ratio <= kTargetRatio ? "met"
                                        : "not met")
            << "\n";
    }
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
