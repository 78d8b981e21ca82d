#pragma once
// The last N samples of a signed duration (ns) and their summary: the one meaning of
// "recent" behind the skew figures of every source in `status` (the last N pairs, not
// since start).
//
// One writer thread; summary() from any thread. Each slot is an atomic, so a reader sees
// every sample whole; a summary taken while the writer adds may mix samples of adjacent
// moments, which a statistic of the recent past tolerates. No allocation, no lock.

#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

#include "base/clock.hpp"

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
        const std::size_t rank = (out.count * 99 + 99) / 100; // ceil(0.99 n), >= 1
        const auto nth = magnitude.begin() + static_cast<std::ptrdiff_t>(rank - 1);
        std::nth_element(magnitude.begin(), nth,
                         magnitude.begin() + static_cast<std::ptrdiff_t>(out.count));
        out.p99_abs_ns = *nth;
        return out;
    }

  private:
    std::array<std::atomic<int64_t>, N> samples_{};
    std::atomic<uint64_t> added_{0};
};

} // namespace stereod
