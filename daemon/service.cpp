#include "daemon/service.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <string_view>
#include <system_error>
#include <thread>

#include <fmt/format.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include "base/descriptor_budget.hpp"
#include "base/system_error.hpp"

namespace stereod {

namespace {

void applyLogLevel(const std::string& level)
{
    spdlog::set_level(spdlog::level::from_str(level));
}

// The worker's frame rate now: a rate measured over frames that stopped coming is no rate.
double currentFps(const PublishedFrame& latest, int64_t now_ns)
{
    const double quiet_s = static_cast<double>(now_ns - latest.published_ns) / 1e9;
    const double fps = latest.stats.fps;
    return quiet_s < std::max(2.0, fps > 0.0 ? 3.0 / fps : 2.0) ? fps : 0.0;
}

} // namespace

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

// A configuration whose only problems are the replay path, or only the calibration
// path, is a source or a calibration problem for the exit code: `stereod --replay DIR`
// with a DIR that does not exist is a source problem, whatever layer finds it.
ExitCode exitCodeFor(const ConfigError& error)
{
    if (error.onlyAbout("source.replay.path"))
        return ExitCode::Source;
    if (error.onlyAbout("calibration"))
        return ExitCode::Calibration;
    return ExitCode::InvalidConfig;
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
        // Not the calibration's fault as far as anything can tell (memory, a library's
        // failure): the calibration's exit code would send the user to the wrong file.
        throw StartupError(ExitCode::Failure, "cannot set up the stereo chain with " +
                                                  calibration_origin + ": " + e.what());
    }
    if (processor_) {
        initial_range_ = processor_->disparityRange();
        initial_matcher_ = processor_->matcherName();
        initial_max_output_depth_m_ = processor_->maxOutputDepth();
        logDisparityRange(initial_range_, config_.processing.matcher, initial_matcher_);
        logRegionLeftEdge(*processor_);
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
        health_ = std::make_unique<CalibrationHealthMonitor>(calibration_->rectified,
                                                             config_.calibration_health.interval_s);
        worker_->setHealthMonitor(health_.get());
        worker_->setWithholdWhenFailed(config_.calibration_health.withhold_when_failed);
    }
    worker_->updateZones(config_.zones);
    worker_->setTakesEveryPair(source_ && source_->keepsEveryPair());

    budgetDescriptors();
    ServerOptions server_options;
    server_options.socket = config_.socket;
    server_options.socket.max_clients = socket_max_clients_;
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
    startLiveView();
    startRos2();
    if (!observers_.empty())
        server_->setPublishObserver(&observers_);

    stop_fd_ = UniqueFd(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
    if (!stop_fd_)
        throw StartupError(ExitCode::Failure, "cannot create an eventfd: " + errnoText(errno));
    server_->watch(stop_fd_.get(), [this] { onStopRequest(); });

    reload_fd_ = UniqueFd(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
    if (!reload_fd_)
        throw StartupError(ExitCode::Failure, "cannot create an eventfd: " + errnoText(errno));
    server_->watch(reload_fd_.get(), [this] { onReloadRequest(); });
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
        throw StartupError(ExitCode::Source, "cannot start the frame source: " +
                                                 (reason.empty() ? errnoText(-rc) : reason));
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
    markStopTaken();
    server_->requestStop();
}

void Service::markStopTaken() noexcept
{
    {
        std::lock_guard lock(stop_taken_mutex_);
        stop_taken_ = true;
    }
    stop_taken_changed_.notify_all();
}

bool Service::waitStopTaken(int64_t timeout_ms)
{
    std::unique_lock lock(stop_taken_mutex_);
    return stop_taken_changed_.wait_for(lock, std::chrono::milliseconds(timeout_ms),
                                        [this] { return stop_taken_; });
}

void Service::requestReload() noexcept
{
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = ::write(reload_fd_.get(), &one, sizeof one);
}

void Service::onReloadRequest()
{
    uint64_t value = 0;
    [[maybe_unused]] const ssize_t got = ::read(reload_fd_.get(), &value, sizeof value);
    spdlog::info("SIGHUP: reloading {}", options_.config_path.empty()
                                             ? std::string("(no configuration file)")
                                             : options_.config_path);
    reloadConfig();
}

void Service::shutdown() noexcept
{
    markStopTaken();
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
        if (!worker_->waitFinished(deadline_ns)) {
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

void Service::budgetDescriptors()
{
    // Descriptors the service opens while it runs besides its connections: replay files
    // and the decoders' pipe, a reload's files, the live view's own (its event loop,
    // acceptor and timer), the two spare descriptors, log files, systemd's socket.
    constexpr std::size_t kReserve = 32;
    // Sockets of the live view beyond its WebSocket clients: the page's HTTP requests and
    // handshakes in progress.
    constexpr std::size_t kLiveViewHttp = 16;
    const std::size_t limit = descriptorLimit();
    const std::size_t open = countOpenDescriptors();
    const std::size_t spare = limit > open + kReserve ? limit - open - kReserve : 0;
    const auto socket_wanted = static_cast<std::size_t>(std::max(config_.socket.max_clients, 1));
    const bool live = parseListenAddress(config_.live_view.listen).has_value();
    const std::size_t live_wanted =
        live ? static_cast<std::size_t>(config_.live_view.max_clients) + kLiveViewHttp : 0;
    // The socket's clients (the robot's own programs) come first, up to two thirds when
    // the live view wants the rest; each keeps at least a few.
    std::size_t socket_clients = socket_wanted;
    std::size_t live_connections = live_wanted;
    if (socket_wanted + live_wanted > spare) {
        socket_clients = std::clamp<std::size_t>(live ? spare * 2 / 3 : spare, 4, socket_wanted);
        live_connections =
            live ? std::clamp<std::size_t>(spare - std::min(spare, socket_clients), 2, live_wanted)
                 : 0;
        spdlog::warn("descriptors: RLIMIT_NOFILE is {} with {} open and {} kept for the service: "
                     "socket clients at most {} (socket.max_clients {}){}",
                     limit, open, kReserve, socket_clients, socket_wanted,
                     live ? fmt::format(", live view connections at most {} (of {})",
                                        live_connections, live_wanted)
                          : std::string());
    }
    socket_max_clients_ = static_cast<int>(socket_clients);
    live_view_connections_ = live_connections;
}

void Service::startLiveView()
{
    const auto address = parseListenAddress(config_.live_view.listen); // checked by the config
    if (!address)
        return;
    live_view::LiveViewSettings settings;
    settings.host = address->host;
    settings.port = address->port;
    settings.allowed_origins = config_.live_view.allowed_origins;
    settings.max_connections = live_view_connections_;
    settings.max_clients = std::min<std::size_t>(
        static_cast<std::size_t>(config_.live_view.max_clients), live_view_connections_);
    settings.points_step = config_.live_view.points_step;
    settings.max_rate_hz = config_.live_view.max_rate_hz;
    const auto& rates = config_.live_view.rate_hz;
    settings.rate_hz[live_view::kLeftImage] = rates.image;
    settings.rate_hz[live_view::kDepth] = rates.depth;
    settings.rate_hz[live_view::kDisparity] = rates.disparity;
    settings.rate_hz[live_view::kConfidence] = rates.confidence;
    settings.rate_hz[live_view::kPoints] = rates.points;
    settings.rate_hz[live_view::kLeftInfo] = rates.camera_info;
    settings.rate_hz[live_view::kRightInfo] = rates.camera_info;
    settings.rate_hz[live_view::kNearest] = rates.nearest;
    settings.rate_hz[live_view::kZones] = rates.nearest; // the zones come with the reading
    settings.web_root = options_.live_view_web_root;
    live_view_ = std::make_unique<live_view::LiveView>(
        settings, calibration_ ? calibration_->rectified : RectifiedGeometry{});
    if (const std::string error = live_view_->start(); !error.empty()) {
        spdlog::error("live view: cannot listen on {}: {}; running without the live view "
                      "(live_view.listen, --live-view)",
                      config_.live_view.listen, error);
        return;
    }
    observers_.add(*live_view_);
    const std::string bound = live_view_->status().listen;
    // The address with the token is given only over the socket (`view`): logs are read
    // more widely than the socket may be used.
    spdlog::info("live view listening on {}, up to {} clients; `stereoctl view` prints its "
                 "address with the token",
                 bound, settings.max_clients);
    if (!isLoopbackHost(address->host))
        spdlog::warn("live view: {} is reached from beyond this machine: whoever on the network "
                     "has the token sees the cameras, unencrypted. Keep the default "
                     "127.0.0.1 and tunnel (ssh -L), docs/live-view.md",
                     bound);
}

LiveViewLinks Service::liveViewLinks()
{
    LiveViewLinks links;
    StatusLiveView status;
    if (live_view_)
        status = live_view_->status();
    else
        status.listen = config_.live_view.listen; // "off"
    links.listening = status.listening;
    links.listen = status.listen;
    links.error = status.error;
    if (!links.listening)
        return links;
    // `view` is asked on this machine (the socket is local): a wildcard address is
    // reached at loopback.
    std::string host = parseListenAddress(config_.live_view.listen)->host;
    if (host == "0.0.0.0")
        host = "127.0.0.1";
    else if (host == "::")
        host = "::1";
    const std::string authority = formatListenAddress(host, live_view_->port());
    links.page = "http://" + authority + "/?token=" + live_view_->token();
    links.websocket = "ws://" + authority + "/?token=" + live_view_->token();
    return links;
}

void Service::startRos2()
{
    if (!config_.ros2.enabled)
        return;
    ros2::Ros2Settings settings;
    settings.ns = config_.ros2.ns;
    settings.points_step = config_.ros2.points_step;
    settings.max_rate_hz = config_.ros2.max_rate_hz;
    std::string error;
    try {
        settings.discovery = ros2::discoveryFromEnvironment(config_.ros2.localhost_only);
    } catch (const std::invalid_argument& e) {
        error = e.what();
    }
    ros2_ = std::make_unique<ros2::Ros2Publisher>(
        settings, calibration_ ? calibration_->rectified : RectifiedGeometry{},
        config_.processing.nearest, config_.zones.camera_pose);
    if (error.empty())
        error = ros2_->start();
    if (!error.empty()) {
        spdlog::error("ros2: cannot publish: {}; running without ROS 2 (ros2.enabled)", error);
        return;
    }
    ros2_observer_ = std::make_unique<Ros2Observer>(*ros2_);
    observers_.add(*ros2_observer_);
    spdlog::info("ros2: publishing under {} in DDS domain {}{}", settings.ns,
                 settings.discovery.domain_id,
                 settings.discovery.localhost_only ? " on 127.0.0.1 only" : "");
}

ServiceStatus Service::serviceStatus(const PublishedFrame* latest, const SourceHealth& health,
                                     int64_t now_ns)
{
    ServiceStatus status;
    if (live_view_)
        status.live_view = live_view_->status();
    else
        status.live_view.listen = config_.live_view.listen; // "off"
    status.ros2.enabled = config_.ros2.enabled;
    status.ros2.ns = config_.ros2.ns;
    if (ros2_) {
        const ros2::Ros2Counters c = ros2_->counters();
        status.ros2.publishing = c.publishing;
        status.ros2.error = c.error;
        status.ros2.domain_id = c.domain_id;
        status.ros2.localhost_only = c.localhost_only;
        status.ros2.readers = c.readers;
        status.ros2.frames = c.frames;
        status.ros2.frames_skipped = c.frames_skipped;
        status.ros2.messages = c.messages;
        status.ros2.write_errors = c.write_errors;
    }
    status.uptime_s = static_cast<double>(now_ns - started_ns_) / 1e9;
    status.state = health.down         ? "source_down"
                   : !calibration_     ? "uncalibrated"
                   : latest != nullptr ? "running"
                                       : "starting";

    const SourceStatus source_status = source_->status();
    StatusSource& source = status.source;
    source.kind = source_status.kind;
    source.state = toString(source_status.state);
    source.last_error = source_status.last_error;
    if (health.down)
        source.down_reason = health.message;
    for (const CameraStatus& camera : source_status.cameras) {
        source.cameras.push_back({camera.name, toString(camera.state), camera.fps, camera.frames,
                                  camera.dropped, camera.bad_frames, camera.last_bad_frame,
                                  camera.unpaired, camera.last_error});
    }
    source.pairs = source_status.pairs;
    source.ring_dropped = ring_->dropped();
    source.unpaired_dropped = source_status.unpaired_dropped;
    source.skew_mean_ms = source_status.skew_mean_ms;
    source.skew_p99_ms = source_status.skew_p99_ms;
    source.skew_max_ms = source_status.skew_max_ms;
    source.clock_offset_detected = source_status.clock_offset_detected;
    source.clock_offset_ms = source_status.clock_offset_ms;
    source.warnings = source_status.warnings;

    StatusPipeline& pipeline = status.pipeline;
    pipeline.range = initial_range_;
    pipeline.region = config_.processing.nearest.roi;
    pipeline.matcher = initial_matcher_;
    pipeline.max_output_depth_m = initial_max_output_depth_m_;
    if (latest != nullptr) {
        const PipelineStats& stats = latest->stats;
        pipeline.frames = stats.frames;
        pipeline.fps = currentFps(*latest, now_ns);
        pipeline.matcher = stats.matcher.view();
        pipeline.range = stats.range;
        if (stats.max_output_depth_m > 0.0)
            pipeline.max_output_depth_m = stats.max_output_depth_m;
        pipeline.bad_frames = stats.bad_frames;
        pipeline.out_of_sync = stats.out_of_sync;
        pipeline.stage_mean_ms = stats.stage_mean_ms;
        pipeline.zones_mean_ms = stats.zones_mean_ms;
        pipeline.publish_mean_ms = stats.publish_mean_ms;
        pipeline.latency_p50_ms = stats.latency_p50_ms;
        pipeline.latency_p99_ms = stats.latency_p99_ms;
    }

    StatusCalibrationHealth& rig_health = status.calibration_health;
    if (!health_) {
        rig_health.state = healthStateName(HealthState::Unknown);
        rig_health.reason = "uncalibrated";
    } else {
        const HealthReport report = health_->report();
        rig_health.state = healthStateName(report.state);
        rig_health.reason = report.reason;
        StatusHealthChecks& checks = rig_health.checks.emplace();
        checks.last_check = healthStateName(report.last_check_state);
        checks.state_changes = report.state_changes;
        checks.row_offset_px = report.row_offset_px;
        checks.row_offset_p90_px = report.row_offset_p90_px;
        checks.offset_px = report.offset_px;
        checks.roll_deg = report.roll_deg;
        checks.max_row_error_px = report.max_row_error_px;
        checks.matches = report.matches;
        checks.trend_px_per_min = report.trend_px_per_min;
        checks.checks = report.checks;
        checks.check_ms = report.check_ms;
        checks.interval_s = config_.calibration_health.interval_s;
        if (report.checked_stamp_ns > 0)
            checks.checked_age_s =
                static_cast<double>(monotonicNowNs() - report.checked_stamp_ns) / 1e9;
    }

    StatusCalibration& calibration = status.calibration;
    calibration.path = options_.calibration_path;
    if (calibration_) {
        calibration.kind =
            calibration_->kind == StereoCalibration::Kind::Full ? "full" : "rectified";
        calibration.geometry = calibration_->rectified;
        calibration.rms_px = calibration_->rms_px;
        calibration.epipolar_error_px = calibration_->epipolar_error_px;
    }
    return status;
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
    for (const LivePart part : change.live_parts)
        applyLivePart(part, proposed);
    outcome.changed = std::move(change.changed);
    outcome.restart_needed = std::move(change.restart_needed);
    return outcome;
}

// Each part is handed over as a whole: the keys of it that did not change keep their
// values, since `proposed` has them too. The parts not changed stay as they were, though
// `proposed` may differ there in keys that need a restart.
void Service::applyLivePart(LivePart part, const ServiceConfig& proposed)
{
    switch (part) {
    case LivePart::Processing:
        worker_->updateSettings(proposed.processing);
        if (ros2_)
            ros2_->setNearest(proposed.processing.nearest);
        config_.processing = proposed.processing;
        return;
    case LivePart::Publish:
        server_->setPublishConfig(proposed.publish);
        config_.publish = proposed.publish;
        return;
    case LivePart::LogLevel:
        applyLogLevel(proposed.log_level);
        config_.log_level = proposed.log_level;
        return;
    case LivePart::CalibrationHealth:
        if (health_) {
            health_->setInterval(proposed.calibration_health.interval_s);
            worker_->setWithholdWhenFailed(proposed.calibration_health.withhold_when_failed);
        }
        config_.calibration_health = proposed.calibration_health;
        return;
    case LivePart::Zones:
        worker_->updateZones(proposed.zones);
        config_.zones = proposed.zones;
        return;
    }
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
        facts.fps = currentFps(*latest, now_ns);
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

void Service::installCalibration(ArrivingCalibration arriving)
{
    const std::string& origin = arriving.origin;
    std::unique_ptr<StereoProcessor> processor;
    try {
        checkFrameSize(arriving.calibration, source_->frameSize(), origin);
        const std::string problem =
            processingProblem(config_.processing, arriving.calibration, options_.config_path);
        if (!problem.empty())
            throw std::invalid_argument(problem);
        processor = std::make_unique<StereoProcessor>(arriving.calibration, config_.processing);
    } catch (const std::exception& e) {
        spdlog::error("calibration from {} refused: {}; running uncalibrated", origin, e.what());
        last_error_ = "calibration from " + origin + " refused: " + e.what();
        return;
    }
    calibration_ = std::move(arriving.calibration);
    processor_ = std::move(processor);
    options_.calibration_path = origin;
    options_.calibration_text = formatCalibration(*calibration_, origin);
    initial_range_ = processor_->disparityRange();
    initial_matcher_ = processor_->matcherName();
    initial_max_output_depth_m_ = processor_->maxOutputDepth();
    spdlog::info("calibration from {}: {}x{}, focal {:.1f} px, baseline {:.4f} m; processing "
                 "starts",
                 origin, calibration_->rectified.image_size.width,
                 calibration_->rectified.image_size.height, calibration_->rectified.focal_px,
                 calibration_->rectified.baseline_m);
    logDisparityRange(initial_range_, config_.processing.matcher, initial_matcher_);
    logRegionLeftEdge(*processor_);
    health_ = std::make_unique<CalibrationHealthMonitor>(calibration_->rectified,
                                                         config_.calibration_health.interval_s);
    worker_->setWithholdWhenFailed(config_.calibration_health.withhold_when_failed);
    server_->setCalibration(calibration_->rectified, options_.calibration_path,
                            options_.calibration_text);
    if (live_view_)
        live_view_->setGeometry(calibration_->rectified);
    if (ros2_)
        ros2_->setGeometry(calibration_->rectified);
    // Last: from here the worker uses the chain and the monitor.
    worker_->installProcessor(*processor_, health_.get());
}

void Service::onTick(int64_t now_ns)
{
    last_tick_ns_.store(now_ns, std::memory_order_release);
    if (!calibration_ && options_.calibration_feed) {
        if (std::optional<ArrivingCalibration> arriving = options_.calibration_feed()) {
            options_.calibration_feed = nullptr;
            installCalibration(std::move(*arriving));
        }
    }
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

} // namespace stereod
