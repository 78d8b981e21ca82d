#include "daemon/systemd_notifier.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>

#include <systemd/sd-daemon.h>

namespace stereod {

namespace {

constexpr int64_t kStatusRefreshNs = 2'000'000'000;

// systemd shows STATUS= as one line.
void appendOneLine(std::string& out, std::string_view text)
{
    for (const char c : text)
        out.push_back(c == '\n' || c == '\r' ? ' ' : c);
}

} // namespace

bool workerMakesProgress(int64_t busy_since_ns, int64_t now_ns, int64_t stuck_after_ns) noexcept
{
    return busy_since_ns == 0 || now_ns - busy_since_ns < stuck_after_ns;
}

std::string statusLine(const StatusFacts& facts, std::size_t max_bytes)
{
    std::string line;
    char number[96];
    if (facts.source_down) {
        line = "source down: ";
        appendOneLine(line, facts.down_reason);
    } else if (facts.uncalibrated) {
        line = "uncalibrated: raw frames only";
    } else if (!facts.have_frame) {
        line = "running: waiting for the first frame";
    } else {
        std::snprintf(number, sizeof number, "running: %.1f fps, frame %llu", facts.fps,
                      static_cast<unsigned long long>(facts.frame));
        line = number;
    }
    std::snprintf(number, sizeof number, ", %llu client%s",
                  static_cast<unsigned long long>(facts.clients), facts.clients == 1 ? "" : "s");
    line += number;
    if (facts.source != nullptr && !facts.source->cameras.empty()) {
        line += ";";
        const char* separator = " ";
        for (const CameraStatus& camera : facts.source->cameras) {
            line += separator;
            appendOneLine(line, camera.name);
            line += ' ';
            line += toString(camera.state);
            separator = ", ";
        }
    }
    if (!facts.last_error.empty()) {
        line += "; last error: ";
        appendOneLine(line, facts.last_error);
    }
    if (line.size() > max_bytes) {
        line.resize(max_bytes >= 3 ? max_bytes - 3 : 0);
        line += "...";
    }
    return line;
}

SystemdNotifier::SystemdNotifier(bool enabled) : enabled_(enabled)
{
    if (!enabled_)
        return;
    uint64_t watchdog_usec = 0;
    if (sd_watchdog_enabled(0, &watchdog_usec) > 0)
        watchdog_interval_ns_ = static_cast<int64_t>(watchdog_usec) * 1000;
}

bool SystemdNotifier::send(const std::string& message)
{
    return enabled_ && sd_notify(0, message.c_str()) > 0;
}

void SystemdNotifier::ready(const std::string& status)
{
    if (ready_sent_)
        return;
    ready_sent_ = true;
    send("READY=1\nSTATUS=" + status);
    last_status_ = status;
}

bool SystemdNotifier::statusDue(int64_t now_ns) const noexcept
{
    return enabled_ && now_ns - last_status_ns_ >= kStatusRefreshNs;
}

void SystemdNotifier::status(const std::string& status, int64_t now_ns, bool now)
{
    if (!now && now_ns - last_status_ns_ < kStatusRefreshNs)
        return;
    last_status_ns_ = now_ns;
    last_status_ = status;
    send("STATUS=" + status);
}

bool SystemdNotifier::watchdog(bool alive, int64_t now_ns)
{
    if (watchdog_interval_ns_ <= 0 || !alive || now_ns - last_ping_ns_ < watchdog_interval_ns_ / 4)
        return false;
    last_ping_ns_ = now_ns;
    return send("WATCHDOG=1");
}

void SystemdNotifier::reloading()
{
    if (ready_sent_)
        send("RELOADING=1\nSTATUS=reloading the configuration");
}

void SystemdNotifier::reloaded(const std::string& status)
{
    // READY=1 ends the reload for systemd; before the first READY=1 it would end the
    // start instead, which is not ours to say yet.
    send(std::string(ready_sent_ ? "READY=1\n" : "") + "STATUS=" + status);
    last_status_ = status;
}

void SystemdNotifier::stopping()
{
    send("STOPPING=1\nSTATUS=stopping");
}

WatchdogPinger::WatchdogPinger(SystemdNotifier& notifier, std::function<bool(int64_t now_ns)> alive)
    : notifier_(notifier), alive_(std::move(alive))
{
}

WatchdogPinger::~WatchdogPinger()
{
    stop();
}

void WatchdogPinger::start()
{
    if (!notifier_.enabled() || notifier_.watchdogIntervalNs() <= 0 || thread_.joinable())
        return;
    {
        std::lock_guard lock(mutex_);
        stopping_ = false;
    }
    thread_ = std::thread([this] { run(); });
}

void WatchdogPinger::stop()
{
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable())
        thread_.join();
}

void WatchdogPinger::run()
{
    // Look often enough that a ping is never late by more than a small part of the
    // interval, and at most every 10 ms.
    const auto step = std::chrono::nanoseconds(
        std::clamp<int64_t>(notifier_.watchdogIntervalNs() / 40, 1'000'000, 10'000'000));
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        lock.unlock();
        const int64_t now_ns = monotonicNowNs();
        notifier_.watchdog(alive_(now_ns), now_ns);
        lock.lock();
        wake_.wait_for(lock, step, [this] { return stopping_; });
    }
}

} // namespace stereod
