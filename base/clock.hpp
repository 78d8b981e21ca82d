#pragma once
// The clock of every stamp (CLOCK_MONOTONIC, in ns), its relation to the system's wall
// clock (CLOCK_REALTIME, the time base of what leaves the service for other robot tools:
// docs/architecture.md, "Time"), and arithmetic on stamps that saturates instead of
// wrapping.

#include <cstdint>
#include <limits>

namespace stereod {

// Current CLOCK_MONOTONIC time in nanoseconds: the clock of every capture stamp.
int64_t monotonicNowNs() noexcept;

// CLOCK_REALTIME minus CLOCK_MONOTONIC now, in ns: added to a capture stamp, the same
// instant on the wall clock (ns since the Unix epoch). Sampled between two reads of the
// monotonic clock, so it is off by at most the time one clock read takes. It changes when
// the wall clock is set or slewed (NTP): take it once per pair and convert every stamp of
// that pair with it (PublishedFrame::realtimeNs()).
int64_t realtimeOffsetNs() noexcept;

// a - b and a + b in ns, saturated to the int64_t range instead of wrapping: stamps
// come from devices and recordings, and may be anything (a recording stamped INT64_MIN
// and INT64_MAX must read as far apart, not as 0 apart).
constexpr int64_t saturatingSubNs(int64_t a, int64_t b) noexcept
{
    int64_t difference = 0;
    if (__builtin_sub_overflow(a, b, &difference))
        return a < b ? std::numeric_limits<int64_t>::min() : std::numeric_limits<int64_t>::max();
    return difference;
}

constexpr int64_t saturatingAddNs(int64_t a, int64_t b) noexcept
{
    int64_t sum = 0;
    if (__builtin_add_overflow(a, b, &sum))
        return b < 0 ? std::numeric_limits<int64_t>::min() : std::numeric_limits<int64_t>::max();
    return sum;
}

// |value|, with INT64_MIN giving INT64_MAX.
constexpr int64_t saturatingAbsNs(int64_t value) noexcept
{
    return value >= 0
               ? value
               : (value == std::numeric_limits<int64_t>::min() ? std::numeric_limits<int64_t>::max()
                                                               : -value);
}

} // namespace stereod
