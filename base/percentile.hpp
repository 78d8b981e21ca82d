#pragma once
// The project's two percentile rules, named, and the selection of a percentile from a range:
// the one definition behind every percentile figure (status's latency and skew, the nearest
// object's distance, the calibration health's row offset).
//
// Two rules on purpose, each promised by the docs of its figure:
// - lower of the linear position: index floor(percent / 100 * (n - 1)) into the ascending
//   values. The latency p50/p99, the nearest-object and zone distances, the health figures.
// - nearest rank: the smallest value at or above percent % of them, index ceil(percent / 100
//   * n) - 1. The skew p99 of status (base/rolling_window.hpp).
//
// Pure functions; any thread. selectPercentile() reorders the range it is given (no
// allocation). Percents are 0..100 (lower-of-linear clamps; nearest rank takes whole percents).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <iterator>

namespace stereod {

// floor(percent / 100 * (count - 1)), percent clamped to 0..100. count must be > 0.
inline std::size_t lowerLinearIndex(double percent, std::size_t count) noexcept
{
    const double position =
        std::clamp(percent, 0.0, 100.0) / 100.0 * static_cast<double>(count - 1);
    return std::min(count - 1, static_cast<std::size_t>(std::floor(position)));
}

// ceil(percent / 100 * count) - 1 in whole numbers (no rounding error), at least 0;
// percent 0..100. count must be > 0.
inline std::size_t nearestRankIndex(unsigned percent, std::size_t count) noexcept
{
    const std::size_t rank = (count * percent + 99) / 100;
    return std::min(count, std::max<std::size_t>(rank, 1)) - 1;
}

// The value at `index` of [first, last) once sorted ascending; reorders the range
// (std::nth_element). index < distance(first, last).
template <typename RandomIt>
auto selectNth(RandomIt first, RandomIt last, std::size_t index) ->
    typename std::iterator_traits<RandomIt>::value_type
{
    const RandomIt nth = first + static_cast<std::ptrdiff_t>(index);
    std::nth_element(first, nth, last);
    return *nth;
}

// The lower-of-linear percentile of [first, last), reordered; not empty.
template <typename RandomIt>
auto lowerLinearPercentile(RandomIt first, RandomIt last, double percent) ->
    typename std::iterator_traits<RandomIt>::value_type
{
    return selectNth(
        first, last,
        lowerLinearIndex(percent, static_cast<std::size_t>(std::distance(first, last))));
}

// The nearest-rank percentile of [first, last), reordered; not empty.
template <typename RandomIt>
auto nearestRankPercentile(RandomIt first, RandomIt last, unsigned percent) ->
    typename std::iterator_traits<RandomIt>::value_type
{
    return selectNth(
        first, last,
        nearestRankIndex(percent, static_cast<std::size_t>(std::distance(first, last))));
}

} // namespace stereod
