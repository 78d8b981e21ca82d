#pragma once
// The last N samples, not since start: the one meaning of "recent" behind the rolling
// figures of `status`. Two windows, one per thread contract:
//
// - RollingWindow: the last N samples of a signed duration (ns) and their summary, behind
//   the skew figures of every source. One writer thread; summary() from any thread. Each
//   slot is an atomic, so a reader sees every sample whole; a summary taken while the
//   writer adds may mix samples of adjacent moments, which a statistic of the recent past
//   tolerates. No allocation, no lock.
// - RecentValues: the last N values of any type, oldest first, for one thread only (plain
//   slots, no atomics); with mean() over it. Behind the worker's stage means and latency
//   percentiles, which it copies out with its stats.
//
// The rate of recent events (every `fps`) is base/rate_estimate.hpp's.

#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

#include "base/clock.hpp"
#include "base/percentile.hpp"

namespace stereod {

struct RollingSummary {
    std::size_t count = 0; // samples in the window (at most N)
    double mean_ns = 0.0;  // signed mean
    double mean_abs_ns = 0.0;
    int64_t max_abs_ns = 0;
    int64_t p99_abs_ns = 0; // nearest rank: the smallest |x| at or above 99 % of them
};

template <std::size_t N> class RollingWindow {
    static_assert(N > 0);

  public:
    static constexpr std::size_t kCapacity = N;

    void add(int64_t sample_ns) noexcept
    {
        const uint64_t added = added_.load(std::memory_order_relaxed);
        samples_[added % N].store(sample_ns, std::memory_order_relaxed);
        added_.store(added + 1, std::memory_order_release);
    }

    RollingSummary summary() const noexcept
    {
        RollingSummary out;
        out.count =
            static_cast<std::size_t>(std::min<uint64_t>(added_.load(std::memory_order_acquire), N));
        if (out.count == 0)
            return out;
        std::array<int64_t, N> magnitude;
        double sum = 0.0;
        double abs_sum = 0.0;
        for (std::size_t i = 0; i < out.count; ++i) {
            const int64_t sample = samples_[i].load(std::memory_order_relaxed);
            magnitude[i] = saturatingAbsNs(sample);
            sum += static_cast<double>(sample);
            abs_sum += static_cast<double>(magnitude[i]);
            out.max_abs_ns = std::max(out.max_abs_ns, magnitude[i]);
        }
        out.mean_ns = sum / static_cast<double>(out.count);
        out.mean_abs_ns = abs_sum / static_cast<double>(out.count);
        out.p99_abs_ns = nearestRankPercentile(
            magnitude.begin(), magnitude.begin() + static_cast<std::ptrdiff_t>(out.count), 99);
        return out;
    }

  private:
    std::array<std::atomic<int64_t>, N> samples_{};
    std::atomic<uint64_t> added_{0};
};

// The last N values added, oldest first: the window of the worker's rolling means and
// latency percentiles.
//
// One thread only (add, size and [] from the same thread, no atomics): for a thread that
// keeps its own figures and hands out copies of them, as the worker does with its stats.
template <typename T, std::size_t N> class RecentValues {
  public:
    void add(T value) noexcept
    {
        values_[next_] = value;
        next_ = (next_ + 1) % N;
        count_ = count_ < N ? count_ + 1 : N;
    }
    std::size_t size() const noexcept { return count_; }
    // The i-th oldest value held, i < size().
    T operator[](std::size_t i) const noexcept { return values_[(next_ + N - count_ + i) % N]; }

  private:
    std::array<T, N> values_{};
    std::size_t next_ = 0;
    std::size_t count_ = 0;
};

// Mean of the values held; 0 when there are none.
template <std::size_t N> double mean(const RecentValues<double, N>& values) noexcept
{
    double sum = 0.0;
    for (std::size_t i = 0; i < values.size(); ++i)
        sum += values[i];
    return values.size() == 0 ? 0.0 : sum / static_cast<double>(values.size());
}

} // namespace stereod
