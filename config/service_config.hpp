#pragma once
// The service configuration (YAML). Every value is validated with its unit and range;
// an error names the key and the file:line. Format and defaults: docs/configuration.md
// and config/examples/.

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "pipeline/stereo_processor.hpp"

namespace stereod {

// Every problem found in a configuration, each one "FILE:LINE: key: problem".
class ConfigError : public std::runtime_error {
public:
    explicit ConfigError(std::vector<std::string> problems);
    const std::vector<std::string>& problems() const noexcept { return problems_; }

private:
    std::vector<std::string> problems_;
};

enum class SourceKind { Replay };          // cameras come with the V4L2 backend
enum class ReplayPacing {
    Paced,     // frames delivered at their recorded times, like real cameras
    Lockstep,  // as fast as the worker consumes, nothing dropped, repeatable
};

struct ReplayConfig {
    std::string path;                 // a recording directory or a folder of left*/right*
    ReplayPacing pacing = ReplayPacing::Paced;
    double fps = 10.0;                // nominal rate for plain folders (no frames.csv)
    bool loop = true;
};

struct SourceConfig {
    SourceKind kind = SourceKind::Replay;
    ReplayConfig replay;
    int ring_capacity = 4;            // pairs queued between source and worker
    double max_skew_ms = 5.0;         // pairs further apart give no reading (out of sync)
    double stall_timeout_ms = 2000.0; // no pair for this long: the source counts as down
};

struct SocketConfig {
    std::string path = "/run/stereod/stereod.sock";
    uint32_t mode = 0660;             // file mode of the socket
    std::string group;                // empty: the service's own group
    int max_clients = 64;
    uint32_t max_request_bytes = 65536;
    double idle_timeout_s = 0.0;      // 0: clients may stay idle
};

struct PublishConfig {
    double readings_max_hz = 0.0;     // 0: every frame
    double depth_max_hz = 10.0;       // depth-frame subscribers get at most this rate
    // A subscriber whose unsent data exceed this is dropped (it still loses frames, one
    // at a time, before that).
    uint32_t max_client_backlog_bytes = 64u << 20;
    double max_reading_age_ms = 1000.0;   // default for `distance` without max_age_ms
};

struct ServiceConfig {
    std::string origin;               // file the configuration came from, or "<defaults>"
    SourceConfig source;
    std::string calibration_path;     // empty: the recording's calibration.yaml
    ProcessorSettings processing;
    SocketConfig socket;
    PublishConfig publish;
    std::string log_level = "info";   // trace, debug, info, warn, error, critical, off
};

// Built-in defaults (what `stereod` runs without --config).
ServiceConfig defaultConfig();

// Reads and validates a file. Throws ConfigError with every problem found.
ServiceConfig loadConfig(const std::string& path);

// The same for YAML text; `origin` names it in messages.
ServiceConfig parseConfig(const std::string& yaml_text, const std::string& origin);

// Checks a configuration assembled in code (defaults plus command-line overrides).
// Throws ConfigError with every problem found.
void validateConfig(const ServiceConfig& config);

// Which settings differ between two configurations and whether all of them can change
// while running ("processing.nearest.roi", ...). Those that need a restart are listed
// in `restart_needed`.
struct ConfigChange {
    std::vector<std::string> changed;
    std::vector<std::string> restart_needed;
};
ConfigChange diffConfig(const ServiceConfig& running, const ServiceConfig& proposed);

} // namespace stereod
