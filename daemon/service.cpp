#include "daemon/service.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string_view>
#include <system_error>

#include <fmt/format.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/eventfd.h>
#include <sys/signalfd.h>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "daemon/json_writer.hpp"
#include "replay/replay_source.hpp"

namespace stereod {

namespace {

constexpr int64_t kStatusIntervalNs = 2'000'000'000;

sigset_t serviceSignals()
{
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGTERM);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGHUP);
    return signals;
}

// A configuration whose only problems are the replay path, or only the calibration
// path, is a source or a calibration problem for the exit code: `stereod --replay DIR`
// with a DIR that does not exist is a source problem, whatever layer finds it.
ExitCode classifyConfigError(const ConfigError& error)
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

void applyLogLevel(const std::string& level)
{
    spdlog::set_level(spdlog::level::from_str(level));
}

} // namespace

void blockServiceSignals()
{
    const sigset_t signals = serviceSignals();
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);
}

Service::Service(ServiceConfig config, std::unique_ptr<FrameSource> source,
                 StereoCalibration calibration, ServiceOptions options)
    : config_(std::move(config)), options_(std::move(options)), source_(std::move(source)),
      calibration_(std::move(calibration))
{
    const std::string calibration_origin = options_.calibration_path.empty()
                                               ? std::string("the calibration")
                                               : options_.calibration_path;
    try {
        checkFrameSize(calibration_, source_->frameSize(), calibration_origin);
        processor_ = std::make_unique<StereoProcessor>(calibration_, config_.processing);
    } catch (const CalibrationError& e) {
        throw StartupError(ExitCode::Calibration, e.what());
    } catch (const std::invalid_argument& e) {
        throw StartupError(ExitCode::InvalidConfig,
                           std::string("processing settings refused: ") + e.what());
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::Calibration, "cannot set up the stereo chain with " +
                                                      calibration_origin + ": " + e.what());
    }
    initial_range_ = processor_->disparityRange();
    initial_matcher_ = processor_->matcherName();
    logDisparityRange(initial_range_, config_.processing.matcher, initial_matcher_);

    ring_ = std::make_unique<PairRing>(static_cast<std::size_t>(config_.source.ring_capacity));
    publisher_ = std::make_unique<Publisher>();
    worker_ =
        std::make_unique<Worker>(*ring_, *publisher_, *processor_, config_.source.max_skew_ms);

    ServerOptions server_options;
    server_options.socket = config_.socket;
    server_options.publish = config_.publish;
    server_options.geometry = calibration_.rectified;
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
    spdlog::info("stereod {} listening on {}", serviceVersion(), config_.socket.path);

    if (options_.notify_systemd) {
        uint64_t watchdog_usec = 0;
        if (sd_watchdog_enabled(0, &watchdog_usec) > 0)
            watchdog_interval_ns_ = watchdog_usec * 1000;
        sd_notify(0, "READY=1\nSTATUS=running: waiting for the first frame");
    }

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
    server_->requestStop();
}

void Service::shutdown() noexcept
{
    if (options_.notify_systemd && running_)
        sd_notify(0, "STOPPING=1\nSTATUS=stopping");
    // The socket first, so that clients see the service gone at once (connections
    // closed, file removed); then the source (no new pairs), the ring (wakes the worker
    // out of pop()) and the worker, which finishes the pair in hand.
    server_.reset();
    if (source_)
        source_->stop();
    if (ring_)
        ring_->stop();
    if (worker_)
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
    status["state"] = health.down ? "source_down" : (latest != nullptr ? "running" : "starting");

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
                           {"last_error", camera.last_error}});
    }
    source["cameras"] = std::move(cameras);
    source["pairs"] = source_status.pairs;
    source["ring_dropped"] = ring_->dropped();
    source["unpaired_dropped"] = source_status.unpaired_dropped;
    source["skew_ms"] = {{"mean", roundTo(source_status.skew_mean_ms, 3)},
                         {"p99", roundTo(source_status.skew_p99_ms, 3)},
                         {"max", roundTo(source_status.skew_max_ms, 3)}};
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
    status["pipeline"] = std::move(pipeline);

    const RectifiedGeometry& geometry = calibration_.rectified;
    Json calibration = Json::object();
    calibration["path"] = options_.calibration_path;
    calibration["kind"] = calibration_.kind == StereoCalibration::Kind::Full ? "full" : "rectified";
    calibration["focal_px"] = geometry.focal_px;
    calibration["baseline_m"] = geometry.baseline_m;
    calibration["doffs_px"] = geometry.doffs_px;
    calibration["cx_px"] = geometry.cx_px;
    calibration["cy_px"] = geometry.cy_px;
    calibration["width"] = geometry.image_size.width;
    calibration["height"] = geometry.image_size.height;
    if (calibration_.rms_px)
        calibration["rms_px"] = *calibration_.rms_px;
    if (calibration_.epipolar_error_px)
        calibration["epipolar_error_px"] = *calibration_.epipolar_error_px;
    status["calibration"] = std::move(calibration);
}

ReloadOutcome Service::reload()
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
    ConfigChange change = diffConfig(config_, proposed);
    // restart_needed is a subset of changed: anything more is a live change. Live
    // settings are handed over as a whole (unchanged values stay what they were).
    if (change.changed.size() > change.restart_needed.size()) {
        worker_->updateSettings(proposed.processing);
        server_->setPublishConfig(proposed.publish);
        applyLogLevel(proposed.log_level);
        config_.processing = proposed.processing;
        config_.publish = proposed.publish;
        config_.log_level = proposed.log_level;
    }
    outcome.changed = std::move(change.changed);
    outcome.restart_needed = std::move(change.restart_needed);
    return outcome;
}

ReloadOutcome Service::reloadConfig()
{
    ReloadOutcome outcome = reload();
    if (!outcome.ok) {
        spdlog::error("reload refused, the running configuration stays in force: {}",
                      outcome.message);
    } else {
        spdlog::info("configuration reloaded from {}: changed: [{}]; need a restart: [{}]",
                     options_.config_path, fmt::join(outcome.changed, ", "),
                     fmt::join(outcome.restart_needed, ", "));
    }
    return outcome;
}

void Service::onTick(int64_t now_ns)
{
    if (!options_.notify_systemd || !running_)
        return;
    if (watchdog_interval_ns_ > 0 &&
        now_ns - last_watchdog_ns_ >= static_cast<int64_t>(watchdog_interval_ns_ / 2)) {
        // Alive means the loop turns and the worker is not stuck inside one pair.
        const int64_t busy_since_ns = worker_->busySinceNs();
        if (busy_since_ns == 0 ||
            now_ns - busy_since_ns < static_cast<int64_t>(watchdog_interval_ns_)) {
            sd_notify(0, "WATCHDOG=1");
            last_watchdog_ns_ = now_ns;
        }
    }
    if (now_ns - last_status_ns_ >= kStatusIntervalNs) {
        last_status_ns_ = now_ns;
        const PublishedFrame* latest = publisher_->latest();
        const SourceHealth health = sourceHealth(now_ns);
        const ClientCounters clients = server_->counters();
        std::array<char, 200> text{};
        if (health.down) {
            std::snprintf(text.data(), text.size(), "STATUS=source down: %s; %llu clients",
                          health.message.c_str(),
                          static_cast<unsigned long long>(clients.connected));
        } else if (latest == nullptr) {
            std::snprintf(text.data(), text.size(), "STATUS=running: waiting for the first frame");
        } else {
            std::snprintf(text.data(), text.size(),
                          "STATUS=running: %.1f fps, frame %llu, %llu clients", latest->stats.fps,
                          static_cast<unsigned long long>(latest->result.frame),
                          static_cast<unsigned long long>(clients.connected));
        }
        sd_notify(0, text.data());
    }
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
        throw StartupError(classifyConfigError(e),
                           std::string("invalid configuration:\n") + e.what());
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::InvalidConfig,
                           std::string("cannot read the configuration: ") + e.what());
    }
    applyLogLevel(config.log_level);

    ReplayOptions replay;
    replay.path = config.source.replay.path;
    replay.pacing = config.source.replay.pacing == ReplayPacing::Lockstep
                        ? ReplayOptions::Pacing::Lockstep
                        : ReplayOptions::Pacing::Paced;
    replay.loop = config.source.replay.loop;
    replay.fps = config.source.replay.fps;
    // Pairs in flight: the ring, the one the worker holds, the one being filled.
    replay.pool_pairs = static_cast<std::size_t>(config.source.ring_capacity) + 2;
    auto source = std::make_unique<ReplaySource>(replay);
    const SourceStatus source_status = source->status();
    if (source_status.state == SourceState::Failed || source->frameSize().empty())
        throw StartupError(ExitCode::Source,
                           "cannot replay " + replay.path + ": " + source_status.last_error);

    std::string calibration_path = config.calibration_path;
    if (calibration_path.empty())
        calibration_path = source->calibrationPath();
    if (calibration_path.empty())
        throw StartupError(ExitCode::Calibration,
                           "no calibration: give --calib FILE, set `calibration` in the "
                           "configuration, or put calibration.yaml into " +
                               replay.path);
    StereoCalibration calibration;
    try {
        calibration = loadCalibration(calibration_path);
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::Calibration, e.what());
    }
    spdlog::info("calibration {}: {}, {}x{}, focal {:.1f} px, baseline {:.4f} m", calibration_path,
                 calibration.kind == StereoCalibration::Kind::Full ? "full" : "rectified-only",
                 calibration.rectified.image_size.width, calibration.rectified.image_size.height,
                 calibration.rectified.focal_px, calibration.rectified.baseline_m);

    ServiceOptions options;
    options.config_path = request.config_path;
    options.overrides = request.overrides;
    options.calibration_path = calibration_path;
    options.handle_signals = handle_signals;
    options.notify_systemd = true;
    return std::make_unique<Service>(std::move(config), std::move(source), std::move(calibration),
                                     std::move(options));
}

} // namespace stereod
