#include "daemon/service_launch.hpp"

#include <cerrno>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <system_error>
#include <utility>

#include <spdlog/spdlog.h>

#include "base/system_error.hpp"
#include "daemon/camera_source_factory.hpp"
#include "pipeline/calibration_formats.hpp"
#include "replay/recording.hpp"
#include "replay/replay_source.hpp"

namespace stereod {

namespace {

// The calibration file's text, read once: what is parsed is what `calibration` hands out.
// Throws CalibrationError naming the file and the errno text: the file named as the
// calibration is the user's to fix.
std::string readCalibrationText(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw CalibrationError(path + ": cannot open: " + errnoText(errno));
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad())
        throw CalibrationError(path + ": cannot read: " + errnoText(errno));
    return text.str();
}

// Loads the calibration at `path`: its text (for the `calibration` request) and the parsed
// calibration. Throws StartupError(Calibration) naming the file and the problem; any other
// failure (memory, a library's) is not the file's and gets the general exit code.
StereoCalibration loadCalibrationFile(const std::string& path, std::string& text)
{
    try {
        text = readCalibrationText(path);
        return parseCalibration(text, path);
    } catch (const CalibrationError& e) {
        throw StartupError(ExitCode::Calibration, e.what());
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::Failure,
                           "cannot load the calibration " + path + ": " + e.what());
    }
}

} // namespace

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

std::unique_ptr<Service> launchService(const LaunchRequest& request)
{
    ServiceConfig config;
    try {
        if (!request.config_path.empty()) {
            config = loadConfig(request.config_path, request.overrides);
        } else {
            config = defaultConfig();
            applyOverrides(config, request.overrides);
            validateConfig(config, request.overrides);
        }
    } catch (const ConfigError& e) {
        throw StartupError(exitCodeFor(e), std::string("invalid configuration:\n") + e.what());
    } catch (const std::exception& e) {
        throw StartupError(ExitCode::InvalidConfig,
                           std::string("cannot read the configuration: ") + e.what());
    }
    spdlog::set_level(spdlog::level::from_str(config.log_level));

    std::unique_ptr<FrameSource> source;
    ros2::Ros2ImageSource* ros2_source = nullptr; // `source`, when it is a ROS 2 one
    std::string source_name;                      // for messages: the recording or the cameras
    std::string recording_calibration;            // a replay's own calibration.yaml, if any
    // A replayed bag's camera_info pair, if any: the calibration when none is given.
    std::optional<std::pair<ros2::CameraInfo, ros2::CameraInfo>> bag_camera_info;
    if (config.source.kind == SourceKind::Replay) {
        ReplayOptions replay;
        replay.path = config.source.replay.path;
        replay.left_topic = config.source.replay.left_topic;
        replay.right_topic = config.source.replay.right_topic;
        replay.pacing = config.source.replay.pacing;
        replay.loop = config.source.replay.loop;
        replay.fps = config.source.replay.fps;
        replay.keep_colour = config.source.replay.colour != CameraColour::None;
        replay.keep_right_colour = config.source.replay.colour == CameraColour::Both;
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
    } else if (config.source.kind == SourceKind::Ros2) {
        // The topics are subscribed to in run(): a domain that cannot be joined is a
        // Source error there.
        try {
            auto made = makeRos2Source(config);
            ros2_source = made.get();
            source = std::move(made);
        } catch (const std::exception& e) {
            throw StartupError(ExitCode::Source, e.what());
        }
        source_name = config.source.ros2.left_topic + " and " + config.source.ros2.right_topic;
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
                calibrationFromCameraInfoMessages(bag_camera_info->first, bag_camera_info->second,
                                                  origin + " left", origin + " right");
            calibration_text = formatCalibration(*calibration, origin);
        } catch (const CalibrationError& e) {
            throw StartupError(ExitCode::Calibration, e.what());
        } catch (const std::exception& e) {
            throw StartupError(ExitCode::Failure,
                               "cannot take the calibration from " + origin + ": " + e.what());
        }
        spdlog::info("calibration from {}: focal {:.1f} px, baseline {:.4f} m", origin,
                     calibration->rectified.focal_px, calibration->rectified.baseline_m);
    } else if (ros2_source != nullptr) {
        spdlog::info("no calibration given (--calib, `calibration` in the configuration): "
                     "taking it from {} and {}; uncalibrated until both arrive",
                     leftCameraInfoTopic(config.source.ros2),
                     rightCameraInfoTopic(config.source.ros2));
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
    if (!calibration && ros2_source != nullptr) {
        // The source lives as long as the service that owns it and asks this.
        options.calibration_feed = [ros2_source]() -> std::optional<ArrivingCalibration> {
            std::optional<ros2::CameraInfoCalibration> taken = ros2_source->cameraInfoCalibration();
            if (!taken)
                return std::nullopt;
            return ArrivingCalibration{std::move(taken->calibration), std::move(taken->origin)};
        };
    }
    options.notify_systemd = true;
    // An installed stereod finds the page next to it (PREFIX/share/stereod/live_view);
    // one run from the build tree uses the source tree's.
    std::error_code ec;
    const std::filesystem::path installed =
        std::filesystem::read_symlink("/proc/self/exe", ec).parent_path().parent_path() /
        "share/stereod/live_view";
    if (!ec && std::filesystem::is_regular_file(installed / "index.html", ec))
        options.live_view_web_root = installed.string();
    return std::make_unique<Service>(std::move(config), std::move(source), std::move(calibration),
                                     std::move(options));
}

} // namespace stereod
