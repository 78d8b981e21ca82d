#include "daemon/calibration_health_monitor.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <unistd.h>

#include "capture/frame.hpp"

namespace stereod {
namespace {

// Checks kept for the trend, and how far back it looks.
constexpr std::size_t kHistory = 64;
constexpr int64_t kTrendWindowNs = 5LL * 60 * 1'000'000'000;
// Below normal priority: the check waits for the pipeline, never the reverse.
constexpr int kNice = 10;

int64_t toNs(double seconds)
{
    return seconds > 0.0 ? static_cast<int64_t>(seconds * 1e9) : 0;
}

// Least-squares slope of the row offset against time, px per minute.
double trendPerMinute(const std::vector<std::pair<double, double>>& minutes_offsets)
{
    const double n = static_cast<double>(minutes_offsets.size());
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (const auto& [x, y] : minutes_offsets) {
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
    }
    const double denominator = n * sxx - sx * sx;
    return denominator > 0.0 ? (n * sxy - sx * sy) / denominator : 0.0;
}

} // namespace

CalibrationHealthMonitor::CalibrationHealthMonitor(const RectifiedGeometry& geometry,
                                                   double interval_s)
    : interval_ns_(toNs(interval_s)), checker_(geometry)
{
    report_.enabled = interval_s > 0.0;
    if (!report_.enabled)
        report_.reason = "off";
    history_.reserve(kHistory);
    thread_ = std::thread([this] { run(); });
}

CalibrationHealthMonitor::~CalibrationHealthMonitor()
{
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_one();
    thread_.join();
}

void CalibrationHealthMonitor::setInterval(double interval_s)
{
    interval_ns_.store(toNs(interval_s), std::memory_order_release);
    std::lock_guard lock(mutex_);
    report_.enabled = interval_s > 0.0;
    if (!report_.enabled) {
        report_.reason = "off";
        report_.state = HealthState::Unknown;
        hysteresis_.reset();
        state_.store(HealthState::Unknown, std::memory_order_release);
    }
}

bool CalibrationHealthMonitor::due(int64_t now_ns) const noexcept
{
    return interval_ns_.load(std::memory_order_acquire) > 0 &&
           now_ns >= next_due_ns_.load(std::memory_order_acquire) &&
           !busy_.load(std::memory_order_acquire);
}

void CalibrationHealthMonitor::offer(const cv::Mat& left_rectified, const cv::Mat& right_rectified,
                                     int64_t stamp_ns)
{
    if (left_rectified.empty() || right_rectified.empty() ||
        left_rectified.size() != right_rectified.size() || busy_.exchange(true))
        return;
    // Buffers keep their size: copying allocates only for the first pair.
    left_rectified.copyTo(left_);
    right_rectified.copyTo(right_);
    stamp_ns_ = stamp_ns;
    next_due_ns_.store(monotonicNowNs() + interval_ns_.load(std::memory_order_acquire),
                       std::memory_order_release);
    {
        std::lock_guard lock(mutex_);
        ready_ = true;
    }
    wake_.notify_one();
}

void CalibrationHealthMonitor::run()
{
    // This thread's own niceness (Linux schedules threads one by one).
    ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), kNice);
    std::unique_lock lock(mutex_);
    for (;;) {
        wake_.wait(lock, [this] { return stop_ || ready_; });
        if (stop_)
            return;
        lock.unlock();
        measureOffered();
        lock.lock();
        ready_ = false;
        busy_.store(false, std::memory_order_release);
        checked_.notify_all();
    }
}

void CalibrationHealthMonitor::measureOffered()
{
    const auto start = std::chrono::steady_clock::now();
    const HealthMeasurement m = checker_.measure(left_, right_);
    const double check_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();

    if (m.state != HealthState::Unknown) {
        if (history_.size() == kHistory)
            history_.erase(history_.begin());
        history_.push_back({stamp_ns_, m.row_offset_px});
    }
    std::vector<std::pair<double, double>> recent;
    for (const Sample& s : history_)
        if (stamp_ns_ - s.stamp_ns <= kTrendWindowNs)
            recent.emplace_back(static_cast<double>(s.stamp_ns - stamp_ns_) / 60e9,
                                s.row_offset_px);
    const bool spans =
        recent.size() >= 3 && (recent.back().first - recent.front().first) * 60.0 >= 10.0;

    HealthState previous, now;
    bool changed;
    std::string reason;
    {
        std::lock_guard lock(mutex_);
        previous = hysteresis_.state();
        changed = hysteresis_.update(m);
        now = hysteresis_.state();
        // Before the first verdict the state's reason is the checks' own (too few matches).
        reason = now == HealthState::Unknown ? m.reason : hysteresis_.reason();
        report_.state = now;
        report_.reason = reason;
        report_.last_check_state = m.state;
        report_.state_changes += changed && previous != HealthState::Unknown;
        report_.matches = m.matches;
        report_.row_offset_px = m.row_offset_px;
        report_.row_offset_p90_px = m.row_offset_p90_px;
        report_.offset_px = m.model.offset_px;
        report_.roll_deg = m.model.roll_deg;
        report_.max_row_error_px = m.model.max_row_error_px;
        report_.row_error_px = m.model.row_error_px;
        report_.trend_px_per_min = spans ? trendPerMinute(recent) : 0.0;
        report_.checked_stamp_ns = stamp_ns_;
        report_.check_ms = check_ms;
        ++report_.checks;
    }
    if (m.state != HealthState::Unknown)
        row_offset_px_.store(m.model.row_error_px, std::memory_order_release);
    state_.store(now, std::memory_order_release);
    if (changed) {
        const auto level = now == HealthState::Ok ? spdlog::level::info : spdlog::level::warn;
        spdlog::log(level,
                    "calibration health: {} -> {}{}{}: rows of matching points up to {:.2f} px "
                    "apart, {:+.2f} px at the centre, roll {:+.3f} deg ({} matches)",
                    healthStateName(previous), healthStateName(now), reason.empty() ? "" : ", ",
                    reason, m.model.max_row_error_px, m.model.offset_px, m.model.roll_deg,
                    m.matches);
    }
}

HealthReport CalibrationHealthMonitor::report() const
{
    std::lock_guard lock(mutex_);
    return report_;
}

bool CalibrationHealthMonitor::waitForChecks(uint64_t count,
                                             std::chrono::milliseconds timeout) const
{
    std::unique_lock lock(mutex_);
    // busy_ is cleared under mutex_ before checked_ is notified.
    return checked_.wait_for(lock, timeout, [&] {
        return report_.checks >= count && !busy_.load(std::memory_order_acquire);
    });
}

} // namespace stereod
