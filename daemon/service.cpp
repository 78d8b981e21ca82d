#include "daemon/service.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string_view>
#include <system_error>
#include <thread>

#include <fmt/format.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/eventfd.h>
#include <sys/signalfd.h>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "daemon/camera_source_factory.hpp"
#include "daemon/json_writer.hpp"
#include "pipeline/calibration_formats.hpp"
#include "replay/recording.hpp"
#include "replay/replay_source.hpp"

namespace stereod {

namespace {

sigset_t serviceSignals()
{
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGTERM);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGHUP);
    return signals;
}

void applyLogLevel(const std::string& level)
{
    spdlog::set_level(spdlog::level::from_str(level));
}

// The calibration file's text, read once: what is parsed is what `calibration` hands out.
// Throws std::runtime_error naming the file and the errno text.
std::string readCalibrationText(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw std::runtime_error(path + ": cannot open: " + std::system_category().message(errno));
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad())
        throw std::runtime_error(path + ": cannot read: " + std::system_category().message(errno));
    return text.str();
}

// Loads the calibration at `path`: its text (for the `calibration` request) and the parsed
// calibration. Throws StartupError(Calibration) naming the file and the problem.
StereoCalibration loadCalibrationFile(const std::string& path, std::string& text)
{
    try {
        text = readCalibrationText(path);
        return parseCalibration(text, path);
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::Calibration, e.what());
    }
}

// The processing settings as the stereo chain checks them against the calibration (a
// disparity range wider than the image, a region of interest of no pixel, ...): the
// problem, naming the key and `origin` (the configuration file), or empty when they fit.
std::string processingProblem(const ProcessorSettings& settings,
                              const StereoCalibration& calibration, const std::string& origin)
{
    try {
        validateProcessorSettings(settings, calibration.rectified);
    } catch (const std::invalid_argument& e) {
        return (origin.empty() ? std::string() : origin + ": ") + e.what() +
               " (with the calibration's " +
               std::to_string(calibration.rectified.image_size.width) + "x" +
               std::to_string(calibration.rectified.image_size.height) + " frames)";
    }
    return {};
}

} // namespace

// A configuration whose only problems are the replay path, or only the calibration
// path, is a source or a calibration problem for the exit code: `stereod --replay DIR`
// with a DIR that does not exist is a source problem, whatever layer finds it.
ExitCode exitCodeFor(const ConfigError& error)
{
    const auto all_about = [&](std::string_view key) {
        const std::string needle = ": " + std::string(key) + ": ";
        return !error.problems().empty() &&
               std::all_of(error.problems().begin(), error.problems().end(),
                           [&](const std::string& problem) {
                               return problem.find(needle) != std::string::npos;
                           });
    };
    if (all_about("source.replay.path"))
        return ExitCode::Source;
    if (all_about("calibration"))
        return ExitCode::Calibration;
    return ExitCode::InvalidConfig;
}

void blockServiceSignals()
{
    const sigset_t signals = serviceSignals();
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);
}

Service::Service(ServiceConfig config, std::unique_ptr<FrameSource> source,
                 std::optional<StereoCalibration> calibration, ServiceOptions options)
    : config_(std::move(config)), options_(std::move(options)), source_(std::move(source)),
      calibration_(std::move(calibration)), notifier_(options_.notify_systemd),
      watchdog_pinger_(notifier_, [this](int64_t now_ns) { return alive(now_ns); })
{
    const std::string calibration_origin = options_.calibration_path.empty()
                                               ? std::string("the calibration")
                                               : options_.calibration_path;
    try {
        if (calibration_) {
            checkFrameSize(*calibration_, source_->frameSize(), calibration_origin);
            const std::string problem =
                processingProblem(config_.processing, *calibration_, options_.config_path);
            if (!problem.empty())
                throw std::invalid_argument(problem);
            processor_ = std::make_unique<StereoProcessor>(*calibration_, config_.processing);
        }
    } catch (const CalibrationError& e) {
        throw StartupError(ExitCode::Calibration, e.what());
    } catch (const std::invalid_argument& e) {
        throw StartupError(ExitCode::InvalidConfig,
                           std::string("processing settings refused: ") + e.what());
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::Calibration, "cannot set up the stereo chain with " +
                                                      calibration_origin + ": " + e.what());
    }
    if (processor_) {
        initial_range_ = processor_->disparityRange();
        initial_matcher_ = processor_->matcherName();
        logDisparityRange(initial_range_, config_.processing.matcher, initial_matcher_);
    } else {
        initial_matcher_ = "none";
        spdlog::warn("no calibration: running uncalibrated, serving raw frames only; every "
                     "reading is `uncalibrated` until a calibration is given");
    }

    ring_ = std::make_unique<PairRing>(static_cast<std::size_t>(config_.source.ring_capacity));
    publisher_ = std::make_unique<Publisher>();
    worker_ =
        std::make_unique<Worker>(*ring_, *publisher_, processor_.get(), config_.source.max_skew_ms);
    if (processor_) {
        health_ = std::make_unique<CalibrationHealthMonitor>(config_.calibration_health.interval_s);
        worker_->setHealthMonitor(health_.get());
        worker_->setWithholdWhenFailed(config_.calibration_health.withhold_when_failed);
    }
    worker_->updateZones(config_.zones);

    ServerOptions server_options;
    server_options.socket = config_.socket;
    server_options.publish = config_.publish;
    if (calibration_)
        server_options.geometry = calibration_->rectified;
    server_options.calibrated = calibration_.has_value();
    server_options.calibration_path = options_.calibration_path;
    server_options.calibration_text = options_.calibration_text;
    server_options.accept_systemd_socket = options_.notify_systemd;
    try {
        server_ = std::make_unique<SocketServer>(server_options, *publisher_,
                                                 static_cast<ServerBackend&>(*this));
    } catch (const SocketError& e) {
        throw StartupError(ExitCode::Socket, e.what());
    }

    stop_fd_ = UniqueFd(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
    if (!stop_fd_)
        throw StartupError(ExitCode::Failure,
                           "cannot create an eventfd: " + std::system_category().message(errno));
    server_->watch(stop_fd_.get(), [this] { onStopRequest(); });

    if (options_.handle_signals) {
        blockServiceSignals();
        const sigset_t signals = serviceSignals();
        signal_fd_ = UniqueFd(::signalfd(-1, &signals, SFD_NONBLOCK | SFD_CLOEXEC));
        if (!signal_fd_)
            throw StartupError(ExitCode::Failure, "cannot create a signalfd: " +
                                                      std::system_category().message(errno));
        server_->watch(signal_fd_.get(), [this] { onSignal(); });
    }
}

Service::~Service()
{
    shutdown();
}

ExitCode Service::run()
{
    started_ns_ = monotonicNowNs();
    last_push_change_ns_ = started_ns_;
    last_pushed_ = ring_->pushed();
    const int rc = source_->start(*ring_);
    if (rc < 0) {
        const std::string reason = source_->status().last_error;
        throw StartupError(ExitCode::Source,
                           "cannot start the frame source: " +
                               (reason.empty() ? std::system_category().message(-rc) : reason));
    }
    running_ = true;
    worker_->start();
    last_tick_ns_.store(monotonicNowNs(), std::memory_order_release);
    watchdog_pinger_.start();
    spdlog::info("stereod {} listening on {}", serviceVersion(), config_.socket.path);

    // READY=1 follows from onTick() once the first pair has arrived.

    ExitCode code = ExitCode::Ok;
    try {
        server_->run();
    } catch (const SocketError& e) {
        spdlog::critical("the event loop failed: {}", e.what());
        code = ExitCode::Failure;
    }
    shutdown();
    return code;
}

void Service::requestStop() noexcept
{
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = ::write(stop_fd_.get(), &one, sizeof one);
}

void Service::onStopRequest()
{
    uint64_t value = 0;
    [[maybe_unused]] const ssize_t got = ::read(stop_fd_.get(), &value, sizeof value);
    if (stop_requested_ns_ == 0)
        stop_requested_ns_ = monotonicNowNs();
    stop_seen_.store(true, std::memory_order_release);
    server_->requestStop();
}

void Service::shutdown() noexcept
{
    stop_seen_.store(true, std::memory_order_release);
    watchdog_pinger_.stop();
    if (running_)
        notifier_.stopping();
    // The socket first, so that clients see the service gone at once (connections
    // closed, file removed); then the source (no new pairs), the ring (wakes the worker
    // out of pop(); queued pairs are dropped) and the worker, which finishes the pair in
    // hand if it can within the stop deadline.
    server_.reset();
    if (source_)
        source_->stop();
    if (ring_)
        ring_->stop();
    if (worker_ && running_) {
        const int64_t since_ns = stop_requested_ns_ != 0 ? stop_requested_ns_ : monotonicNowNs();
        const int64_t deadline_ns = since_ns + options_.stop_timeout_ms * 1'000'000;
        while (!worker_->finished() && monotonicNowNs() < deadline_ns)
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
        if (!worker_->finished()) {
            worker_abandoned_ = true;
            const int64_t busy_since_ns = worker_->busySinceNs();
            spdlog::warn("stopping without the worker: it has been on one pair for {:.0f} ms, "
                         "longer than the {} ms a stop may wait",
                         busy_since_ns != 0
                             ? static_cast<double>(monotonicNowNs() - busy_since_ns) / 1e6
                             : 0.0,
                         options_.stop_timeout_ms);
        }
    }
    // Not abandoned: returns at once. Abandoned (a second call, from the destructor):
    // the objects the worker uses must outlive it, so this waits for the pair in hand.
    if (worker_ && (!worker_abandoned_ || !running_))
        worker_->join();
    if (running_)
        spdlog::info("stopped");
    running_ = false;
}

void Service::onSignal()
{
    signalfd_siginfo info{};
    while (::read(signal_fd_.get(), &info, sizeof info) == static_cast<ssize_t>(sizeof info)) {
        const auto signal_number = static_cast<int>(info.ssi_signo);
        if (signal_number == SIGHUP) {
            spdlog::info("SIGHUP: reloading {}", options_.config_path.empty()
                                                     ? std::string("(no configuration file)")
                                                     : options_.config_path);
            reloadConfig();
        } else {
            spdlog::info("{}: stopping", signal_number == SIGINT ? "SIGINT" : "SIGTERM");
            if (stop_requested_ns_ == 0)
                stop_requested_ns_ = monotonicNowNs();
            stop_seen_.store(true, std::memory_order_release);
            server_->requestStop();
        }
    }
}

SourceHealth Service::sourceHealth(int64_t now_ns)
{
    SourceHealth health;
    const SourceStatus status = source_->status();
    const uint64_t pushed = ring_->pushed();
    if (pushed != last_pushed_) {
        last_pushed_ = pushed;
        last_push_change_ns_ = now_ns;
    }
    switch (status.state) {
    case SourceState::Failed:
    case SourceState::Stalled:
    case SourceState::Finished:
        health.down = true;
        health.message = std::string("the ") + (status.kind.empty() ? "source" : status.kind) +
                         " source is " + toString(status.state);
        if (!status.last_error.empty())
            health.message += ": " + status.last_error;
        return health;
    case SourceState::Stopped:
        if (running_) {
            health.down = true;
            health.message = "the source stopped";
            return health;
        }
        break;
    default:
        break;
    }
    const double silent_ms = static_cast<double>(now_ns - last_push_change_ns_) / 1e6;
    if (running_ && silent_ms > config_.source.stall_timeout_ms) {
        health.down = true;
        std::array<char, 160> text{};
        std::snprintf(text.data(), text.size(),
                      "no pair from the source for %.0f ms (source.stall_timeout_ms: %.0f)",
                      silent_ms, config_.source.stall_timeout_ms);
        health.message = text.data();
    }
    return health;
}

void Service::describe(Json& status, const PublishedFrame* latest, const SourceHealth& health,
                       int64_t now_ns)
{
    status["uptime_s"] = roundTo(static_cast<double>(now_ns - started_ns_) / 1e9, 1);
    status["state"] = health.down         ? "source_down"
                      : !calibration_     ? "uncalibrated"
                      : latest != nullptr ? "running"
                                          : "starting";

    const SourceStatus source_status = source_->status();
    Json source = Json::object();
    source["kind"] = source_status.kind;
    source["state"] = toString(source_status.state);
    source["last_error"] = source_status.last_error;
    if (health.down)
        source["down_reason"] = health.message;
    Json cameras = Json::array();
    for (const CameraStatus& camera : source_status.cameras) {
        cameras.push_back({{"name", camera.name},
                           {"state", toString(camera.state)},
                           {"fps", roundTo(camera.fps, 2)},
                           {"frames", camera.frames},
                           {"dropped", camera.dropped},
                           {"bad_frames", camera.bad_frames},
                           {"last_bad_frame", camera.last_bad_frame},
                           {"unpaired", camera.unpaired},
                           {"last_error", camera.last_error}});
    }
    source["cameras"] = std::move(cameras);
    source["pairs"] = source_status.pairs;
    source["ring_dropped"] = ring_->dropped();
    source["unpaired_dropped"] = source_status.unpaired_dropped;
    source["skew_ms"] = {{"mean", roundTo(source_status.skew_mean_ms, 3)},
                         {"p99", roundTo(source_status.skew_p99_ms, 3)},
                         {"max", roundTo(source_status.skew_max_ms, 3)}};
    source["clock_offset"] = {{"detected", source_status.clock_offset_detected},
                              {"estimate_ms", roundTo(source_status.clock_offset_ms, 3)}};
    source["warnings"] = source_status.warnings;
    status["source"] = std::move(source);

    PipelineStats stats;
    stats.range = initial_range_;
    std::string matcher = initial_matcher_;
    double fps = 0.0;
    if (latest != nullptr) {
        stats = latest->stats;
        matcher = stats.matcher.data();
        // A rate measured over frames that stopped coming is no rate now.
        const double quiet_s = static_cast<double>(now_ns - latest->published_ns) / 1e9;
        fps = quiet_s < std::max(2.0, stats.fps > 0.0 ? 3.0 / stats.fps : 2.0) ? stats.fps : 0.0;
    }
    Json pipeline = Json::object();
    pipeline["frames"] = stats.frames;
    pipeline["fps"] = roundTo(fps, 2);
    pipeline["matcher"] = matcher;
    pipeline["num_disparities"] = stats.range.num_disparities;
    pipeline["min_disparity"] = stats.range.min_disparity;
    pipeline["closest_depth_m"] = roundTo(stats.range.closest_depth_m, 3);
    pipeline["disparity_range_capped"] = stats.range.capped;
    pipeline["bad_frames"] = stats.bad_frames;
    pipeline["out_of_sync"] = stats.out_of_sync;
    const StageTimings& stage = stats.stage_mean_ms;
    pipeline["stage_ms"] = {
        {"rectify", roundTo(stage.rectify_ms, 3)}, {"match", roundTo(stage.match_ms, 3)},
        {"depth", roundTo(stage.depth_ms, 3)},     {"nearest", roundTo(stage.nearest_ms, 3)},
        {"cloud", roundTo(stage.cloud_ms, 3)},     {"publish", roundTo(stats.publish_mean_ms, 3)}};
    // From the capture stamp of a pair to the publication of its result (the last 256 pairs).
    pipeline["latency_ms"] = {{"p50", roundTo(stats.latency_p50_ms, 3)},
                              {"p99", roundTo(stats.latency_p99_ms, 3)}};
    status["pipeline"] = std::move(pipeline);

    Json rig_health = Json::object();
    if (!health_) {
        rig_health["state"] = healthStateName(HealthState::Unknown);
        rig_health["reason"] = "uncalibrated";
    } else {
        const HealthReport report = health_->report();
        rig_health["state"] = healthStateName(report.state);
        if (!report.reason.empty())
            rig_health["reason"] = report.reason;
        rig_health["row_offset_px"] = roundTo(report.row_offset_px, 3);
        rig_health["row_offset_p90_px"] = roundTo(report.row_offset_p90_px, 3);
        rig_health["matches"] = report.matches;
        rig_health["trend_px_per_min"] = roundTo(report.trend_px_per_min, 4);
        rig_health["checks"] = report.checks;
        rig_health["check_ms"] = roundTo(report.check_ms, 2);
        rig_health["interval_s"] = config_.calibration_health.interval_s;
        if (report.checked_stamp_ns > 0)
            rig_health["checked_age_s"] =
                roundTo(static_cast<double>(monotonicNowNs() - report.checked_stamp_ns) / 1e9, 2);
    }
    status["calibration_health"] = std::move(rig_health);

    Json calibration = Json::object();
    calibration["path"] = options_.calibration_path;
    if (!calibration_) {
        calibration["kind"] = "none";
        status["calibration"] = std::move(calibration);
        return;
    }
    const RectifiedGeometry& geometry = calibration_->rectified;
    calibration["kind"] =
        calibration_->kind == StereoCalibration::Kind::Full ? "full" : "rectified";
    calibration["focal_px"] = geometry.focal_px;
    calibration["baseline_m"] = geometry.baseline_m;
    calibration["doffs_px"] = geometry.doffs_px;
    calibration["cx_px"] = geometry.cx_px;
    calibration["cy_px"] = geometry.cy_px;
    calibration["width"] = geometry.image_size.width;
    calibration["height"] = geometry.image_size.height;
    if (calibration_->rms_px)
        calibration["rms_px"] = *calibration_->rms_px;
    if (calibration_->epipolar_error_px)
        calibration["epipolar_error_px"] = *calibration_->epipolar_error_px;
    status["calibration"] = std::move(calibration);
}

ReloadOutcome Service::loadAndApply()
{
    ReloadOutcome outcome;
    if (options_.config_path.empty()) {
        outcome.ok = false;
        outcome.error = ErrorCode::NotAvailable;
        outcome.message = "the service runs on built-in defaults (started without --config): "
                          "there is no configuration file to re-read";
        return outcome;
    }
    ServiceConfig proposed;
    try {
        proposed = loadConfig(options_.config_path, options_.overrides);
    } catch (const std::exception& e) {
        outcome.ok = false;
        outcome.error = ErrorCode::InvalidConfig;
        outcome.message = e.what();
        return outcome;
    }
    // Everything the worker will check, checked here: a file the worker would refuse is
    // refused now, as a whole, rather than answered `ok` and silently not applied.
    if (calibration_) {
        std::string problem =
            processingProblem(proposed.processing, *calibration_, options_.config_path);
        if (!problem.empty()) {
            outcome.ok = false;
            outcome.error = ErrorCode::InvalidConfig;
            outcome.message = std::move(problem);
            return outcome;
        }
    }
    ConfigChange change = diffConfig(config_, proposed);
    // restart_needed is a subset of changed: anything more is a live change. Live
    // settings are handed over as a whole (unchanged values stay what they were).
    if (change.changed.size() > change.restart_needed.size()) {
        worker_->updateSettings(proposed.processing);
        server_->setPublishConfig(proposed.publish);
        applyLogLevel(proposed.log_level);
        if (health_) {
            health_->setInterval(proposed.calibration_health.interval_s);
            worker_->setWithholdWhenFailed(proposed.calibration_health.withhold_when_failed);
        }
        config_.calibration_health = proposed.calibration_health;
        worker_->updateZones(proposed.zones);
        config_.zones = proposed.zones;
        config_.processing = proposed.processing;
        config_.publish = proposed.publish;
        config_.log_level = proposed.log_level;
    }
    outcome.changed = std::move(change.changed);
    outcome.restart_needed = std::move(change.restart_needed);
    return outcome;
}

ReloadOutcome Service::reload()
{
    return reloadConfig();
}

ReloadOutcome Service::reloadConfig()
{
    notifier_.reloading();
    ReloadOutcome outcome = loadAndApply();
    if (!outcome.ok) {
        spdlog::error("reload refused, the running configuration stays in force: {}",
                      outcome.message);
        last_error_ =
            "reload refused, the running configuration stays in force: " + outcome.message;
    } else {
        spdlog::info("configuration reloaded from {}: changed: [{}]; need a restart: [{}]",
                     options_.config_path, fmt::join(outcome.changed, ", "),
                     fmt::join(outcome.restart_needed, ", "));
        last_error_.clear();
    }
    if (running_) {
        const int64_t now_ns = monotonicNowNs();
        notifier_.reloaded(statusText(now_ns, sourceHealth(now_ns)));
    }
    return outcome;
}

std::string Service::statusText(int64_t now_ns, const SourceHealth& health)
{
    const PublishedFrame* latest = publisher_->latest();
    const SourceStatus source_status = source_->status();
    StatusFacts facts;
    facts.source_down = health.down;
    facts.down_reason = health.message;
    facts.uncalibrated = !calibration_.has_value();
    facts.source = &source_status;
    facts.clients = server_ ? server_->counters().connected : 0;
    if (latest != nullptr) {
        facts.have_frame = true;
        facts.frame = latest->result.frame;
        // A rate measured over frames that stopped coming is no rate now.
        const double quiet_s = static_cast<double>(now_ns - latest->published_ns) / 1e9;
        const double fps = latest->stats.fps;
        facts.fps = quiet_s < std::max(2.0, fps > 0.0 ? 3.0 / fps : 2.0) ? fps : 0.0;
    }
    facts.last_error = !last_error_.empty() ? std::string_view(last_error_)
                                            : std::string_view(source_status.last_error);
    return statusLine(facts);
}

bool Service::alive(int64_t now_ns) const noexcept
{
    const int64_t interval_ns = notifier_.watchdogIntervalNs();
    return now_ns - last_tick_ns_.load(std::memory_order_acquire) < interval_ns &&
           workerMakesProgress(worker_->busySinceNs(), now_ns, interval_ns);
}

void Service::onTick(int64_t now_ns)
{
    last_tick_ns_.store(now_ns, std::memory_order_release);
    if (running_ && source_counters_.due(now_ns)) {
        for (const SourceCounterWatch::Report& report :
             source_counters_.look(source_->status(), now_ns))
            spdlog::log(report.bad_frames ? spdlog::level::warn : spdlog::level::info, "{}",
                        report.text);
    }
    if (!running_ || !notifier_.enabled())
        return;
    // READY=1 once the socket listens (it has since the constructor) and the first pair
    // has arrived, or once the source is found down (failed, or silent for
    // source.stall_timeout_ms): the service then runs and says why there is no reading.
    if (!notifier_.readySent()) {
        if (ring_->pushed() > 0) {
            notifier_.ready(statusText(now_ns, sourceHealth(now_ns)));
        } else {
            const SourceHealth health = sourceHealth(now_ns);
            if (health.down)
                notifier_.ready(statusText(now_ns, health));
        }
    }
    if (notifier_.statusDue(now_ns))
        notifier_.status(statusText(now_ns, sourceHealth(now_ns)), now_ns);
}

std::string checkConfiguration(const std::string& path)
{
    const ServiceConfig config = loadConfig(path);
    std::string calibration_path = config.calibration_path;
    if (calibration_path.empty() && config.source.kind == SourceKind::Replay) {
        // A recording's own calibration, as start-up would find it.
        std::error_code error;
        const std::filesystem::path in_recording =
            std::filesystem::path(config.source.replay.path) / kCalibrationName;
        if (std::filesystem::is_directory(config.source.replay.path, error) &&
            std::filesystem::is_regular_file(in_recording, error))
            calibration_path = in_recording.string();
    }
    if (calibration_path.empty())
        return {};
    std::string text;
    const StereoCalibration calibration = loadCalibrationFile(calibration_path, text);
    const std::string problem = processingProblem(config.processing, calibration, path);
    if (!problem.empty())
        throw StartupError(ExitCode::InvalidConfig,
                           problem + " (calibration " + calibration_path + ")");
    return calibration_path;
}

std::unique_ptr<Service> launchService(const LaunchRequest& request, bool handle_signals)
{
    ServiceConfig config;
    try {
        if (!request.config_path.empty()) {
            config = loadConfig(request.config_path, request.overrides);
        } else {
            config = defaultConfig();
            applyOverrides(config, request.overrides);
            validateConfig(config);
        }
    } catch (const ConfigError& e) {
        throw StartupError(exitCodeFor(e), std::string("invalid configuration:\n") + e.what());
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::InvalidConfig,
                           std::string("cannot read the configuration: ") + e.what());
    }
    applyLogLevel(config.log_level);

    std::unique_ptr<FrameSource> source;
    std::string source_name;           // for messages: the recording or the cameras
    std::string recording_calibration; // a replay's own calibration.yaml, if any
    // A replayed bag's camera_info pair, if any: the calibration when none is given.
    std::optional<std::pair<ros2::CameraInfo, ros2::CameraInfo>> bag_camera_info;
    if (config.source.kind == SourceKind::Replay) {
        ReplayOptions replay;
        replay.path = config.source.replay.path;
        replay.left_topic = config.source.replay.left_topic;
        replay.right_topic = config.source.replay.right_topic;
        replay.pacing = config.source.replay.pacing == ReplayPacing::Lockstep
                            ? ReplayOptions::Pacing::Lockstep
                            : ReplayOptions::Pacing::Paced;
        replay.loop = config.source.replay.loop;
        replay.fps = config.source.replay.fps;
        // Pairs in flight: the ring, the one the worker holds, the one being filled.
        replay.pool_pairs = static_cast<std::size_t>(config.source.ring_capacity) + 2;
        auto replay_source = std::make_unique<ReplaySource>(replay);
        const SourceStatus source_status = replay_source->status();
        if (source_status.state == SourceState::Failed || replay_source->frameSize().empty())
            throw StartupError(ExitCode::Source,
                               "cannot replay " + replay.path + ": " + source_status.last_error);
        recording_calibration = replay_source->calibrationPath();
        bag_camera_info = replay_source->bagCameraInfo();
        source_name = replay.path;
        source = std::move(replay_source);
    } else {
        // The cameras open in run(): a camera that cannot start is a Source error there.
        try {
            source = makeCameraSource(config.source);
        } catch (const std::exception& e) {
            throw StartupError(ExitCode::Source, e.what());
        }
        source_name = config.source.kind == SourceKind::V4l2
                          ? config.source.cameras.left + " and " + config.source.cameras.right
                          : config.source.cameras.device;
    }

    std::string calibration_path = config.calibration_path;
    if (calibration_path.empty())
        calibration_path = recording_calibration;
    // No calibration anywhere: a robot's first start. The service runs uncalibrated and
    // serves raw frames, so that the rig can be calibrated from it.
    std::optional<StereoCalibration> calibration;
    std::string calibration_text;
    if (!calibration_path.empty()) {
        calibration = loadCalibrationFile(calibration_path, calibration_text);
        spdlog::info(
            "calibration {}: {}, {}x{}, focal {:.1f} px, baseline {:.4f} m", calibration_path,
            calibration->kind == StereoCalibration::Kind::Full ? "full" : "rectified-only",
            calibration->rectified.image_size.width, calibration->rectified.image_size.height,
            calibration->rectified.focal_px, calibration->rectified.baseline_m);
    } else if (bag_camera_info) {
        const std::string origin = source_name + " (camera_info)";
        try {
            calibration =
                calibrationFromRosCameraInfo(rosCameraInfoFromMessage(bag_camera_info->first),
                                             rosCameraInfoFromMessage(bag_camera_info->second),
                                             origin + " left", origin + " right");
            calibration_text = formatCalibration(*calibration, origin);
        } catch (const std::exception& e) {
            throw StartupError(ExitCode::Calibration, e.what());
        }
        spdlog::info("calibration from {}: focal {:.1f} px, baseline {:.4f} m", origin,
                     calibration->rectified.focal_px, calibration->rectified.baseline_m);
    } else {
        spdlog::warn("no calibration given (--calib, `calibration` in the configuration) and "
                     "none in {}",
                     source_name);
    }

    ServiceOptions options;
    options.config_path = request.config_path;
    options.overrides = request.overrides;
    options.calibration_path = calibration_path;
    options.calibration_text = std::move(calibration_text);
    options.handle_signals = handle_signals;
    options.notify_systemd = true;
    return std::make_unique<Service>(std::move(config), std::move(source), std::move(calibration),
                                     std::move(options));
}

} // namespace stereod
