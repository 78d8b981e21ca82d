#include "config/key_table.hpp"

#include <algorithm>

#include "pipeline/zones.hpp"

namespace stereod::config_detail {

// The keep-out zones: a list of boxes in the robot's base frame.
KeyDef zonesKey()
{
    KeyDef def{"zones", kLive, {}, {}};
    def.read = [](const YAML::Node& node, ServiceConfig& config, const ReadContext&) -> ReadResult {
        const std::string expected =
            "a list of {name, min: [x, y, z], max: [x, y, z], min_points, enter_frames, "
            "leave_frames}, metres in the robot's base frame";
        if (!node.IsNull() && !node.IsSequence())
            return ReadFailure{"not a list", expected};
        std::vector<ZoneSettings> zones;
        for (std::size_t i = 0; i < node.size(); ++i) {
            const YAML::Node item = node[i];
            const std::string where = "zone " + std::to_string(i + 1);
            if (!item.IsMap())
                return ReadFailure{where + " is not a mapping", expected};
            ZoneSettings zone;
            for (const auto& entry : item) {
                const std::string key = entry.first.as<std::string>();
                const YAML::Node& value = entry.second;
                if (key == "name" && value.IsScalar()) {
                    zone.name = value.Scalar();
                } else if (key == "min" || key == "max") {
                    const auto v = parseVec3(value);
                    if (!v)
                        return ReadFailure{where + ": " + key + " is not [x, y, z]", expected};
                    (key == "min" ? zone.min_m : zone.max_m) = *v;
                } else if (key == "min_points" || key == "enter_frames" || key == "leave_frames") {
                    const auto v = value.IsScalar() ? parseInteger(value.Scalar()) : std::nullopt;
                    if (!v || *v < 1 || *v > 1000000)
                        return ReadFailure{where + ": " + key + " is not a whole number >= 1",
                                           expected};
                    (key == "min_points"     ? zone.min_points
                     : key == "enter_frames" ? zone.enter_frames
                                             : zone.leave_frames) = static_cast<int>(*v);
                } else {
                    return ReadFailure{where + ": unknown key " + key, expected};
                }
            }
            zones.push_back(std::move(zone));
        }
        config.zones.zones = std::move(zones);
        return std::nullopt;
    };
    def.show = [](const ServiceConfig& config) {
        std::string text = "[";
        for (const ZoneSettings& z : config.zones.zones)
            text += (text.size() > 1 ? ", " : "") + std::string("{name: ") + z.name +
                    ", min: " + showVec3(z.min_m) + ", max: " + showVec3(z.max_m) +
                    ", min_points: " + std::to_string(z.min_points) +
                    ", enter_frames: " + std::to_string(z.enter_frames) +
                    ", leave_frames: " + std::to_string(z.leave_frames) + "}";
        return text + "]";
    };
    return def;
}

KeyDef powerLineKey()
{
    std::vector<std::string> known{std::string(kKeep)};
    for (const std::string& name : kPowerLineFrequencies.names()) {
        known.push_back(name);
    }
    return keepKey(
        "source.cameras.controls.power_line_frequency", kRestart,
        [](auto& c) -> auto& { return c.source.cameras.controls.power_line; }, "unknown value",
        listNames(known), [](std::string_view text) { return kPowerLineFrequencies.parse(text); },
        [](PowerLineFrequency value) { return std::string(kPowerLineFrequencies.name(value)); });
}

std::string algorithmName(const MatcherSettings& matcher)
{
    return std::string(matcherAlgorithmName(matcher.kind, matcher.sgbm_mode));
}

KeyDef algorithmKey()
{
    KeyDef def{"matcher.algorithm", kLive, {}, {}};
    def.read = [](const YAML::Node& node, ServiceConfig& config, const ReadContext&) -> ReadResult {
        if (node.IsScalar()) {
            if (const auto algorithm = matcherAlgorithmNamed(node.Scalar())) {
                config.processing.matcher.kind = algorithm->kind;
                config.processing.matcher.sgbm_mode = algorithm->mode;
                return std::nullopt;
            }
        }
        std::vector<std::string> known;
        for (const MatcherAlgorithm& algorithm : kMatcherAlgorithms)
            known.emplace_back(algorithm.name);
        return ReadFailure{"unknown matcher", expectedOneOf(known, scalarText(node))};
    };
    def.show = [](const ServiceConfig& config) { return algorithmName(config.processing.matcher); };
    return def;
}

KeyDef modeKey()
{
    KeyDef def{"socket.mode", kRestart, {}, {}};
    def.read = [](const YAML::Node& node, ServiceConfig& config, const ReadContext&) -> ReadResult {
        const auto mode = node.IsScalar() ? parseMode(node.Scalar()) : std::nullopt;
        if (!mode) {
            return ReadFailure{"not an octal file mode", "octal digits, like \"0660\""};
        }
        config.socket.mode = *mode;
        return std::nullopt;
    };
    def.show = [](const ServiceConfig& config) {
        return "\"" + formatMode(config.socket.mode) + "\"";
    };
    return def;
}

const std::vector<std::string>& logLevelNames()
{
    // spdlog's level names (spdlog::level::to_string_view), least severe first.
    static const std::vector<std::string> names = {"trace", "debug",    "info", "warn",
                                                   "error", "critical", "off"};
    return names;
}

std::vector<KeyDef> buildKeyTable()
{
    std::vector<KeyDef> keys;
    const auto add = [&keys](KeyDef def) { keys.push_back(std::move(def)); };

    add(choiceKey(
        "source.type", kRestart, [](auto& c) -> auto& { return c.source.kind; }, kSourceKinds));
    add(textKey(
        "source.replay.path", kRestart, [](auto& c) -> auto& { return c.source.replay.path; },
        true));
    add(choiceKey(
        "source.replay.pacing", kRestart, [](auto& c) -> auto& { return c.source.replay.pacing; },
        kReplayPacings));
    add(realKey(
        "source.replay.fps", kRestart, [](auto& c) -> auto& { return c.source.replay.fps; },
        "frames per second"));
    add(boolKey(
        "source.replay.loop", kRestart, [](auto& c) -> auto& { return c.source.replay.loop; }));
    add(choiceKey(
        "source.replay.colour", kRestart, [](auto& c) -> auto& { return c.source.replay.colour; },
        kCameraColours));
    add(textKey(
        "source.replay.topics.left", kRestart,
        [](auto& c) -> auto& { return c.source.replay.left_topic; }, false));
    add(textKey(
        "source.replay.topics.right", kRestart,
        [](auto& c) -> auto& { return c.source.replay.right_topic; }, false));
    add(textKey(
        "source.cameras.left", kRestart, [](auto& c) -> auto& { return c.source.cameras.left; },
        false));
    add(textKey(
        "source.cameras.right", kRestart, [](auto& c) -> auto& { return c.source.cameras.right; },
        false));
    add(textKey(
        "source.cameras.device", kRestart, [](auto& c) -> auto& { return c.source.cameras.device; },
        false));
    add(choiceKey(
        "source.cameras.format", kRestart, [](auto& c) -> auto& { return c.source.cameras.format; },
        kPixelFormatChoices));
    add(choiceKey(
        "source.cameras.colour", kRestart, [](auto& c) -> auto& { return c.source.cameras.colour; },
        kCameraColours));
    add(integerKey(
        "source.cameras.width", kRestart, [](auto& c) -> auto& { return c.source.cameras.width; }));
    add(integerKey(
        "source.cameras.height", kRestart,
        [](auto& c) -> auto& { return c.source.cameras.height; }));
    add(realKey(
        "source.cameras.fps", kRestart, [](auto& c) -> auto& { return c.source.cameras.fps; },
        "frames per second"));
    add(boolKey(
        "source.cameras.lock_exposure", kRestart,
        [](auto& c) -> auto& { return c.source.cameras.lock_exposure; }));
    add(keepBoolKey(
        "source.cameras.controls.auto_exposure",
        [](auto& c) -> auto& { return c.source.cameras.controls.auto_exposure; }));
    add(keepIntegerKey(
        "source.cameras.controls.exposure_us",
        [](auto& c) -> auto& { return c.source.cameras.controls.exposure_us; }, "us"));
    add(keepIntegerKey(
        "source.cameras.controls.gain",
        [](auto& c) -> auto& { return c.source.cameras.controls.gain; }, "device units"));
    add(keepBoolKey(
        "source.cameras.controls.auto_white_balance",
        [](auto& c) -> auto& { return c.source.cameras.controls.auto_white_balance; }));
    add(keepIntegerKey(
        "source.cameras.controls.white_balance_k",
        [](auto& c) -> auto& { return c.source.cameras.controls.white_balance_k; }, "kelvin"));
    add(powerLineKey());
    add(textKey(
        "source.ros2.topics.left", kRestart,
        [](auto& c) -> auto& { return c.source.ros2.left_topic; }, false));
    add(textKey(
        "source.ros2.topics.right", kRestart,
        [](auto& c) -> auto& { return c.source.ros2.right_topic; }, false));
    add(autoTextKey(
        "source.ros2.topics.left_camera_info", kRestart,
        [](auto& c) -> auto& { return c.source.ros2.left_info_topic; }));
    add(autoTextKey(
        "source.ros2.topics.right_camera_info", kRestart,
        [](auto& c) -> auto& { return c.source.ros2.right_info_topic; }));
    add(integerKey(
        "source.ros2.width", kRestart, [](auto& c) -> auto& { return c.source.ros2.width; }));
    add(integerKey(
        "source.ros2.height", kRestart, [](auto& c) -> auto& { return c.source.ros2.height; }));
    add(integerKey(
        "source.ring_capacity", kRestart, [](auto& c) -> auto& { return c.source.ring_capacity; }));
    add(realKey(
        "source.max_skew_ms", kRestart, [](auto& c) -> auto& { return c.source.max_skew_ms; },
        "ms"));
    add(realKey(
        "source.stall_timeout_ms", kRestart,
        [](auto& c) -> auto& { return c.source.stall_timeout_ms; }, "ms"));
    add(textKey(
        "calibration", kRestart, [](auto& c) -> auto& { return c.calibration_path; }, true));

    add(algorithmKey());
    add(realKey(
        "matcher.min_depth_m", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.min_depth_m; }, "m"));
    add(autoIntegerKey(
        "matcher.num_disparities", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.num_disparities; },
        "auto or a positive multiple of 16"));
    add(integerKey(
        "matcher.max_num_disparities", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.max_num_disparities; }));
    add(integerKey(
        "matcher.min_disparity", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.min_disparity; }));
    add(integerKey(
        "matcher.block_size", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.block_size; }));
    add(autoIntegerKey(
        "matcher.uniqueness_ratio", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.uniqueness_ratio; },
        "auto or a percentage from 0 to 100", 0));
    add(autoIntegerKey(
        "matcher.speckle_window_px", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.speckle_window_px; },
        "auto or pixels, 0 disables", 0));
    add(autoIntegerKey(
        "matcher.speckle_range_px", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.speckle_range_px; }, "auto or pixels",
        0));
    add(autoIntegerKey(
        "matcher.lr_max_diff_px", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.lr_max_diff_px; },
        "auto, -1 (off) or pixels", -1));
    add(autoIntegerKey(
        "matcher.p1", kLive, [](auto& c) -> auto& { return c.processing.matcher.p1; },
        "auto or an integer from 1 to 32767"));
    add(autoIntegerKey(
        "matcher.p2", kLive, [](auto& c) -> auto& { return c.processing.matcher.p2; },
        "auto or an integer from 1 to 32767"));
    add(integerKey(
        "matcher.pre_filter_cap", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.pre_filter_cap; }));
    add(integerKey(
        "matcher.texture_threshold", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.texture_threshold; }));
    add(autoIntegerKey(
        "matcher.census_width", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.census_width; },
        "auto or an odd number of pixels"));
    add(autoIntegerKey(
        "matcher.census_height", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.census_height; },
        "auto or an odd number of pixels"));
    add(autoIntegerKey(
        "matcher.paths", kLive, [](auto& c) -> auto& { return c.processing.matcher.paths; },
        "auto, 3 or 5"));
    add(autoIntegerKey(
        "matcher.p2_gradient_scale", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.p2_gradient_scale; },
        "auto, off or grey levels", 1, true));
    add(choiceKey(
        "matcher.tuning", kLive, [](auto& c) -> auto& { return c.processing.matcher.tuning; },
        kMatcherTunings));
    add(autoIntegerKey(
        "matcher.threads", kLive, [](auto& c) -> auto& { return c.processing.matcher.threads; },
        "auto (the cores available) or a number of threads"));
    add(boolKey(
        "matcher.extended_range", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.extended_range; }));
    add(boolKey(
        "matcher.guided_search", kLive,
        [](auto& c) -> auto& { return c.processing.matcher.guided_search; }));

    add(realKey(
        "nearest.roi.x", kLive, [](auto& c) -> auto& { return c.processing.nearest.roi.x; },
        "image widths"));
    add(realKey(
        "nearest.roi.y", kLive, [](auto& c) -> auto& { return c.processing.nearest.roi.y; },
        "image heights"));
    add(realKey(
        "nearest.roi.width", kLive, [](auto& c) -> auto& { return c.processing.nearest.roi.width; },
        "image widths"));
    add(realKey(
        "nearest.roi.height", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.roi.height; }, "image heights"));
    add(realKey(
        "nearest.min_depth_m", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_depth_m; }, "m"));
    add(realKey(
        "nearest.max_depth_m", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.max_depth_m; }, "m"));
    add(autoRealKey(
        "output.max_depth_m", kLive,
        [](auto& c) -> auto& { return c.processing.output.max_depth_m; }, "m"));
    add(realKey(
        "nearest.percentile", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.percentile; }, "percent"));
    add(realKey(
        "nearest.min_valid_fraction", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_valid_fraction; }, ""));
    add(integerKey(
        "nearest.min_pixels", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_pixels; }));
    add(realKey(
        "nearest.min_in_range_fraction", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_in_range_fraction; }, ""));
    add(integerKey(
        "nearest.min_confidence", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.min_confidence; }));
    add(realKey(
        "nearest.range_limit_fraction", kLive,
        [](auto& c) -> auto& { return c.processing.nearest.range_limit_fraction; }, ""));
    add(boolKey(
        "point_cloud", kLive, [](auto& c) -> auto& { return c.processing.compute_cloud; }));
    add(vec3Key(
        "robot.camera_pose.translation_m", kLive,
        [](auto& c) -> auto& { return c.zones.camera_pose.translation_m; }, "metres"));
    add(vec3Key(
        "robot.camera_pose.rpy_deg", kLive,
        [](auto& c) -> auto& { return c.zones.camera_pose.rpy_deg; }, "degrees"));
    add(realKey(
        "robot.min_visible_fraction", kLive,
        [](auto& c) -> auto& { return c.zones.min_visible_fraction; }, ""));
    add(zonesKey());
    add(realKey(
        "calibration_health.interval_s", kLive,
        [](auto& c) -> auto& { return c.calibration_health.interval_s; }, "s"));
    add(boolKey(
        "calibration_health.withhold_when_failed", kLive,
        [](auto& c) -> auto& { return c.calibration_health.withhold_when_failed; }));

    add(textKey(
        "socket.path", kRestart, [](auto& c) -> auto& { return c.socket.path; }, true));
    add(modeKey());
    add(textKey(
        "socket.group", kRestart, [](auto& c) -> auto& { return c.socket.group; }, false));
    add(integerKey(
        "socket.max_clients", kRestart, [](auto& c) -> auto& { return c.socket.max_clients; }));
    add(integerKey(
        "socket.max_request_bytes", kRestart,
        [](auto& c) -> auto& { return c.socket.max_request_bytes; }));
    add(realKey(
        "socket.idle_timeout_s", kRestart, [](auto& c) -> auto& { return c.socket.idle_timeout_s; },
        "s"));
    add(idListKey(
        "socket.allow_uids", kRestart, [](auto& c) -> auto& { return c.socket.allow_uids; }));
    add(idListKey(
        "socket.allow_gids", kRestart, [](auto& c) -> auto& { return c.socket.allow_gids; }));

    add(realKey(
        "publish.readings_max_hz", kLive,
        [](auto& c) -> auto& { return c.publish.readings_max_hz; }, "Hz"));
    add(realKey(
        "publish.depth_max_hz", kLive, [](auto& c) -> auto& { return c.publish.depth_max_hz; },
        "Hz"));
    add(integerKey(
        "publish.max_client_backlog_bytes", kLive,
        [](auto& c) -> auto& { return c.publish.max_client_backlog_bytes; }));
    add(realKey(
        "publish.max_reading_age_ms", kLive,
        [](auto& c) -> auto& { return c.publish.max_reading_age_ms; }, "ms"));
    add(textKey(
        "live_view.listen", kRestart, [](auto& c) -> auto& { return c.live_view.listen; }, false));
    add(integerKey(
        "live_view.max_clients", kRestart,
        [](auto& c) -> auto& { return c.live_view.max_clients; }));
    add(textListKey(
        "live_view.allowed_origins", kRestart,
        [](auto& c) -> auto& { return c.live_view.allowed_origins; }));
    add(integerKey(
        "live_view.points_step", kRestart,
        [](auto& c) -> auto& { return c.live_view.points_step; }));
    add(realKey(
        "live_view.max_rate_hz", kRestart, [](auto& c) -> auto& { return c.live_view.max_rate_hz; },
        "Hz"));
    add(realKey(
        "live_view.rate_hz.image", kRestart,
        [](auto& c) -> auto& { return c.live_view.rate_hz.image; }, "Hz"));
    add(realKey(
        "live_view.rate_hz.depth", kRestart,
        [](auto& c) -> auto& { return c.live_view.rate_hz.depth; }, "Hz"));
    add(realKey(
        "live_view.rate_hz.disparity", kRestart,
        [](auto& c) -> auto& { return c.live_view.rate_hz.disparity; }, "Hz"));
    add(realKey(
        "live_view.rate_hz.confidence", kRestart,
        [](auto& c) -> auto& { return c.live_view.rate_hz.confidence; }, "Hz"));
    add(realKey(
        "live_view.rate_hz.points", kRestart,
        [](auto& c) -> auto& { return c.live_view.rate_hz.points; }, "Hz"));
    add(realKey(
        "live_view.rate_hz.camera_info", kRestart,
        [](auto& c) -> auto& { return c.live_view.rate_hz.camera_info; }, "Hz"));
    add(realKey(
        "live_view.rate_hz.nearest", kRestart,
        [](auto& c) -> auto& { return c.live_view.rate_hz.nearest; }, "Hz"));
    add(boolKey(
        "ros2.enabled", kRestart, [](auto& c) -> auto& { return c.ros2.enabled; }));
    add(textKey(
        "ros2.namespace", kRestart, [](auto& c) -> auto& { return c.ros2.ns; }, false));
    add(boolKey(
        "ros2.localhost_only", kRestart, [](auto& c) -> auto& { return c.ros2.localhost_only; }));
    add(integerKey(
        "ros2.points_step", kRestart, [](auto& c) -> auto& { return c.ros2.points_step; }));
    add(realKey(
        "ros2.max_rate_hz", kRestart, [](auto& c) -> auto& { return c.ros2.max_rate_hz; }, "Hz"));
    add(textKey(
        "log_level", kLive, [](auto& c) -> auto& { return c.log_level; }, false));
    return keys;
}

const Schema& schema()
{
    static const Schema instance = [] {
        Schema built;
        built.keys = buildKeyTable();
        for (const auto& def : built.keys) {
            SchemaNode* node = &built.root;
            size_t start = 0;
            while (true) {
                const size_t dot = def.path.find('.', start);
                const std::string part = def.path.substr(start, dot - start);
                SchemaNode* next = nullptr;
                for (auto& entry : node->children) {
                    if (entry.name == part) {
                        next = &entry;
                    }
                }
                if (next == nullptr) {
                    node->children.push_back(SchemaNode{part, nullptr, {}});
                    next = &node->children.back();
                }
                node = next;
                if (dot == std::string::npos) {
                    break;
                }
                start = dot + 1;
            }
            node->key = &def;
        }
        return built;
    }();
    return instance;
}

std::string joinPath(const std::string& prefix, std::string_view name)
{
    return prefix.empty() ? std::string(name) : prefix + "." + std::string(name);
}

} // namespace stereod::config_detail
