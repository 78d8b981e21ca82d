#pragma once
// From what `stereod` was asked to run to a Service ready to run: the configuration (file
// or built-in defaults, with the command line's overrides), the frame source, and the
// calibration found for it; and the same checks alone for `stereod --check-config`.
//
// Reentrant: no state of its own (the log level is set process-wide).

#include <memory>
#include <string>

#include "config/service_config.hpp"
#include "daemon/service.hpp"

namespace stereod {

// `stereod --check-config FILE`: the checks of start-up that need neither a running source
// nor the socket. The file and its values (throws ConfigError with every problem), the
// calibration it names or the recording's calibration.yaml (StartupError: Calibration),
// and the processing settings against that calibration, as the stereo chain will check
// them (StartupError: InvalidConfig). Returns the calibration checked against, or empty
// when none is named.
std::string checkConfiguration(const std::string& path);

// What `stereod` was asked to run, from its command line.
struct LaunchRequest {
    std::string config_path; // empty: built-in defaults
    ConfigOverrides overrides;
};

// Reads the configuration (file or defaults) with the overrides and validates it; opens
// the replay; finds and loads the calibration (--calib, the file's `calibration`, or the
// recording's calibration.yaml; none of them: uncalibrated mode); builds the service.
// Throws StartupError with the exit code for the problem (a calibration that is given but
// unreadable, invalid or not the frame size among them).
std::unique_ptr<Service> launchService(const LaunchRequest& request);

} // namespace stereod
