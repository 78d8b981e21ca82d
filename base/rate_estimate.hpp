#pragma once
// The rate of recent events: the one definition behind every `fps` of `status` (a camera's
// delivered frames, a replay's delivered pairs, a ROS 2 topic's arrivals, the worker's
// processed pairs).
//
// Definition: over the last N events (fewer until N have come), the number of intervals
// divided by the time they span: (events - 1) / (newest - oldest). 0 until two events have
// come; a span that does not advance (events at one instant, or a clock read out of order)
// leaves the figure as it was. The figure is new at every event, and each user chooses N for
// its pace (32 frames is about a second at 30 fps). A sliding window of events rather than
// a fixed window of time: it is what the replay, ROS 2 and worker figures already were, and
// the cameras' windows of at least one second, which gave a figure that was up to a second
// old and moved once a second, now follow the same rule as the rest. Whether a figure is
// stale (a camera silent for 2 s, a replay that is not running) is the user's rule, decided
// where it reads the figure: the estimate knows no clock.
//
// Thread contract: one writer thread calls add() and restart(); perSecond() from any thread.
// The event times are the writer's alone (plain slots); the figure is published through an
// atomic at each add(), so a reader never waits and never sees half a figure. No lock, no
// allocation: fit for a capture thread (docs/architecture.md).
//
// Units: event times in ns on one clock (CLOCK_MONOTONIC for every user today); the figure in
// events per second.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

namespace stereod {

template <std::size_t N> class RateEstimate {
    static_assert(N >= 2, "a rate needs at least two events");

  public:
    static constexpr std::size_t kEvents = N;

    // An event at `time_ns`. Writer thread only.
    void add(int64_t time_ns) noexcept
    {
        times_ns_[count_ % N] = time_ns;
        ++count_;
        const std::size_t held = count_ < N ? count_ : N;
        if (held < 2)
            return;
        const int64_t oldest_ns = times_ns_[(count_ - held) % N];
        if (time_ns > oldest_ns) {
            per_second_.store(static_cast<double>(held - 1) * 1e9 /
                                  static_cast<double>(time_ns - oldest_ns),
                              std::memory_order_relaxed);
        }
    }

    // Forgets the events (a source starting again), so that the next figure comes from
    // events after this; the figure published stays until then. Writer thread only (or
    // the thread that owns the writer while it is not running).
    void restart() noexcept { count_ = 0; }

    // Events per second over the last N events; 0 before two. Any thread.
    double perSecond() const noexcept { return per_second_.load(std::memory_order_relaxed); }

  private:
    std::array<int64_t, N> times_ns_{}; // writer only: a ring of the last N event times
    std::size_t count_ = 0;             // writer only: events since the start or restart()
    std::atomic<double> per_second_{0.0};
};

} // namespace stereod
