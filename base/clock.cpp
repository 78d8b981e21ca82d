#include "base/clock.hpp"

#include <ctime>

namespace stereod {

namespace {

int64_t nowNs(clockid_t clock) noexcept
{
    timespec ts{};
    clock_gettime(clock, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

} // namespace

int64_t monotonicNowNs() noexcept
{
    return nowNs(CLOCK_MONOTONIC);
}

int64_t realtimeFromMonotonicNs(int64_t monotonic_ns) noexcept
{
    const int64_t offset_ns = nowNs(CLOCK_REALTIME) - nowNs(CLOCK_MONOTONIC);
    return saturatingAddNs(monotonic_ns, offset_ns);
}

} // namespace stereod
