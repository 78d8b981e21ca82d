#pragma once
// The service configuration (YAML). Every value is validated with its unit and range;
// an error names the key and the file:line. Format and defaults: docs/configuration.md
// and config/examples/.
//
// The functions below are reentrant: they share nothing but an immutable table of keys.

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "base/name_table.hpp"
#include "capture/camera_settings.hpp"
#include "pipeline/stereo_processor.hpp"
#include "pipeline/zones.hpp"
#include "replay/replay_pacing.hpp"

namespace stereod {

// One problem of a configuration: the key it is about (empty when about none, a YAML
// syntax error say) and its text, "FILE:LINE: key: problem".
struct ConfigProblem {
    std::string key;
    std::string text;
};

// Every problem found in a configuration. what() holds all of them, one per line, ready
// to print; onlyAbout() tells by their keys, not their words, what they are about (the
// exit code of a bad replay path is a source problem's). Immutable, so thread-safe.
class ConfigError : public std::runtime_error {
  public:
    // Problems about no key (a file that cannot be read).
    explicit ConfigError(std::vector<std::string> problems);
    explicit ConfigError(const std::vector<ConfigProblem>& problems);
    const std::vector<std::string>& problems() const noexcept { return problems_; }
    // True when there are problems and every one is about `key` ("source.replay.path").
    bool onlyAbout(std::string_view key) const;

  private:
    std::vector<std::string> problems_;
    std::vector<std::string> keys_; // problems_[i] is about keys_[i]; empty: about none
};

enum class SourceKind {
    Replay,     // a recording on disk (source.replay)
    V4l2,       // two V4L2 cameras, paired by stereo sync (source.cameras.left/right)
    SideBySide, // one V4L2 device whose frames hold left|right halves (source.cameras.device)
    Ros2,       // a ROS 2 camera driver's two Image topics over DDS (source.ros2)
};

// The names of source.type.
inline constexpr NameTable<SourceKind, 4> kSourceKinds{{{
    {SourceKind::Replay, "replay"},
    {SourceKind::V4l2, "v4l2"},
    {SourceKind::SideBySide, "side_by_side"},
    {SourceKind::Ros2, "ros2"},
}}};
static_assert(kSourceKinds.wellFormed());

// Which cameras keep their colour beside the grey image the matcher sees
// (source.cameras.colour, and source.replay.colour for a recording's images). The left
// camera's colour is what the outputs carry (rectified left image, cloud colours); the
// right's only reaches recordings.
enum class CameraColour { None, Left, Both };

// The names of source.cameras.colour and source.replay.colour, in the order the docs list
// them.
inline constexpr NameTable<CameraColour, 3> kCameraColours{{{
    {CameraColour::Left, "left"},
    {CameraColour::Both, "both"},
    {CameraColour::None, "none"},
}}};
static_assert(kCameraColours.wellFormed());

struct ReplayConfig {
    std::string path; // a recording directory, a folder of left*/right*, or
                      // a ROS 2 bag (MCAP file)
    // A bag's image topics (source.replay.topics.left/right); empty: the defaults
    // /stereo/{left,right}/image_raw, or the one pair whose names say left and right.
    std::string left_topic;
    std::string right_topic;
    ReplayPacing pacing = ReplayPacing::Paced;
    double fps = 10.0; // nominal rate for plain folders (no frames.csv)
    bool loop = true;
    CameraColour colour = CameraColour::Left; // kept where the recording's images have it
};

// The V4L2 cameras of source.type v4l2 (two devices) or side_by_side (one device). The
// controls are applied alike to both cameras; an unset control keeps the device's value.
struct CamerasConfig {
    std::string left; // device path (/dev/videoN or /dev/v4l/by-id/...)
    std::string right;
    std::string device; // side_by_side: the one device
    PixelFormatChoice format = PixelFormatChoice::Auto;
    CameraColour colour = CameraColour::Left; // kept where the format has colour
    int width = 640; // px of each device's frame (side_by_side: both halves)
    int height = 480;
    double fps = 30.0; // asked frame rate
    CameraControls controls;
    bool lock_exposure = false; // manual exposure, frozen (controls.exposure_us if set)
};

// The two sensor_msgs/msg/Image topics of source.type ros2 (docs/ros2.md); the DDS domain
// and discovery are the ROS 2 node's (ROS_DOMAIN_ID, ros2.localhost_only).
struct Ros2SourceConfig {
    std::string left_topic = "/stereo/left/image_raw"; // ROS 2 topic names
    std::string right_topic = "/stereo/right/image_raw";
    // The drivers' sensor_msgs/msg/CameraInfo topics, subscribed to for the calibration when
    // none is given (`calibration`, --calib); unset ("auto"): the camera_info topic beside
    // each image topic (/stereo/left/image_raw -> /stereo/left/camera_info).
    std::optional<std::string> left_info_topic;
    std::optional<std::string> right_info_topic;
    int width = 640; // px of each image; images of another size are refused
    int height = 480;
};

// The camera_info topics source.type ros2 subscribes to when no calibration is given: the
// configured ones, else the ones beside the image topics.
std::string leftCameraInfoTopic(const Ros2SourceConfig& ros2);
std::string rightCameraInfoTopic(const Ros2SourceConfig& ros2);

struct SourceConfig {
    SourceKind kind = SourceKind::Replay;
    ReplayConfig replay;
    CamerasConfig cameras;
    Ros2SourceConfig ros2;
    int ring_capacity = 4;            // pairs queued between source and worker
    double max_skew_ms = 5.0;         // pairs further apart give no reading (out of sync)
    double stall_timeout_ms = 2000.0; // no pair for this long: the source counts as down
};

struct SocketConfig {
    std::string path = "/run/stereod/stereod.sock";
    uint32_t mode = 0660; // file mode of the socket
    std::string group;    // empty: the service's own group
    int max_clients = 64;
    uint32_t max_request_bytes = 65536;
    double idle_timeout_s = 0.0; // 0: clients may stay idle
    // Who may talk to the service, on top of the file mode: when either list is not
    // empty, a peer (by SO_PEERCRED) is served only if its uid is in allow_uids or its
    // primary or a supplementary gid is in allow_gids; others get `not_allowed`.
    std::vector<uint32_t> allow_uids;
    std::vector<uint32_t> allow_gids;
};

struct PublishConfig {
    double readings_max_hz = 0.0; // 0: every frame
    double depth_max_hz = 10.0;   // depth-frame subscribers get at most this rate
    // A subscriber whose unsent data exceed this is dropped (it still loses frames, one
    // at a time, before that).
    uint32_t max_client_backlog_bytes = 64u << 20;
    double max_reading_age_ms = 1000.0; // default for `distance` without max_age_ms
};

// The live view (docs/live-view.md): a Foxglove WebSocket server and the viewer page on
// one address.
struct LiveViewConfig {
    // "HOST:PORT" (an IP address; loopback unless the network should see the cameras), or
    // "off".
    std::string listen = "127.0.0.1:8765";
    // WebSocket clients at once (Foxglove, the page); each may hold a few MiB of frames.
    int max_clients = 16;
    // Web pages, besides the live view's own, whose browsers may connect (their Origin,
    // e.g. "https://app.foxglove.dev"); every request needs the live view's token anyway.
    std::vector<std::string> allowed_origins;
    int points_step = 4;       // every n-th point of the cloud is sent
    double max_rate_hz = 10.0; // frame channels at most this often
    // Per channel (live_view.rate_hz.*): at most this often; 0 follows max_rate_hz.
    struct Rates {
        double image = 0, depth = 0, disparity = 0, confidence = 0, points = 0, camera_info = 0,
               nearest = 0;
    } rate_hz;
};

// stereod as a ROS 2 node on DDS (docs/ros2.md). The domain comes from ROS_DOMAIN_ID.
struct Ros2Config {
    bool enabled = false;
    std::string ns = "/stereo"; // ros2.namespace: the topics' namespace
    // Discovery on the loopback interface only; false leaves it to Cyclone DDS's own
    // configuration (CYCLONEDDS_URI), unless ROS_LOCALHOST_ONLY=1 or
    // ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST keep it local.
    bool localhost_only = true;
    int points_step = 4;       // every n-th point of the cloud is published
    double max_rate_hz = 30.0; // image and cloud topics at most this often
};

// Calibration health while running (docs/configuration.md).
struct HealthConfig {
    double interval_s = 2.0;           // between checks; 0 turns them off
    bool withhold_when_failed = false; // failed: readings become calibration_suspect
};

struct ServiceConfig {
    std::string origin; // file the configuration came from, or "<defaults>"
    SourceConfig source;
    std::string calibration_path; // empty: the recording's calibration.yaml
    ProcessorSettings processing;
    HealthConfig calibration_health;
    // The camera's pose on the robot and the keep-out zones in its base frame
    // (robot.*, zones); no zones: none are watched.
    ZonesSettings zones;
    SocketConfig socket;
    PublishConfig publish;
    LiveViewConfig live_view;
    Ros2Config ros2;
    std::string log_level = "info"; // trace, debug, info, warn, error, critical, off
};

// Built-in defaults (what `stereod` runs without --config).
ServiceConfig defaultConfig();

// Reads and validates a file. Throws ConfigError with every problem found. Relative
// paths in the file (source.replay.path, calibration, socket.path) resolve against the
// file's directory.
ServiceConfig loadConfig(const std::string& path);

// The command-line overrides of `stereod` (--replay, --calib, --socket, --log-level);
// an empty string leaves the value alone. Relative paths resolve against the working
// directory.
struct ConfigOverrides {
    std::string replay_path;
    std::string calibration_path;
    std::string socket_path;
    std::string log_level;
    std::string live_view; // --live-view ADDR:PORT|off
};

// live_view.listen split into host and port; nullopt for "off". Throws
// std::invalid_argument naming what is wrong with the text.
struct ListenAddress {
    std::string host;
    uint16_t port = 0;
};
std::optional<ListenAddress> parseListenAddress(const std::string& text);
// HOST:PORT as parseListenAddress() reads it back, with an IPv6 host in brackets
// ("[::1]:8765"): also the authority part of a URL.
std::string formatListenAddress(const std::string& host, uint16_t port);
// True for a host only this machine reaches (127.0.0.0/8, ::1).
bool isLoopbackHost(const std::string& host);

// Reads a file, applies the overrides, then validates the result, so that a file whose
// replay path does not exist on this machine still runs with --replay. Problems with an
// overridden value name the option ("command line (--replay): source.replay.path: ...").
// Use the same overrides on `reload`, or they show up as changes.
ServiceConfig loadConfig(const std::string& path, const ConfigOverrides& overrides);

// Applies the overrides to a configuration assembled in code (e.g. defaultConfig());
// validateConfig() checks the result.
void applyOverrides(ServiceConfig& config, const ConfigOverrides& overrides);

// Reads and validates YAML text like loadConfig(); `origin` names it in messages.
// Without a file, relative paths stay relative to the working directory.
ServiceConfig parseConfig(const std::string& yaml_text, const std::string& origin);

// Checks a configuration assembled in code (defaults plus command-line overrides).
// Throws ConfigError with every problem found. With the overrides that were applied, a
// problem with an overridden value names the option ("command line (--live-view):
// live_view.listen: ..."), as loadConfig() does, instead of "<defaults>".
void validateConfig(const ServiceConfig& config);
void validateConfig(const ServiceConfig& config, const ConfigOverrides& overrides);

// Which settings differ between two configurations and whether all of them can change
// while running, as the dotted keys of the file ("nearest.roi.x", ...). Those that need
// a restart (source.*, calibration, socket.*) are also listed in `restart_needed`.
// The parts of a running service that live keys reach; a reload hands each part whose
// keys changed over as a whole (unchanged values in it stay what they were).
enum class LivePart {
    Processing,        // matcher.*, nearest.*, output.*, point_cloud
    Publish,           // publish.*
    LogLevel,          // log_level
    CalibrationHealth, // calibration_health.interval_s, withhold_when_failed
    Zones,             // robot.*, zones
};

// The part a live key reaches; none for a key that is not live (or one a part has not
// been given yet: diffConfig() then says it needs a restart, which is the truth).
std::optional<LivePart> livePartOf(std::string_view key);

struct ConfigChange {
    std::vector<std::string> changed;
    std::vector<std::string> restart_needed; // of changed, the keys that are not live
    std::vector<LivePart> live_parts;        // each part of changed's live keys, once
};
ConfigChange diffConfig(const ServiceConfig& running, const ServiceConfig& proposed);

// Every key of the file format, as a dotted path in the order of the reference config
// (config/examples/stereod.yaml), and whether it can change while running.
struct ConfigKeyInfo {
    std::string path;
    bool live = false;
};
std::vector<ConfigKeyInfo> configKeys();

} // namespace stereod
