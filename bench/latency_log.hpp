#pragma once
// Capture-to-publish latency samples of the pipeline benchmarks, kept per benchmark across
// all the calls Google Benchmark makes of it (the sizing runs and every repetition), so
// that p50 and p99 cover every timed frame of a case, not the few of one repetition.
//
// Storage is reserved when a benchmark is registered: recording a sample never allocates
// (a full log stops recording and counts what it dropped).
//
// Thread-bound: the thread that runs the benchmarks records and reads.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace stereod::bench {

// The p-th percentile (0..100) of `values` by nearest rank; NaN when empty. Reorders
// `values`.
inline double percentile(std::vector<double>& values, double p)
{
    if (values.empty()) {
        return std::numeric_limits<double>::quiet_NaN();
    }
    const double rank = std::ceil(p / 100.0 * static_cast<double>(values.size()));
    const size_t index =
        static_cast<size_t>(std::clamp(rank, 1.0, static_cast<double>(values.size()))) - 1;
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(index),
                     values.end());
    return values[index];
}

class LatencyLog {
  public:
    // Samples one benchmark can keep: far more frames than a default run times.
    static constexpr size_t kCapacity = 8192;

    struct Samples {
        std::vector<double> ms; // capacity kCapacity, reserved at registration
        uint64_t dropped = 0;   // samples that did not fit

        void add(double latency_ms) noexcept
        {
            if (ms.size() < ms.capacity()) {
                ms.push_back(latency_ms);
            } else {
                ++dropped;
            }
        }
    };

    struct Summary {
        double p50_ms = std::numeric_limits<double>::quiet_NaN();
        double p99_ms = std::numeric_limits<double>::quiet_NaN();
        size_t frames = 0;
    };

    // Reserves the storage of `benchmark_name` (a registered name). Call before the run.
    void reserve(const std::string& benchmark_name)
    {
        samples_[benchmark_name].ms.reserve(kCapacity);
        scratch_.reserve(kCapacity);
    }

    // The log of a benchmark reserved with reserve(); nullptr for any other name.
    Samples* find(const std::string& benchmark_name)
    {
        const auto it = samples_.find(benchmark_name);
        return it == samples_.end() ? nullptr : &it->second;
    }

    // p50 and p99 of samples [first, end) of `benchmark_name`. Allocates nothing (a
    // scratch copy reserved with the logs).
    Summary summarize(const std::string& benchmark_name, size_t first = 0) const
    {
        Summary summary;
        const auto it = samples_.find(benchmark_name);
        if (it == samples_.end() || first >= it->second.ms.size()) {
            return summary;
        }
        scratch_.assign(it->second.ms.begin() + static_cast<std::ptrdiff_t>(first),
                        it->second.ms.end());
        summary.frames = scratch_.size();
        summary.p50_ms = percentile(scratch_, 50.0);
        summary.p99_ms = percentile(scratch_, 99.0);
        return summary;
    }

  private:
    std::map<std::string, Samples> samples_;
    mutable std::vector<double> scratch_;
};

} // namespace stereod::bench
