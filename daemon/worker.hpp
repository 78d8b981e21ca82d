#pragma once
// The worker: one thread that takes stereo pairs from the ring, runs the stereo chain on
// each into the publisher's back slot, and publishes the result.
//
// Per pair: the worker gathers the pair's facts (processed or bad, the capture times'
// skew, the region's measurement from the chain, calibration health) and the reading is
// judgeReading() of them (pipeline/reading_verdict.hpp): a pair whose capture times differ
// by more than max_skew_ms gives an out_of_sync reading (still published, with its stamp,
// so that clients see why there is no distance); an exception from the chain gives a
// bad_frame reading and a log line (rate-limited), never an exception across threads; the
// frames go back to their source right after processing. The depth, disparity and cloud of an
// out_of_sync or bad_frame pair are cleared (PublishedFrame::depth_valid false); those of a pair
// whose region only lacked data (too_few_valid_pixels, nothing_in_range) are kept.
//
// Raw frames: while the publisher says they are wanted (Publisher::rawWanted()), the pair
// is copied as captured into the slot's RawPair before it goes back to its source.
//
// Uncalibrated mode (no processor): the worker runs no stereo chain; every pair gives an
// `uncalibrated` reading (with its stamp and frame number) and, when wanted, its raw
// frames, so that a calibration can be made from the running service. A calibration that
// comes later (a ROS 2 driver's camera_info) hands its chain over with installProcessor(),
// and the worker processes from its next pair on.
//
// Thread contract: start(), join() and the destructor from the controlling thread;
// updateSettings(), installProcessor(), busySinceNs() and waitFinished() from any thread; the
// processor and the publisher's write side are used by the worker thread only while it runs.

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include "base/rate_estimate.hpp"
#include "base/rolling_window.hpp"
#include "base/unique_fd.hpp"
#include "capture/frame_source.hpp"
#include "daemon/calibration_health_monitor.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/publisher.hpp"
#include "pipeline/stereo_processor.hpp"
#include "pipeline/zones.hpp"

namespace stereod {

// Logs the disparity range chosen, and warns when the cap keeps the configured closest
// distance out of sight ("cannot see closer than X m with N disparities").
void logDisparityRange(const DisparityRange& range, const MatcherSettings& settings,
                       const std::string& matcher_name);
// A warning when the nearest-object region reaches so near the image's left edge that its
// left columns cannot see as near as the range measures (LeftEdgeView): a surface that
// near there goes unseen, and the reading passes over it.
void logRegionLeftEdge(const StereoProcessor& processor);

// Copies the pair's frames into `raw` (as captured, with each camera's own stamp) and
// marks it present; a missing frame leaves it not present. Allocates only when the
// buffers do not have the frames' size yet.
void copyRawPair(const StereoPair& pair, RawPair& raw);

class Worker {
  public:
    // Borrows all three until the worker is destroyed; `processor` may be null
    // (uncalibrated mode). `max_skew_ms`: pairs further apart give out_of_sync readings.
    Worker(PairRing& ring, Publisher& publisher, StereoProcessor* processor, double max_skew_ms);
    // Stops the ring (waking the thread) and joins it.
    ~Worker();

    Worker(const Worker&) = delete;
    Worker& operator=(const Worker&) = delete;

    // Starts the thread. Throws std::system_error when it cannot.
    void start();
    // Waits for the thread to end: it does once the ring is stopped (PairRing::stop())
    // and the pair in hand is done. Idempotent.
    void join();

    // Calibration health (borrowed until the worker is destroyed; null: none): the worker
    // offers it a rectified pair when it is due, flags readings while it is degraded or
    // failed, and withholds them (calibration_suspect) while it is failed if asked to.
    // Call before start().
    void setHealthMonitor(CalibrationHealthMonitor* monitor) noexcept { health_ = monitor; }
    void setWithholdWhenFailed(bool withhold) noexcept
    {
        withhold_when_failed_.store(withhold, std::memory_order_relaxed);
    }
    // Whether the worker takes the newest pair waiting (dropping the older ones, counted
    // with the ring's drops) or every pair oldest first: FrameSource::keepsEveryPair().
    // Newest first unless told. Call before start().
    void setTakesEveryPair(bool every) noexcept { takes_every_pair_ = every; }

    // Hands over the camera pose and keep-out zones; the worker applies them before its
    // next pair (zones whose name stays keep their hysteresis). Validated by the caller
    // (validateZonesSettings). Never blocks the worker; zones not picked up yet are
    // replaced.
    void updateZones(const ZonesSettings& zones);

    // The stereo chain of a calibration that came after start, for a worker made without
    // one, and its health monitor (null: none): the worker takes both before its next pair
    // (a frame boundary). Borrowed until the worker is destroyed. Once; never blocks.
    void installProcessor(StereoProcessor& processor, CalibrationHealthMonitor* health) noexcept
    {
        pending_health_ = health;
        pending_processor_.store(&processor, std::memory_order_release);
    }

    // Hands new settings over; the worker applies them before its next pair (a frame
    // boundary). Never blocks the worker: an atomic pointer swap; settings not picked up
    // yet are replaced. If the processor refuses them, the worker logs why and keeps the
    // ones in force.
    void updateSettings(const ProcessorSettings& settings);

    // CLOCK_MONOTONIC time at which the worker started on the pair in hand; 0 while it
    // waits for a pair. For the watchdog: a worker stuck in one pair is not alive.
    int64_t busySinceNs() const noexcept { return busy_since_ns_.load(std::memory_order_acquire); }

    // Waits until the thread has left its loop (the ring is stopped and the pair in hand
    // is done), or until `deadline_ns` (CLOCK_MONOTONIC) passes; true when it has left:
    // join() then returns at once. Any thread; for a stop with a deadline. The thread
    // says it is finished through an eventfd, so the wait is one poll(), not a polling
    // loop.
    bool waitFinished(int64_t deadline_ns) const;

  private:
    static constexpr std::size_t kWindow = 32;         // frames in the rolling means
    static constexpr std::size_t kLatencyWindow = 256; // frames in the latency percentiles

    void run();
    void processPair(StereoPair& pair);
    void applyPendingSettings();
    void refreshRange();
    void logFailure(uint64_t frame, const char* what);

    PairRing& ring_;
    Publisher& publisher_;
    StereoProcessor* processor_; // null: uncalibrated
    CalibrationHealthMonitor* health_ = nullptr;
    std::atomic<bool> withhold_when_failed_{false};
    bool takes_every_pair_ = false; // set before start(), read by the thread
    std::thread thread_;
    const double max_skew_ms_; // source.max_skew_ms, which needs a restart to change
    std::atomic<ProcessorSettings*> pending_settings_{nullptr}; // owned; see updateSettings()
    std::atomic<ZonesSettings*> pending_zones_{nullptr};        // owned; see updateZones()
    // Borrowed; see installProcessor(): pending_health_ is written before the release store
    // of pending_processor_ and read after the worker's acquire.
    std::atomic<StereoProcessor*> pending_processor_{nullptr};
    CalibrationHealthMonitor* pending_health_ = nullptr;
    std::atomic<int64_t> busy_since_ns_{0};
    UniqueFd finished_fd_; // eventfd the thread writes once when it leaves its loop

    // Worker thread only.
    ZoneMonitor zones_{ZonesSettings{}};
    PipelineStats stats_;
    RecentValues<double, kWindow> rectify_ms_, match_ms_, depth_ms_, nearest_ms_, cloud_ms_,
        zones_ms_, publish_ms_, extended_ms_, probe_ms_;
    RateEstimate<kWindow> processed_;                     // pairs done, for the rate
    RecentValues<double, kLatencyWindow> latency_ms_;     // capture stamp to publication
    std::array<double, kLatencyWindow> latency_sorted_{}; // scratch for the percentiles
    LogLimiter log_limiter_; // failing pairs: one line per 5 s, the rest counted
};

} // namespace stereod
