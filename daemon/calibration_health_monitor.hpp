#pragma once
// Calibration health while the service runs (pipeline/calibration_health.hpp): every
// `interval_s` the worker hands over a copy of the rectified pair it just matched, and a
// thread of its own, at a lower scheduling priority, measures how far apart the rows of
// matching features are. The state (ok, degraded, failed, unknown) follows the checks
// with hysteresis (pipeline/calibration_health_hysteresis.hpp): it changes only when
// several checks agree. It is logged once when it changes, never per frame; readings are
// flagged while it is degraded or failed.
//
// Thread contract: due() and offer() from the worker thread only (never blocking: a pair
// offered while a measurement runs is not taken); state(), rowOffsetPx(), report() and
// waitForChecks() from any thread; setInterval() from the controlling thread.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "pipeline/calibration_health.hpp"
#include "pipeline/calibration_health_hysteresis.hpp"

namespace stereod {

// What the monitor last found, for `status`. The state and its reason are the
// hysteresis's; the figures are those of the last check.
struct HealthReport {
    bool enabled = false;
    HealthState state = HealthState::Unknown;
    std::string reason = "no_check_yet";                 // see HealthMeasurement::reason
    HealthState last_check_state = HealthState::Unknown; // the last check's own verdict
    uint64_t state_changes = 0;                          // changes of state after the first verdict
    int matches = 0;
    double row_offset_px = 0.0; // signed median, right row - left row
    double row_offset_p90_px = 0.0;
    // The fitted model (RowOffsetModel): rows apart at the principal point, the roll, and
    // the largest row error over the area the matches cover (signed as right - left).
    double offset_px = 0.0;
    double roll_deg = 0.0;
    double max_row_error_px = 0.0;
    double row_error_px = 0.0;
    // Change of the row offset per minute, from the checks of the last minutes (0 with
    // fewer than three checks ten seconds apart).
    double trend_px_per_min = 0.0;
    uint64_t checks = 0;
    int64_t checked_stamp_ns = 0; // capture stamp of the pair last checked
    double check_ms = 0.0;        // what the last check cost, on its own thread
};

class CalibrationHealthMonitor {
  public:
    // `geometry`: the rectified images' (pipeline/calibration.hpp). interval_s <= 0: no
    // checks (state unknown, reason "off").
    CalibrationHealthMonitor(const RectifiedGeometry& geometry, double interval_s);
    ~CalibrationHealthMonitor();

    CalibrationHealthMonitor(const CalibrationHealthMonitor&) = delete;
    CalibrationHealthMonitor& operator=(const CalibrationHealthMonitor&) = delete;

    // Whether a pair is wanted now: checks are on, the last one is an interval old and
    // none is running.
    bool due(int64_t now_ns) const noexcept;
    // Copies the rectified pair (CV_8UC1, same size) and wakes the measuring thread.
    void offer(const cv::Mat& left_rectified, const cv::Mat& right_rectified, int64_t stamp_ns);

    HealthState state() const noexcept { return state_.load(std::memory_order_acquire); }
    // The largest row error (signed, right - left) of the last check with a verdict: what a
    // flagged reading reports.
    double rowOffsetPx() const noexcept { return row_offset_px_.load(std::memory_order_acquire); }
    HealthReport report() const;
    // Blocks until `count` checks are done and the monitor is ready for the next pair, or
    // `timeout` has passed; true when they are. For tools and tests that hand it pairs one
    // after the other.
    bool waitForChecks(uint64_t count, std::chrono::milliseconds timeout) const;

    void setInterval(double interval_s);

  private:
    void run();
    void measureOffered();

    std::atomic<int64_t> interval_ns_;
    std::atomic<int64_t> next_due_ns_{0};
    std::atomic<bool> busy_{false}; // a pair is waiting or being measured
    std::atomic<HealthState> state_{HealthState::Unknown};
    std::atomic<double> row_offset_px_{0.0};

    mutable std::mutex mutex_;
    std::condition_variable wake_;            // a pair was offered, or stop
    mutable std::condition_variable checked_; // a check is done and busy_ cleared
    bool stop_ = false;                       // guarded by mutex_
    bool ready_ = false;                      // guarded by mutex_: an offered pair is copied
    HealthReport report_;                     // guarded by mutex_
    HealthHysteresis hysteresis_;             // guarded by mutex_

    // Owned by whoever holds busy_: the worker fills them, the thread measures them.
    cv::Mat left_, right_;
    int64_t stamp_ns_ = 0;
    // The measuring thread's own.
    CalibrationHealthChecker checker_;
    struct Sample {
        int64_t stamp_ns;
        double row_offset_px;
    };
    std::vector<Sample> history_; // recent checks, for the trend
    std::thread thread_;
};

} // namespace stereod
