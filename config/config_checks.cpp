#include "config/config_checks.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <system_error>

#include <grp.h>
#include <sys/un.h>
#include <unistd.h>

#include "base/settings_error.hpp"
#include "base/system_error.hpp"
#include "config/key_table.hpp"
#include "pipeline/census_sgm_matcher.hpp"
#include "pipeline/matcher_defaults.hpp"
#include "pipeline/zones.hpp"
#include "ros2/topic_names.hpp"

namespace stereod::config_detail {

namespace {

// ---------------------------------------------------------------------------------------
// Validation

// A closed, open or half-open interval with its unit, for range checks and their messages.
struct Range {
    double lo = -std::numeric_limits<double>::infinity();
    double hi = std::numeric_limits<double>::infinity();
    bool lo_open = false;
    bool hi_open = false;
    std::string unit; // " m", " ms", ...: appended to the expected range

    bool contains(double value) const
    {
        return (lo_open ? value > lo : value >= lo) && (hi_open ? value < hi : value <= hi);
    }

    std::string text() const
    {
        if (std::isinf(hi)) {
            return (lo_open ? "> " : ">= ") + formatNumber(lo) + unit;
        }
        if (!lo_open && !hi_open) {
            return formatNumber(lo) + " to " + formatNumber(hi) + unit;
        }
        return (lo_open ? "> " : ">= ") + formatNumber(lo) + " and " + (hi_open ? "< " : "<= ") +
               formatNumber(hi) + unit;
    }
};

Range above(double lo, double hi, std::string unit)
{
    return Range{lo, hi, true, false, std::move(unit)};
}

Range closed(double lo, double hi, std::string unit)
{
    return Range{lo, hi, false, false, std::move(unit)};
}

// Checks the values of a configuration and words the problems. One per call,
// thread-bound.
class Checker {
  public:
    Checker(const ServiceConfig& config, const KeyLocations& locations)
        : config_(config), locations_(locations),
          origin_(config.origin.empty() ? "<config>" : config.origin)
    {
    }

    // Records a problem with `key` unless its value could not be read in the first place.
    void fail(const std::string& key, std::string_view problem, std::string_view expected)
    {
        if (locations_.unreadable.count(key) != 0) {
            return;
        }
        const KeyDef* def = schema().find(key);
        const std::string got = def != nullptr ? def->show(config_) : std::string("?");
        const auto line = locations_.lines.find(key);
        problems_.push_back(Problem{line != locations_.lines.end() ? line->second : 0, key,
                                    location(key) + ": " + key + ": " + std::string(problem) +
                                        " (got " + got + ", expected " + std::string(expected) +
                                        ")"});
        failed_.insert(key);
    }

    // True when none of `keys` has a problem yet: cross-key checks need good inputs.
    bool usable(std::initializer_list<std::string_view> keys) const
    {
        return std::none_of(keys.begin(), keys.end(), [&](std::string_view key) {
            const std::string name(key);
            return failed_.count(name) != 0 || locations_.unreadable.count(name) != 0;
        });
    }

    void real(const std::string& key, double value, const Range& range)
    {
        if (!std::isfinite(value)) {
            fail(key, "not a finite number", range.text());
        } else if (!range.contains(value)) {
            fail(key, "out of range", range.text());
        }
    }

    // hi at the limit of the field's type reads as no upper bound (">= 1 px").
    void integer(const std::string& key, int64_t value, int64_t lo, int64_t hi,
                 std::string_view unit = "")
    {
        if (value >= lo && value <= hi) {
            return;
        }
        const bool open =
            hi == std::numeric_limits<int>::max() || hi == std::numeric_limits<uint32_t>::max();
        fail(
            key, "out of range",
            (open ? ">= " + std::to_string(lo) : std::to_string(lo) + " to " + std::to_string(hi)) +
                std::string(unit));
    }

    std::vector<Problem> takeProblems() { return std::move(problems_); }

  private:
    std::string location(const std::string& key) const
    {
        if (auto it = locations_.overridden.find(key); it != locations_.overridden.end()) {
            return "command line (" + it->second + ")";
        }
        if (auto it = locations_.lines.find(key); it != locations_.lines.end()) {
            return origin_ + ":" + std::to_string(it->second);
        }
        return origin_;
    }

    const ServiceConfig& config_;
    const KeyLocations& locations_;
    std::string origin_;
    std::vector<Problem> problems_;
    std::set<std::string> failed_;
};

// A path the service will open: exists and has the right type. Relative paths are
// checked against the working directory, as the service will open them.
void checkPath(Checker& checker, const std::string& key, const std::string& path, bool directory,
               std::string_view expected)
{
    std::error_code error;
    const fs::file_status status = fs::status(path, error);
    if (status.type() == fs::file_type::not_found) {
        checker.fail(key, "does not exist", expected);
    } else if (error) {
        checker.fail(key, "cannot be checked: " + error.message(), expected);
    } else if (directory && !fs::is_directory(status)) {
        checker.fail(key, "is not a directory", expected);
    } else if (!directory && !fs::is_regular_file(status)) {
        checker.fail(key, "is not a regular file", expected);
    } else if (::access(path.c_str(), R_OK | (directory ? X_OK : 0)) != 0) {
        checker.fail(key, std::string("cannot be read: ") + errnoText(errno), expected);
    }
}

void checkCameras(Checker& checker, const SourceConfig& source)
{
    const CamerasConfig& cameras = source.cameras;
    checker.integer("source.cameras.width", cameras.width, 16, 16384, " px");
    checker.integer("source.cameras.height", cameras.height, 16, 16384, " px");
    checker.real("source.cameras.fps", cameras.fps, above(0, 1000, " frames/s"));
    const CameraControls& controls = cameras.controls;
    if (controls.exposure_us) {
        checker.integer("source.cameras.controls.exposure_us", *controls.exposure_us, 1, 10000000,
                        " us");
    }
    if (controls.gain) {
        checker.integer("source.cameras.controls.gain", *controls.gain, 0,
                        std::numeric_limits<int>::max(), " (device units)");
    }
    if (controls.white_balance_k) {
        checker.integer("source.cameras.controls.white_balance_k", *controls.white_balance_k, 1000,
                        20000, " K");
    }
    if (cameras.lock_exposure && controls.auto_exposure.value_or(false)) {
        checker.fail("source.cameras.lock_exposure",
                     "contradicts source.cameras.controls.auto_exposure: true",
                     "false, or auto_exposure keep or false");
    }

    if (source.kind == SourceKind::V4l2) {
        constexpr std::string_view kDevice =
            "a V4L2 device path, e.g. /dev/v4l/by-id/usb-...-video-index0 (stereoctl devices "
            "lists them)";
        if (cameras.left.empty()) {
            checker.fail("source.cameras.left", "empty with source.type v4l2", kDevice);
        }
        if (cameras.right.empty()) {
            checker.fail("source.cameras.right", "empty with source.type v4l2", kDevice);
        }
        if (!cameras.left.empty() && cameras.left == cameras.right) {
            checker.fail("source.cameras.right", "the same device as source.cameras.left",
                         "the other camera of the rig");
        }
        // A partner more than half a period away may belong to the next frame: pairs
        // must not be able to mix up instants.
        const double half_period_ms = 500.0 / cameras.fps;
        if (checker.usable({"source.max_skew_ms", "source.cameras.fps"}) &&
            source.max_skew_ms >= half_period_ms) {
            checker.fail("source.max_skew_ms", "not below half the frame period",
                         "< " + formatNumber(half_period_ms) + " ms at source.cameras.fps " +
                             formatNumber(cameras.fps));
        }
    } else if (source.kind == SourceKind::SideBySide) {
        if (cameras.device.empty()) {
            checker.fail("source.cameras.device", "empty with source.type side_by_side",
                         "the V4L2 device path of the side-by-side camera");
        }
        if (cameras.width % 2 != 0) {
            checker.fail("source.cameras.width", "odd with source.type side_by_side",
                         "an even width: the frame holds two halves");
        }
    }
}

void checkRos2Source(Checker& checker, const SourceConfig& source)
{
    const Ros2SourceConfig& ros2 = source.ros2;
    // An absolute topic name follows a namespace's rules (tokens of letters, digits and _),
    // with at least one token.
    const auto checkTopic = [&checker](const std::string& key, const std::string& topic) {
        std::string problem = ros2::namespaceProblem(topic);
        if (problem.empty() && topic == "/")
            problem = "names no topic";
        if (!problem.empty())
            checker.fail(key, problem,
                         "an absolute ROS 2 topic name such as /stereo/left/image_raw");
    };
    checkTopic("source.ros2.topics.left", ros2.left_topic);
    checkTopic("source.ros2.topics.right", ros2.right_topic);
    if (ros2.left_topic == ros2.right_topic)
        checker.fail("source.ros2.topics.right", "the same topic as source.ros2.topics.left",
                     "the other camera's image topic");
    if (ros2.left_info_topic)
        checkTopic("source.ros2.topics.left_camera_info", *ros2.left_info_topic);
    if (ros2.right_info_topic)
        checkTopic("source.ros2.topics.right_camera_info", *ros2.right_info_topic);
    if (ros2.left_topic != ros2.right_topic &&
        leftCameraInfoTopic(ros2) == rightCameraInfoTopic(ros2))
        checker.fail("source.ros2.topics.right_camera_info",
                     "the same topic as the left camera's camera_info (" +
                         leftCameraInfoTopic(ros2) + ")",
                     "the right camera's camera_info topic");
    // The largest frame any source may have (8192x8192, as a recording's).
    checker.integer("source.ros2.width", ros2.width, 16, 8192, " px");
    checker.integer("source.ros2.height", ros2.height, 16, 8192, " px");
}

void checkSource(Checker& checker, const SourceConfig& source, const std::string& calibration)
{
    checker.integer("source.ring_capacity", source.ring_capacity, 2, 64, " pairs");
    checker.real("source.max_skew_ms", source.max_skew_ms, above(0, 1000, " ms"));
    // Shorter than 100 ms would call a 10 fps source down between two frames.
    checker.real("source.stall_timeout_ms", source.stall_timeout_ms, closed(100, 600000, " ms"));
    checker.real("source.replay.fps", source.replay.fps, above(0, 1000, " fps"));

    checkCameras(checker, source);
    checkRos2Source(checker, source);

    constexpr std::string_view kRecording =
        "a recording directory (frames.csv, left/, right/), a folder of left*/right* images, "
        "or a ROS 2 bag (FILE.mcap)";
    constexpr std::string_view kCalibration = "a calibration file (docs/calibration.md)";
    if (!source.replay.path.empty()) {
        // A regular file must be an MCAP bag: it starts with MCAP's magic bytes.
        std::error_code error;
        if (fs::is_regular_file(source.replay.path, error)) {
            char magic[8] = {};
            std::ifstream(source.replay.path, std::ios::binary).read(magic, sizeof magic);
            if (std::string_view(magic, sizeof magic) != std::string_view("\x89MCAP0\r\n", 8)) {
                checker.fail("source.replay.path", "is neither a directory nor an MCAP file",
                             kRecording);
            }
        } else {
            checkPath(checker, "source.replay.path", source.replay.path, true, kRecording);
        }
    }
    // Without a calibration key the recording's own calibration.yaml is used; with
    // neither, the service runs uncalibrated (docs/service.md), which is no error.
    if (!calibration.empty()) {
        checkPath(checker, "calibration", calibration, false, kCalibration);
    }
}

// A refusal thrown by a part's own validation, "key: problem", as the checker's problem
// for that key (`fallback_key` when the message names none). A list item's key
// ("zones[1].max") belongs to the list's key, and the item is named in what is expected.
void failAsRefused(Checker& checker, const std::string& message, const std::string& fallback_key)
{
    const std::string docs = "see docs/configuration.md";
    const size_t colon = message.find(": ");
    if (colon == std::string::npos) {
        checker.fail(fallback_key, message, docs);
        return;
    }
    const std::string key = message.substr(0, colon);
    const size_t bracket = key.find('[');
    if (bracket != std::string::npos)
        checker.fail(key.substr(0, bracket), message.substr(colon + 2), key);
    else // the checker shows the key's value itself: the matcher's ", got X" would repeat it
        checker.fail(key, message.substr(colon + 2, message.rfind(", got ") - colon - 2), docs);
}

// census-sgm's own limits are the matcher's (one place): its first refusal, under the
// `matcher.` key of the field it names.
void checkCensusSgm(Checker& checker, const MatcherSettings& matcher)
{
    try {
        validateCensusSgm(matcher);
    } catch (const SettingsError& e) {
        // The checker shows the key's value itself: the matcher's ", got X" would repeat it.
        const std::string& problem = e.problem();
        checker.fail("matcher." + e.field(), problem.substr(0, problem.rfind(", got ")),
                     "see docs/configuration.md");
    }
}

void checkMatcher(Checker& checker, const MatcherSettings& matcher)
{
    checker.real("matcher.min_depth_m", matcher.min_depth_m, above(0, 1000, " m"));

    // Cost grows linearly with the range; beyond 1024 px no rig in this service's reach
    // needs more, and OpenCV's buffers grow with it.
    constexpr int kMaxDisparities = 1024;
    const std::string steps = "16 to " + std::to_string(kMaxDisparities) + " in steps of 16";
    if (matcher.max_num_disparities % 16 != 0) {
        checker.fail("matcher.max_num_disparities", "not a multiple of 16", steps);
    } else {
        checker.integer("matcher.max_num_disparities", matcher.max_num_disparities, 16,
                        kMaxDisparities);
    }
    if (matcher.num_disparities) {
        if (*matcher.num_disparities % 16 != 0) {
            checker.fail("matcher.num_disparities", "not a multiple of 16", "auto or " + steps);
        } else if (*matcher.num_disparities < 16 || *matcher.num_disparities > kMaxDisparities) {
            checker.fail("matcher.num_disparities", "out of range", "auto or " + steps);
        }
    }
    checker.integer("matcher.min_disparity", matcher.min_disparity, -kMaxDisparities,
                    kMaxDisparities, " px");

    // The shared settings, with the chosen matcher's values where the file leaves them.
    const MatcherSettings effective = effectiveMatcherSettings(matcher);
    checker.integer("matcher.uniqueness_ratio", *effective.uniqueness_ratio, 0, 100, " percent");
    checker.integer("matcher.speckle_window_px", *effective.speckle_window_px, 0, 1000000, " px");
    checker.integer("matcher.speckle_range_px", *effective.speckle_range_px, 0, kMaxDisparities,
                    " px");
    if (*effective.lr_max_diff_px < -1 || *effective.lr_max_diff_px > kMaxDisparities) {
        checker.fail("matcher.lr_max_diff_px", "out of range",
                     "-1 (off) or 0 to " + std::to_string(kMaxDisparities) + " px");
    }

    if (matcher.kind == MatcherKind::CensusSgm) {
        if (checker.usable({"matcher.num_disparities", "matcher.max_num_disparities",
                            "matcher.min_disparity", "matcher.uniqueness_ratio",
                            "matcher.speckle_window_px", "matcher.speckle_range_px"}))
            checkCensusSgm(checker, matcher);
        return;
    }
    // OpenCV's limits: StereoBM takes odd blocks of 5..255, StereoSGBM odd blocks >= 1;
    // beyond 31 px SGBM only blurs depth edges and costs time.
    const bool bm = matcher.kind == MatcherKind::Bm;
    const int block_lo = bm ? 5 : 1;
    const int block_hi = bm ? 255 : 31;
    const std::string block_expected = "an odd number from " + std::to_string(block_lo) + " to " +
                                       std::to_string(block_hi) + " px for " +
                                       algorithmName(matcher);
    if (matcher.block_size % 2 == 0) {
        checker.fail("matcher.block_size", "not odd", block_expected);
    } else if (matcher.block_size < block_lo || matcher.block_size > block_hi) {
        checker.fail("matcher.block_size", "out of range", block_expected);
    }

    // SGBM keeps its path costs in 16 bits, so penalties stay below 32768.
    constexpr int kMaxPenalty = 32767;
    if (matcher.p1) {
        checker.integer("matcher.p1", *matcher.p1, 1, kMaxPenalty);
    }
    if (matcher.p2) {
        checker.integer("matcher.p2", *matcher.p2, 1, kMaxPenalty);
    }
    if (!bm && checker.usable({"matcher.p1", "matcher.p2", "matcher.block_size"})) {
        // The automatic penalties, for one (grayscale) channel: 8*bs^2 and 32*bs^2.
        const int p1 = *effective.p1;
        const int p2 = *effective.p2;
        if (p2 <= p1) {
            if (matcher.p2) {
                checker.fail("matcher.p2", "not above matcher.p1",
                             "> " + std::to_string(p1) +
                                 (matcher.p1 ? "" : ", the automatic p1 of 8*block_size^2"));
            } else {
                checker.fail("matcher.p1", "not below the automatic p2",
                             "< " + std::to_string(p2) + " (32*block_size^2), or set matcher.p2");
            }
        }
    }
    checker.integer("matcher.pre_filter_cap", matcher.pre_filter_cap, 1, 63);
    checker.integer("matcher.texture_threshold", matcher.texture_threshold, 0,
                    std::numeric_limits<int>::max());
}

void checkNearest(Checker& checker, const NearestSettings& nearest)
{
    const RegionOfInterest& roi = nearest.roi;
    checker.real("nearest.roi.x", roi.x, Range{0, 1, false, true, " of the image width"});
    checker.real("nearest.roi.y", roi.y, Range{0, 1, false, true, " of the image height"});
    checker.real("nearest.roi.width", roi.width, above(0, 1, " of the image width"));
    checker.real("nearest.roi.height", roi.height, above(0, 1, " of the image height"));
    // A tolerance for fractions such as 0.3 + 0.7 that do not add up to 1 exactly.
    constexpr double kSlack = 1e-9;
    if (checker.usable({"nearest.roi.x", "nearest.roi.width"}) && roi.x + roi.width > 1 + kSlack) {
        checker.fail("nearest.roi.width", "reaches past the right edge of the image",
                     "<= " + formatNumber(1 - roi.x) + ", 1 - nearest.roi.x");
    }
    if (checker.usable({"nearest.roi.y", "nearest.roi.height"}) &&
        roi.y + roi.height > 1 + kSlack) {
        checker.fail("nearest.roi.height", "reaches past the bottom edge of the image",
                     "<= " + formatNumber(1 - roi.y) + ", 1 - nearest.roi.y");
    }

    checker.real("nearest.min_depth_m", nearest.min_depth_m, above(0, 1000, " m"));
    checker.real("nearest.max_depth_m", nearest.max_depth_m, above(0, 1000, " m"));
    if (checker.usable({"nearest.min_depth_m", "nearest.max_depth_m"}) &&
        nearest.max_depth_m <= nearest.min_depth_m) {
        checker.fail("nearest.max_depth_m", "not above nearest.min_depth_m",
                     "> " + formatNumber(nearest.min_depth_m) + " m");
    }
    checker.real("nearest.percentile", nearest.percentile, closed(0, 100, " percent"));
    checker.real("nearest.min_valid_fraction", nearest.min_valid_fraction,
                 closed(0, 1, " of the region's pixels"));
    checker.integer("nearest.min_pixels", nearest.min_pixels, 1, std::numeric_limits<int>::max(),
                    " px");
    checker.real("nearest.min_in_range_fraction", nearest.min_in_range_fraction,
                 closed(0, 1, " of the region's pixels"));
    checker.integer("nearest.min_confidence", nearest.min_confidence, 0, 255, "");
    checker.real("nearest.range_limit_fraction", nearest.range_limit_fraction,
                 closed(0, 1, " of the region's pixels"));
}

void checkSocket(Checker& checker, const SocketConfig& socket)
{
    // sockaddr_un holds the path with its terminating NUL.
    constexpr size_t kMaxPath = sizeof(sockaddr_un::sun_path) - 1;
    if (socket.path.empty()) {
        checker.fail("socket.path", "empty", "the path of the service's Unix socket");
    } else if (socket.path.size() > kMaxPath) {
        checker.fail("socket.path", "too long for a Unix socket",
                     "at most " + std::to_string(kMaxPath) + " bytes");
    }
    if (socket.mode > 0777) {
        checker.fail("socket.mode", "out of range", "permission bits \"0000\" to \"0777\"");
    }
    if (!socket.group.empty()) {
        const bool numeric = std::all_of(socket.group.begin(), socket.group.end(),
                                         [](unsigned char ch) { return std::isdigit(ch); });
        if (!numeric) {
            // getgrnam_r, not getgrnam: validation may run on any thread.
            struct group entry {};
            struct group* found = nullptr;
            std::vector<char> buffer(16384);
            const int error =
                ::getgrnam_r(socket.group.c_str(), &entry, buffer.data(), buffer.size(), &found);
            if (error != 0) {
                checker.fail("socket.group",
                             std::string("cannot be looked up: ") + errnoText(error),
                             "a group of this system");
            } else if (found == nullptr) {
                checker.fail("socket.group", "no such group", "a group of this system, or empty");
            }
        }
    }
    checker.integer("socket.max_clients", socket.max_clients, 1, 1024);
    checker.integer("socket.max_request_bytes", socket.max_request_bytes, 1024, 16 << 20, " bytes");
    checker.real("socket.idle_timeout_s", socket.idle_timeout_s,
                 closed(0, 86400, " s (0: no limit)"));
}

void checkPublish(Checker& checker, const PublishConfig& publish)
{
    checker.real("publish.readings_max_hz", publish.readings_max_hz,
                 closed(0, 1000, " Hz (0: every frame)"));
    checker.real("publish.depth_max_hz", publish.depth_max_hz,
                 closed(0, 1000, " Hz (0: every frame)"));
    // Below 1 MiB a single depth frame of a small camera would not fit.
    checker.integer("publish.max_client_backlog_bytes", publish.max_client_backlog_bytes, 1 << 20,
                    std::numeric_limits<uint32_t>::max(), " bytes");
    checker.real("publish.max_reading_age_ms", publish.max_reading_age_ms,
                 above(0, 3600000, " ms"));
}

void checkLiveView(Checker& checker, const LiveViewConfig& live_view)
{
    try {
        parseListenAddress(live_view.listen);
    } catch (const std::invalid_argument& e) {
        checker.fail("live_view.listen", e.what(), "HOST:PORT with an IP address, or off");
    }
    checker.integer("live_view.max_clients", live_view.max_clients, 1, 256, " clients");
    for (const std::string& origin : live_view.allowed_origins) {
        // What a browser sends: scheme://host[:port], no path; or "*" for any page.
        const std::size_t scheme = origin.find("://");
        const bool looks_right =
            origin == "*" ||
            (scheme != std::string::npos && scheme > 0 && origin.size() > scheme + 3 &&
             origin.find_first_of("/ \t", scheme + 3) == std::string::npos);
        if (!looks_right) {
            checker.fail("live_view.allowed_origins", "\"" + origin + "\" is not an origin",
                         "origins as browsers send them: scheme://host[:port] without a path, "
                         "like https://app.foxglove.dev, or *");
            break;
        }
    }
    checker.integer("live_view.points_step", live_view.points_step, 1, 1000, "");
    checker.real("live_view.max_rate_hz", live_view.max_rate_hz, above(0, 1000, " Hz"));
    const auto& r = live_view.rate_hz;
    const std::pair<const char*, double> rates[] = {
        {"live_view.rate_hz.image", r.image},
        {"live_view.rate_hz.depth", r.depth},
        {"live_view.rate_hz.disparity", r.disparity},
        {"live_view.rate_hz.confidence", r.confidence},
        {"live_view.rate_hz.points", r.points},
        {"live_view.rate_hz.camera_info", r.camera_info},
        {"live_view.rate_hz.nearest", r.nearest}};
    for (const auto& [key, value] : rates)
        checker.real(key, value, closed(0, 1000, " Hz (0: live_view.max_rate_hz)"));
}

void checkRos2(Checker& checker, const ServiceConfig& config)
{
    const Ros2Config& ros2 = config.ros2;
    if (const std::string problem = ros2::namespaceProblem(ros2.ns); !problem.empty()) {
        checker.fail("ros2.namespace", problem, "a ROS 2 namespace such as /stereo");
    } else if (ros2.enabled && config.source.kind == SourceKind::Ros2 &&
               config.calibration_path.empty()) {
        // The node's own rectified camera_info must not be read back as the drivers'.
        for (const bool right : {false, true}) {
            const std::string published =
                ros2::rosTopicName(ros2.ns, right ? "right/camera_info" : "left/camera_info");
            const std::string subscribed = right ? rightCameraInfoTopic(config.source.ros2)
                                                 : leftCameraInfoTopic(config.source.ros2);
            if (published == subscribed) {
                checker.fail("ros2.namespace",
                             "stereod would publish its rectified camera_info on " + published +
                                 ", the driver's camera_info topic it takes the calibration from",
                             "a namespace of stereod's own (such as /stereo_depth), other "
                             "source.ros2.topics, or a calibration file");
                break;
            }
        }
    }
    checker.integer("ros2.points_step", ros2.points_step, 1, 1000, "");
    checker.real("ros2.max_rate_hz", ros2.max_rate_hz, above(0, 1000, " Hz"));
}

} // namespace

std::vector<Problem> checkValues(const ServiceConfig& config, const KeyLocations& locations)
{
    Checker checker(config, locations);
    checkSource(checker, config.source, config.calibration_path);
    checkMatcher(checker, config.processing.matcher);
    checkNearest(checker, config.processing.nearest);
    if (const auto& cap = config.processing.output.max_depth_m)
        checker.real("output.max_depth_m", *cap, above(0, 1e6, " m"));
    checker.real("calibration_health.interval_s", config.calibration_health.interval_s,
                 closed(0, 3600, " s"));
    checker.real("robot.min_visible_fraction", config.zones.min_visible_fraction,
                 closed(0, 1, " of a zone's volume"));
    try {
        validateZonesSettings(config.zones);
    } catch (const std::invalid_argument& e) {
        failAsRefused(checker, e.what(), "zones");
    }
    checkSocket(checker, config.socket);
    checkPublish(checker, config.publish);
    checkLiveView(checker, config.live_view);
    checkRos2(checker, config);
    const auto& levels = logLevelNames();
    if (std::find(levels.begin(), levels.end(), config.log_level) == levels.end()) {
        checker.fail("log_level", "unknown level", expectedOneOf(levels, config.log_level));
    }
    return checker.takeProblems();
}
} // namespace stereod::config_detail
