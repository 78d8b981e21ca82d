#include "base/clock.hpp"

#include <ctime>

namespace stereod {

int64_t monotonicNowNs() noexcept
{
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

int64_t realtimeOffsetNs() noexcept
{
    timespec before{}, realtime{}, after{};
    clock_gettime(CLOCK_MONOTONIC, &before);
    clock_gettime(CLOCK_REALTIME, &realtime);
    clock_gettime(CLOCK_MONOTONIC, &after);
    const auto ns = [](const timespec& ts) {
        return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
    };
    // The realtime read sits between the two monotonic ones: against their middle.
    const int64_t monotonic = ns(before) + (ns(after) - ns(before)) / 2;
    return ns(realtime) - monotonic;
}

} // namespace stereod
