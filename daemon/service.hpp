#pragma once
// The service: the frame source, the ring, the worker, the publisher and the socket
// server wired together, with their start-up checks, shutdown, signals, reload and
// systemd notifications.
//
// Life cycle: the constructor checks everything that can be checked before running
// (frames against the calibration, the processor's settings, the socket) and throws
// StartupError with the exit code for the problem; run() starts the source and the
// worker and serves until requestStop() (SIGTERM/SIGINT, through the signal watch,
// daemon/signal_watch.hpp), telling systemd how it goes
// (daemon/systemd_notifier.hpp); then it closes the socket and removes its file, stops
// the source and the ring (which wakes the worker), and waits for the worker to finish
// the pair in hand, but no longer than ServiceOptions::stop_timeout_ms after the stop
// request: a full-size frame can take more than a second to match, and a stop must not.
// A worker still busy then is left running (workerAbandoned()); `stereod` then exits at
// once without destroying what the worker uses (abandonProcess()). The stop sequence is
// drawn in docs/architecture.md, "Stopping".
//
// Thread contract: construction, run() and destruction one after the other (run() on
// the thread that becomes the I/O thread); requestStop(), waitStopTaken() and
// requestReload() from any thread at any time.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>

#include "base/unique_fd.hpp"
#include "capture/frame_source.hpp"
#include "config/service_config.hpp"
#include "daemon/calibration_health_monitor.hpp"
#include "daemon/live_view/live_view.hpp"
#include "daemon/publisher.hpp"
#include "daemon/ros2_observer.hpp"
#include "daemon/socket_server.hpp"
#include "daemon/source_counter_watch.hpp"
#include "daemon/systemd_notifier.hpp"
#include "daemon/worker.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/stereo_processor.hpp"

namespace stereod {

// The exit codes of `stereod` (also in docs/service.md).
enum class ExitCode : int {
    Ok = 0,
    Failure = 1,       // anything not listed below (a failure while running)
    BadArguments = 2,  // the command line
    InvalidConfig = 3, // the configuration file or its values
    Calibration = 4,   // the calibration: missing, unreadable, invalid, or not the frame size
    Source = 5,        // the frame source: missing or unreadable recording, cannot start
    Socket = 6,        // the socket: cannot bind, in use, bad path, mode or group
};

// Start-up cannot go on. what() names what is wrong (file, key, path, errno text).
class StartupError : public std::runtime_error {
  public:
    StartupError(ExitCode code, const std::string& message)
        : std::runtime_error(message), code_(code)
    {
    }
    ExitCode code() const noexcept { return code_; }

  private:
    ExitCode code_;
};

// The exit code for an invalid configuration: Source when its only problems concern
// source.replay.path, Calibration when they only concern `calibration`, else
// InvalidConfig.
ExitCode exitCodeFor(const ConfigError& error);

// The processing settings as the stereo chain checks them against the calibration (a
// disparity range wider than the image, a region of interest of no pixel, ...): the
// problem, naming the key and `origin` (the configuration file), or empty when they fit.
std::string processingProblem(const ProcessorSettings& settings,
                              const StereoCalibration& calibration, const std::string& origin);

// A calibration that came after start-up, and where it came from (for `status`, the log and
// the `calibration` request).
struct ArrivingCalibration {
    StereoCalibration calibration;
    std::string origin;
};

struct ServiceOptions {
    // The file `reload` and SIGHUP re-read; empty when running on built-in defaults.
    std::string config_path;
    // Applied again on every reload, so that they do not show up as changes.
    ConfigOverrides overrides;
    // Where the calibration came from, for `status`.
    std::string calibration_path;
    // The text of that file as loaded, for the `calibration` request (empty: the
    // calibration did not come from a file).
    std::string calibration_text;
    // Where a calibration may come from after start-up when none was given (source.type
    // ros2: the drivers' camera_info): asked on the I/O thread at every tick while the
    // service is uncalibrated. The first one it gives is installed, or refused with the
    // reason in the log and STATUS=, and it is asked no more. Unset: none comes.
    std::function<std::optional<ArrivingCalibration>()> calibration_feed;
    // Talk to systemd (READY=1, STATUS=, WATCHDOG=1); harmless without systemd.
    bool notify_systemd = false;
    // How long after the stop request the worker may take to finish the pair in hand.
    int64_t stop_timeout_ms = 700;
    // The live view page's files (index.html, ...).
    std::string live_view_web_root = STEREOD_LIVE_VIEW_WEB_ROOT;
};

class Service final : private ServerBackend {
  public:
    // Takes the source (not started) and a loaded calibration, or none: uncalibrated mode
    // (no stereo chain; readings say `uncalibrated`, raw frames are served, `status` says
    // "uncalibrated") until options.calibration_feed gives one. Throws StartupError: Calibration
    // when the source's frames do not fit the calibration or the processor refuses it,
    // InvalidConfig when the processing settings are refused, Socket when the socket cannot be set
    // up.
    Service(ServiceConfig config, std::unique_ptr<FrameSource> source,
            std::optional<StereoCalibration> calibration, ServiceOptions options);
    ~Service() override;

    Service(const Service&) = delete;
    Service& operator=(const Service&) = delete;

    // Runs until a stop; returns the exit code. Throws StartupError(Source) when the
    // source cannot start.
    ExitCode run();

    // Makes run() return soon. Any thread.
    void requestStop() noexcept;

    // Waits up to `timeout_ms` for the event loop to take a stop request, or for the
    // service to be stopping anyway; true when it has. Any thread: a stop request that
    // stays untaken means the loop is not running (daemon/signal_watch.hpp).
    bool waitStopTaken(int64_t timeout_ms);

    // Makes the event loop re-read the configuration file soon (SIGHUP). Any thread.
    void requestReload() noexcept;

    // Re-reads the configuration file and applies what can change live. I/O thread.
    ReloadOutcome reloadConfig();

    // After run(): the worker was still inside a pair at the stop deadline and is left
    // running. The process must then end without destroying the service (std::_Exit):
    // the destructor would wait for the worker. Nothing is lost: the service keeps no
    // state on disk, and the socket is already closed and removed.
    bool workerAbandoned() const noexcept { return worker_abandoned_; }

    const std::string& socketPath() const noexcept { return config_.socket.path; }

  private:
    SourceHealth sourceHealth(int64_t now_ns) override;
    ServiceStatus serviceStatus(const PublishedFrame* latest, const SourceHealth& health,
                                int64_t now_ns) override;
    ReloadOutcome reload() override;
    void onTick(int64_t now_ns) override;
    LiveViewLinks liveViewLinks() override;
    // The watchdog rule (daemon/systemd_notifier.hpp), asked by the pinger's thread: the
    // event loop ran its timer within one watchdog interval, and the worker is not stuck
    // in one pair for as long. The pings come from their own thread, so a loop busy with
    // a backlog does not delay them; a loop that stops turning still stops them.
    bool alive(int64_t now_ns) const noexcept;

    // Reads the configuration file and applies what can change live (reloadConfig()
    // adds the log lines and the notifications).
    ReloadOutcome loadAndApply();
    // Hands one live part of `proposed` to the running service and keeps it in config_.
    void applyLivePart(LivePart part, const ServiceConfig& proposed);
    // The STATUS= line for systemd now.
    std::string statusText(int64_t now_ns, const SourceHealth& health);
    // Shares the descriptors left under RLIMIT_NOFILE between the socket's clients and
    // the live view's connections, each at most what the configuration asks; says so when
    // the limit makes them fewer (sets socket_max_clients_, live_view_connections_).
    void budgetDescriptors();
    // Listens for the live view when live_view.listen says so; a failure is logged and
    // the service runs on without it.
    void startLiveView();
    // Joins the DDS domain as a ROS 2 node when ros2.enabled says so; a failure is logged
    // and the service runs on without it.
    void startRos2();
    void onStopRequest();
    void onReloadRequest();
    // Takes a calibration that came after start-up (ServiceOptions::calibration_feed) while
    // uncalibrated: checked as the constructor checks one, its stereo chain made here and
    // handed to the worker, the socket server, the live view and the ROS 2 node told. A
    // calibration refused leaves the service uncalibrated, with the reason. I/O thread.
    void installCalibration(ArrivingCalibration arriving);
    // Records that the service is stopping and wakes waitStopTaken().
    void markStopTaken() noexcept;
    void shutdown() noexcept;

    ServiceConfig config_;
    ServiceOptions options_;
    std::unique_ptr<FrameSource> source_;
    std::optional<StereoCalibration> calibration_; // none: uncalibrated mode
    std::unique_ptr<StereoProcessor> processor_;   // null in uncalibrated mode
    // Calibration health; outlives the worker, which borrows it. Null when uncalibrated.
    std::unique_ptr<CalibrationHealthMonitor> health_;
    std::unique_ptr<PairRing> ring_;
    std::unique_ptr<Publisher> publisher_;
    std::unique_ptr<Worker> worker_;
    std::unique_ptr<SocketServer> server_;
    std::unique_ptr<live_view::LiveView> live_view_; // none when live_view.listen is off
    int socket_max_clients_ = 0;                     // socket.max_clients, within the budget
    std::size_t live_view_connections_ = 0;          // the live view's sockets, within the budget
    std::unique_ptr<ros2::Ros2Publisher> ros2_;      // none when ros2.enabled is false
    std::unique_ptr<Ros2Observer> ros2_observer_;
    PublishObservers observers_; // the live view and the ROS 2 node, as they started
    UniqueFd stop_fd_;           // eventfd written by requestStop(); outlives server_
    UniqueFd reload_fd_;         // eventfd written by requestReload(); outlives server_

    DisparityRange initial_range_; // for `status` before the first frame
    std::string initial_matcher_;
    std::optional<double> initial_max_output_depth_m_; // none uncalibrated
    int64_t started_ns_ = 0;
    bool running_ = false;
    // Stall detection: when the ring's push count last changed, as seen by this thread.
    uint64_t last_pushed_ = 0;
    int64_t last_push_change_ns_ = 0;
    // systemd notifications.
    SystemdNotifier notifier_;
    // When the event loop last ran its timer, for the watchdog's pinger thread.
    std::atomic<int64_t> last_tick_ns_{0};
    WatchdogPinger watchdog_pinger_;     // after notifier_ and last_tick_ns_, which it uses
    SourceCounterWatch source_counters_; // bad/dropped/unpaired frames into the log
    std::string last_error_; // the newest error for STATUS= (a refused reload), or empty
    int64_t stop_requested_ns_ = 0;
    std::mutex stop_taken_mutex_;
    std::condition_variable stop_taken_changed_;
    bool stop_taken_ = false; // guarded by stop_taken_mutex_; see waitStopTaken()
    bool worker_abandoned_ = false;
};

} // namespace stereod
