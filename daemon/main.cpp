// stereod: the stereo depth service. Command line and exit codes: docs/service.md.

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "capture/device_list.hpp"
#include "config/service_config.hpp"
#include "daemon/service.hpp"
#include "daemon/service_launch.hpp"
#include "daemon/signal_watch.hpp"

namespace {

using stereod::ExitCode;

// Runs before the initialisers of the shared libraries (OpenCV's take a good part of a
// second on a loaded machine), so that a SIGTERM that early finds the service's signals
// blocked and waits for the SignalWatch, instead of ending the process with 143.
// Every thread created later inherits the mask.
void blockSignalsBeforeLibraries(int, char**, char**)
{
    stereod::blockServiceSignals();
}

[[gnu::section(".preinit_array"),
  gnu::used]] void (*const kBlockSignalsEarly)(int, char**, char**) = &blockSignalsBeforeLibraries;

int exitCode(ExitCode code)
{
    return static_cast<int>(code);
}

// `stereod --check-config FILE`: every problem on its own line, file:line first.
int checkConfig(const std::string& path)
{
    std::string calibration_path;
    try {
        calibration_path = stereod::checkConfiguration(path);
    } catch (const stereod::ConfigError& e) {
        for (const std::string& problem : e.problems())
            std::cerr << problem << '\n';
        return exitCode(stereod::exitCodeFor(e));
    } catch (const stereod::StartupError& e) {
        std::cerr << e.what() << '\n';
        return exitCode(e.code());
    } catch (const std::exception& e) {
        std::cerr << path << ": " << e.what() << '\n';
        return exitCode(ExitCode::InvalidConfig);
    }
    if (calibration_path.empty())
        std::cout << path
                  << ": valid (no calibration named: the processing settings are "
                     "checked against the frames at start-up)\n";
    else
        std::cout << path << ": valid with the calibration " << calibration_path << '\n';
    return exitCode(ExitCode::Ok);
}

void setUpLogging()
{
    auto logger = spdlog::stderr_color_mt("stereod");
    // Under systemd the journal stamps every line itself.
    if (std::getenv("JOURNAL_STREAM") != nullptr)
        logger->set_pattern("[%l] %v");
    else
        logger->set_pattern("%Y-%m-%d %H:%M:%S.%e [%l] %v");
    spdlog::set_default_logger(logger);
}

} // namespace

int main(int argc, char** argv)
{
    // Blocked already (blockSignalsBeforeLibraries()); again here in case the loader did
    // not run .preinit_array. Before any thread exists, so that every thread inherits
    // the mask: these signals are taken by the SignalWatch alone, never by an asynchronous
    // handler.
    stereod::blockServiceSignals();
    // A client that hangs up while we write must not kill the service (sends also use
    // MSG_NOSIGNAL; this covers every other write).
    signal(SIGPIPE, SIG_IGN);

    CLI::App app{"stereod: stereo depth service. Serves the nearest-object distance, depth "
                 "frames and point clouds on a Unix socket (docs/protocol.md).",
                 "stereod"};
    stereod::LaunchRequest request;
    std::string check_path;
    bool list_devices = false;
    app.set_version_flag("--version", stereod::serviceVersion());
    auto* config_option = app.add_option("--config", request.config_path,
                                         "configuration file (YAML); without it, built-in "
                                         "defaults apply");
    auto* check_option = app.add_option("--check-config", check_path,
                                        "validate FILE, print every problem (file:line), "
                                        "and exit: 0 valid, 3 invalid");
    auto* replay_option = app.add_option("--replay", request.overrides.replay_path,
                                         "replay this recording: a directory (frames.csv, or "
                                         "a folder of left*/right* images) or a ROS 2 bag "
                                         "(FILE.mcap, two image topics)");
    auto* calib_option = app.add_option("--calib", request.overrides.calibration_path,
                                        "calibration file (default: the configuration's, "
                                        "or DIR/calibration.yaml, or a bag's camera_info, of "
                                        "the replay)");
    auto* socket_option = app.add_option("--socket", request.overrides.socket_path,
                                         "Unix socket path (default /run/stereod/stereod.sock)");
    // An empty path would silently mean "not given" further on (`--socket ""` would bind
    // the default path): refused here.
    const CLI::Validator non_empty_path(
        [](std::string& value) {
            return value.empty()
                       ? std::string("an empty path; leave the option out for the default")
                       : std::string();
        },
        "PATH");
    for (CLI::Option* option :
         {config_option, check_option, replay_option, calib_option, socket_option})
        option->check(non_empty_path);
    auto* level_option =
        app.add_option("--log-level", request.overrides.log_level, "log level")
            ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}));
    auto* live_view_option =
        app.add_option("--live-view", request.overrides.live_view,
                       "live view address HOST:PORT (Foxglove WebSocket and the viewer page; "
                       "default 127.0.0.1:8765), or off")
            ->check(non_empty_path);
    check_option->excludes(config_option, replay_option, calib_option, socket_option, level_option,
                           live_view_option);
    auto* list_option = app.add_flag("--list-devices", list_devices,
                                     "list the V4L2 cameras (formats, sizes, frame rates, "
                                     "/dev/v4l/by-id paths) and exit: 0 found, 1 none");
    list_option->excludes(config_option, check_option, replay_option, calib_option, socket_option,
                          level_option);
    app.footer("Exit codes: 0 ok; 1 failure while running; 2 bad arguments; 3 invalid "
               "configuration; 4 calibration problem; 5 source problem; 6 socket problem.");

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0)
            return app.exit(e); // --help, --version
        std::cerr << "stereod: " << e.what() << " (see stereod --help)\n";
        return exitCode(ExitCode::BadArguments);
    }

    // From here on SIGTERM and SIGINT stop the process within a second whatever it is
    // doing, a start-up blocked in an open() included, and SIGHUP reloads once the service
    // runs (daemon/signal_watch.hpp).
    setUpLogging();
    stereod::SignalWatch signals;
    if (!check_path.empty())
        return checkConfig(check_path);
    if (list_devices) {
        const stereod::DeviceList devices = stereod::listCaptureDevices();
        std::cout << stereod::formatDeviceList(devices);
        return devices.devices.empty() ? exitCode(ExitCode::Failure) : exitCode(ExitCode::Ok);
    }

    try {
        std::unique_ptr<stereod::Service> service = stereod::launchService(request);
        signals.setService(service.get());
        ExitCode code = ExitCode::Ok;
        try {
            code = service->run();
        } catch (...) {
            signals.setService(nullptr);
            throw;
        }
        signals.setService(nullptr);
        // The worker is still inside a pair that would outlast the stop: end now, without
        // the destructors that would wait for it (docs/service.md, Signals).
        if (service->workerAbandoned())
            stereod::abandonProcess(exitCode(code));
        return exitCode(code);
    } catch (const stereod::StartupError& e) {
        spdlog::critical("{}", e.what());
        return exitCode(e.code());
    } catch (const std::exception& e) {
        spdlog::critical("{}", e.what());
        return exitCode(ExitCode::Failure);
    }
}
