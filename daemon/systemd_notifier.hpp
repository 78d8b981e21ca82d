#pragma once
// What the service tells systemd over its notify socket (sd_notify(3)), and when:
//
//  - READY=1 once the socket listens and the first pair has arrived from the source, or,
//    when the source has delivered nothing for source.stall_timeout_ms, with the source
//    reported down (a camera unplugged at boot: the service runs and says why there is
//    no reading, rather than failing its start and being restarted in a loop);
//  - STATUS= a line a person reads in `systemctl status`: state, fps, frame, clients,
//    each camera's state, the last error (statusLine());
//  - WATCHDOG=1 every quarter of WatchdogSec=, from a thread of its own (WatchdogPinger),
//    only while the service makes progress (the watchdog rule, workerMakesProgress()); a
//    hung pipeline or event loop stops the pings and systemd restarts the service;
//  - RELOADING=1 / READY=1 around a reload, STOPPING=1 at the stop.
//
// Without NOTIFY_SOCKET (not started by systemd) every call does nothing.
//
// Thread contract: SystemdNotifier is thread-bound (the I/O thread), except watchdog(),
// which is the WatchdogPinger's thread's only.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>

#include "capture/frame_source.hpp"

namespace stereod {

// The watchdog rule. The service is alive when its event loop turns (it ran its timer
// within one watchdog interval) and the worker is not stuck: it is waiting for a pair
// (`busy_since_ns` = 0), or it has been on the pair in hand for less than `stuck_after_ns`. A
// source that is idle for a legitimate reason (a replay that finished, a camera unplugged) leaves
// the worker waiting: the service is alive and keeps pinging, and says in STATUS= why there is no
// reading.
bool workerMakesProgress(int64_t busy_since_ns, int64_t now_ns, int64_t stuck_after_ns) noexcept;

// What the STATUS= line is made of.
struct StatusFacts {
    bool source_down = false;
    std::string_view down_reason; // when source_down
    bool uncalibrated = false;
    bool have_frame = false; // a result has been published
    double fps = 0.0;        // processing rate now (0 when frames stopped)
    uint64_t frame = 0;      // the newest result's frame number
    uint64_t clients = 0;    // open connections
    const SourceStatus* source = nullptr;
    std::string_view last_error; // the newest error worth a person's eye, or empty
};

// "running: 9.8 fps, frame 1234, 2 clients; left streaming, right streaming; last error:
// ...". At most `max_bytes` bytes (systemd shows one line; longer ones are cut).
std::string statusLine(const StatusFacts& facts, std::size_t max_bytes = 400);

class SystemdNotifier {
  public:
    // `enabled` false: never notifies (in-process tests, --check-config). Otherwise reads
    // NOTIFY_SOCKET and WATCHDOG_USEC/WATCHDOG_PID (sd_watchdog_enabled()).
    explicit SystemdNotifier(bool enabled);

    bool enabled() const noexcept { return enabled_; }
    // WatchdogSec= in ns, 0 without a watchdog.
    int64_t watchdogIntervalNs() const noexcept { return watchdog_interval_ns_; }
    bool readySent() const noexcept { return ready_sent_; }

    // READY=1 with a STATUS= line; once.
    void ready(const std::string& status);
    // Whether a periodic STATUS= line is due (every 2 s).
    bool statusDue(int64_t now_ns) const noexcept;
    // STATUS= line, at most every 2 s unless `now` (a reload, an error just now).
    void status(const std::string& status, int64_t now_ns, bool now = false);
    // WATCHDOG=1 when a quarter of the interval has passed since the last ping and
    // `alive`. Returns whether a ping was sent. The WatchdogPinger's thread only.
    bool watchdog(bool alive, int64_t now_ns);
    void reloading();
    void reloaded(const std::string& status);
    void stopping();

  private:
    bool send(const std::string& message);

    bool enabled_ = false;
    int64_t watchdog_interval_ns_ = 0;
    int64_t last_ping_ns_ = 0; // the pinger's thread only
    bool ready_sent_ = false;
    std::string last_status_;
    int64_t last_status_ns_ = 0;
};

// Sends the watchdog pings from a thread of its own, so that they do not wait for the
// event loop's work: every few milliseconds it asks `alive` (the watchdog rule) and pings
// through the notifier when a ping is due. Does nothing without a watchdog.
//
// Thread contract: start(), stop() and the destructor from the controlling thread;
// `alive` is called on the pinger's thread and must be thread-safe.
class WatchdogPinger {
  public:
    WatchdogPinger(SystemdNotifier& notifier, std::function<bool(int64_t now_ns)> alive);
    ~WatchdogPinger(); // stop()

    WatchdogPinger(const WatchdogPinger&) = delete;
    WatchdogPinger& operator=(const WatchdogPinger&) = delete;

    // Starts the thread when the notifier has a watchdog interval.
    void start();
    // Ends the thread; no ping after it returns. Idempotent.
    void stop();

  private:
    void run();

    SystemdNotifier& notifier_;
    std::function<bool(int64_t)> alive_;
    std::thread thread_;
    std::mutex mutex_;
    std::condition_variable wake_;
    bool stopping_ = false; // guarded by mutex_
};

} // namespace stereod
