// stereoctl: the command-line client of stereod and its offline tools (docs/stereoctl.md).
// This file declares the command line; ctl/*_commands.cpp do the work.

#include <csignal>
#include <cstdio>
#include <exception>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "ctl/client.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "pipeline/matcher_settings.hpp"

namespace stereod {

namespace {

// A number > 0; CLI11's own PositiveNumber prints the whole double range in its message.
const CLI::Validator kPositive(
    [](std::string& input) -> std::string {
        double value = 0.0;
        if (!CLI::detail::lexical_cast(input, value)) {
            return "expected a number, got '" + input + "'";
        }
        if (!(value > 0.0)) {
            return "must be greater than 0, got " + input;
        }
        return {};
    },
    "> 0");

// CLI11 errors as one line (CLI11's default adds a second, "Run with --help ...").
std::string oneLineFailure(const CLI::App*, const CLI::Error& error)
{
    return fmt::format("stereoctl: {} (see --help)\n", error.what());
}

// The socket path of a command that talks to the service: its own --socket option and the
// options it fills.
struct CommandSocket {
    const CLI::Option* option = nullptr;
    ConnectionOptions* service = nullptr;
};
using CommandSockets = std::vector<CommandSocket>;

const char* const kSocketHelp =
    "the service's Unix socket (also before the command, or from STEREOD_SOCKET)";

// --socket on a command. It takes no value from the environment itself: STEREOD_SOCKET
// belongs to the application's --socket (before the command), which this one overrides
// (resolveSockets).
CLI::Option* addSocketOption(CLI::App* command, ConnectionOptions& options, const char* help,
                             CommandSockets& sockets)
{
    CLI::Option* option =
        command->add_option("--socket", options.socket_path, help)->capture_default_str();
    sockets.push_back({option, &options});
    return option;
}

// Where each command's socket comes from, first found: its own --socket (after the
// command), --socket before the command, STEREOD_SOCKET, the default.
void resolveSockets(const CLI::Option& global_option, const std::string& global_path,
                    const CommandSockets& sockets)
{
    if (global_option.count() == 0) {
        return;
    }
    for (const CommandSocket& socket : sockets) {
        if (socket.option->count() == 0) {
            socket.service->socket_path = global_path;
        }
    }
}

// A command that talks to the service: --socket, --timeout-ms, and --json when `json` is
// given.
CLI::App* addServiceCommand(CLI::App& app, const char* name, const char* description,
                            ConnectionOptions& options, CommandSockets& sockets,
                            bool* json = nullptr, const char* json_help = nullptr)
{
    CLI::App* command = app.add_subcommand(name, description);
    addSocketOption(command, options, kSocketHelp, sockets);
    command->add_option("--timeout-ms", options.timeout_ms, "limit on each wait for the service")
        ->check(kPositive)
        ->capture_default_str();
    if (json != nullptr) {
        command->add_flag("--json", *json, json_help);
    }
    return command;
}

// --rectified and the geometry options, which need it and which it needs (focal length
// and baseline). Returns the --rectified flag.
CLI::Option* addRectifiedOptions(CLI::App* cmd, RectifiedOptions& o, const char* what)
{
    CLI::Option* rectified = cmd->add_flag("--rectified", o.rectified, what);
    CLI::Option* focal =
        cmd->add_option("--focal-px", o.focal_px, "rectified focal length (px)")->check(kPositive);
    CLI::Option* baseline =
        cmd->add_option("--baseline-m", o.baseline_m, "baseline (m)")->check(kPositive);
    CLI::Option* cx = cmd->add_option("--cx", o.cx_px, "principal point x (px; default: centre)");
    CLI::Option* cy = cmd->add_option("--cy", o.cy_px, "principal point y (px; default: centre)");
    CLI::Option* doffs =
        cmd->add_option("--doffs-px", o.doffs_px, "right minus left principal point x (px)");
    rectified->needs(focal)->needs(baseline);
    for (CLI::Option* geometry : {focal, baseline, cx, cy, doffs}) {
        geometry->needs(rectified);
    }
    return rectified;
}

struct Options {
    DistanceOptions distance;
    StatusOptions status;
    StatusOptions view;
    WatchOptions watch;
    SnapshotOptions snapshot;
    DepthOptions depth;
    CalibrateOptions calibrate;
    ExportRosOptions export_ros;
    BoardDistanceOptions board_distance;
    DevicesOptions devices;
    RecordOptions record;
    CheckCalibrationOptions check_calibration;
    ZonesOptions zones;
};

CLI::App* declareRecord(CLI::App& app, RecordOptions& o, CommandSockets& sockets)
{
    CLI::App* cmd = addServiceCommand(
        app, "record",
        "record the service's raw pairs as a recording (a directory: frames.csv, left/, "
        "right/, calibration.yaml; or FILE.mcap: a ROS 2 bag) until --frames, Ctrl-C or the "
        "service ends (exit 0 done, 2 cannot write, 3 service gone)",
        o.service, sockets, &o.json, "print the summary as JSON");
    cmd->add_option("--out", o.out_dir,
                    "recording directory to create (new or empty), or a new FILE.mcap")
        ->required();
    cmd->add_option("--frames", o.frames, "stop after this many pairs")
        ->check(CLI::Range(uint64_t{1}, std::numeric_limits<uint64_t>::max()));
    cmd->add_option("--with", o.with,
                    "with FILE.mcap: also record the service's results of each pair, a "
                    "comma-separated list of: depth (/stereo/depth, 32FC1 metres), points "
                    "(/stereo/points, PointCloud2)")
        ->delimiter(',');
    cmd->add_option("--queue", o.queue_pairs,
                    "pairs held between the socket and the disk; more are dropped and counted")
        ->check(CLI::Range(std::size_t{1}, std::size_t{4096}))
        ->capture_default_str();
    return cmd;
}

CLI::App* declareDistance(CLI::App& app, DistanceOptions& o, CommandSockets& sockets)
{
    CLI::App* cmd = addServiceCommand(
        app, "distance",
        "the nearest-object distance now (exit 0 valid, 1 no reading in range, 2 stale or not "
        "producing, 3 service unreachable, 4 valid but the calibration is suspect)",
        o.service, sockets, &o.json, "print the reading object as JSON");
    cmd->add_option("--max-age-ms", o.max_age_ms, "refuse a reading older than this (ms)")
        ->check(kPositive);
    return cmd;
}

CLI::App* declareSnapshot(CLI::App& app, SnapshotOptions& o, CommandSockets& sockets)
{
    CLI::App* cmd = addServiceCommand(
        app, "snapshot", "write the service's latest result to files (at least one option)",
        o.service, sockets);
    cmd->add_option("--depth", o.depth_path, "depth as PNG, uint16 millimetres (0 = invalid)");
    cmd->add_option("--disparity", o.disparity_path,
                    "disparity as .pfm (float, inf = invalid) or .png (uint16 x256)");
    cmd->add_option("--cloud", o.cloud_path,
                    "point cloud as binary .ply (x y z metres, "
                    "intensity)");
    cmd->add_option("--colormap", o.colormap_path, "colourised depth as PNG (near warm, far cool)");
    cmd->add_option("--left", o.left_path, "the rectified left image as PNG");
    cmd->add_option("--confidence", o.confidence_path,
                    "the per-pixel match confidence as PNG (0 = no disparity, 1..255)");
    return cmd;
}

CLI::App* declareDepth(CLI::App& app, DepthOptions& o)
{
    CLI::App* cmd = app.add_subcommand(
        "depth", "run one stereo pair through the service's pipeline, offline (exit 0 reading, "
                 "1 no reading, 2 bad arguments or files)");
    cmd->add_option("LEFT", o.left_path, "left image")->required();
    cmd->add_option("RIGHT", o.right_path, "right image")->required();
    CLI::Option* calib = cmd->add_option("--calib", o.calib_path, "calibration file (YAML)");
    CLI::Option* rectified =
        addRectifiedOptions(cmd, o.geometry, "the pair is rectified; give its geometry");
    calib->excludes(rectified);
    cmd->add_option("--config", o.config_path,
                    "take the processing settings from this service configuration");
    std::vector<std::string> algorithms;
    for (const stereod::MatcherAlgorithm& algorithm : stereod::kMatcherAlgorithms)
        algorithms.emplace_back(algorithm.name);
    cmd->add_option("--matcher", o.matcher,
                    "our census-sgm (the default), or OpenCV's sgbm, sgbm-3way, sgbm-hh, "
                    "sgbm-hh4 or bm")
        ->check(CLI::IsMember(algorithms));
    cmd->add_option("--tuning", o.tuning,
                    "census-sgm's tuning: natural (textured scenes, the default), planar "
                    "(man-made: uniform flat surfaces, repeating patterns) or patterns "
                    "(natural, and planar's steps where a pattern repeats along the rows)")
        ->check(CLI::IsMember(kMatcherTunings.names()));
    cmd->add_option("--max-disparity", o.max_disparity,
                    "disparities searched, rounded up to a multiple of 16 (instead of deriving "
                    "them from the closest depth)")
        ->check(kPositive);
    cmd->add_option("--min-depth-m", o.min_depth_m,
                    "closest depth to see (m); sets the disparity range")
        ->check(kPositive);
    cmd->add_option("--roi", o.roi,
                    "region for the nearest object: x,y,w,h fractions of the "
                    "image");
    cmd->add_option("--disparity", o.disparity_path, "write the disparity (.pfm or .png)");
    cmd->add_option("--depth", o.depth_path, "write the depth (.png, uint16 mm)");
    cmd->add_option("--cloud", o.cloud_path, "write the point cloud (.ply)");
    cmd->add_option("--colormap", o.colormap_path, "write the colourised depth (.png)");
    cmd->add_option("--confidence", o.confidence_path,
                    "write the per-pixel match confidence (.png, 0 = no disparity, 1..255)");
    cmd->add_flag("--json", o.json,
                  "print the reading, stage timings, disparity range and matcher as JSON");
    return cmd;
}

CLI::App* declareCalibrate(CLI::App& app, CalibrateOptions& o, CommandSockets& sockets)
{
    CLI::App* cmd = app.add_subcommand(
        "calibrate", "write a calibration file: from chessboard pairs (--left --right --board "
                     "--square-m), for a rectified rig (--rectified), or from ROS or OpenCV "
                     "files (--from-ros, --from-opencv)");
    CLI::Option* rectified =
        addRectifiedOptions(cmd, o.geometry, "a rig or dataset that delivers rectified pairs");
    CLI::Option* size = cmd->add_option("--size", o.size, "image size WxH (px)");
    cmd->add_option("--out", o.out_path, "calibration file to write (YAML)")->required();

    CLI::Option* left = cmd->add_option(
        "--left", o.left_glob, "left chessboard images: a glob, quoted (e.g. 'left*.png'), sorted");
    CLI::Option* right =
        cmd->add_option("--right", o.right_glob, "right chessboard images, paired in sorted order");
    CLI::Option* board = cmd->add_option("--board", o.board,
                                         "inner corners COLSxROWS, as OpenCV counts them (a board "
                                         "of 10x7 squares is 9x6)");
    CLI::Option* square =
        cmd->add_option("--square-m", o.square_m, "side of one square (m)")->check(kPositive);
    CLI::Option* preview =
        cmd->add_option("--preview", o.preview_path,
                        "write the first pair rectified side by side with row lines "
                        "(PNG)");
    CLI::Option* alpha = cmd->add_option("--alpha", o.alpha,
                                         "rectified scale: 0 crops to pixels with image data, 1 "
                                         "keeps every raw pixel")
                             ->check(CLI::Range(0.0, 1.0))
                             ->capture_default_str();
    CLI::Option* min_pairs =
        cmd->add_option("--min-pairs", o.min_pairs, "fewest usable pairs to calibrate from")
            ->check(CLI::Range(3, 1000))
            ->capture_default_str();
    CLI::Option* json = cmd->add_flag("--json", o.json,
                                      "print rms_px, epipolar_error_px, pairs_used, "
                                      "pairs_rejected, baseline_m and the per-pair table as JSON");
    // The chessboard forms: images from files (--left --right), or --live from the service.
    CLI::Option* live = cmd->add_flag("--live", o.live,
                                      "collect the chessboard pairs from the running service's "
                                      "raw frames (needs --count, --board, --square-m)");
    CLI::Option* count =
        cmd->add_option("--count", o.count, "with --live: accepted pairs to collect")
            ->check(CLI::Range(3, 1000));
    addSocketOption(cmd, o.service,
                    "with --live: the service's Unix socket (also before the command, or from "
                    "STEREOD_SOCKET)",
                    sockets);
    CLI::Option* timeout_ms = cmd->add_option("--timeout-ms", o.service.timeout_ms,
                                              "with --live: limit on each wait for the service")
                                  ->check(kPositive)
                                  ->capture_default_str();
    CLI::Option* save_pairs = cmd->add_option(
        "--save-pairs", o.save_pairs_dir,
        "with --live: directory for the accepted pairs, left_NNN.png and right_NNN.png "
        "(default: beside --out, OUT-pairs/)");
    CLI::Option* timeout_s =
        cmd->add_option(
               "--timeout-s", o.timeout_s,
               "with --live: stop collecting after this long and calibrate with the pairs accepted "
               "(default: until --count pairs or Ctrl-C)")
            ->check(kPositive);
    CLI::Option* max_hz = cmd->add_option("--max-hz", o.max_hz,
                                          "with --live: raw pairs asked of the service per "
                                          "second")
                              ->check(kPositive)
                              ->capture_default_str();
    live->needs(count)->needs(board)->needs(square);
    for (CLI::Option* live_only : {count, timeout_ms, save_pairs, timeout_s, max_hz}) {
        live_only->needs(live);
    }
    left->needs(right)->needs(board)->needs(square);
    right->needs(left);
    board->needs(square);
    square->needs(board);

    CLI::Option* from_ros = cmd->add_option("--from-ros", o.from_ros,
                                            "import a ROS camera_info pair: LEFT.yaml "
                                            "RIGHT.yaml")
                                ->expected(2);
    CLI::Option* from_opencv =
        cmd->add_option("--from-opencv", o.from_opencv,
                        "import OpenCV stereo_calib output: INTRINSICS.yml EXTRINSICS.yml "
                        "(needs --size)")
            ->expected(2);
    CLI::Option* unit = cmd->add_option("--unit-m", o.unit_m,
                                        "with --from-opencv: metres per unit of its T (the "
                                        "square size given to stereo_calib's -s)")
                            ->check(kPositive);
    unit->needs(from_opencv);
    from_opencv->needs(size);
    // One form at a time; --size belongs to --rectified and --from-opencv.
    const std::vector<CLI::Option*> forms = {rectified, left, live, from_ros, from_opencv};
    for (CLI::Option* form : forms) {
        for (CLI::Option* other : forms) {
            if (other != form) {
                form->excludes(other);
            }
        }
    }
    rectified->needs(size);
    for (CLI::Option* not_sized : {left, live, from_ros}) {
        size->excludes(not_sized);
    }
    cmd->callback([cmd, rectified, left, live, from_ros, from_opencv, board, preview, alpha,
                   min_pairs, json] {
        if (rectified->count() + left->count() + live->count() + from_ros->count() +
                from_opencv->count() ==
            0) {
            throw CLI::ValidationError(
                cmd->get_name(), "give one form: --left/--right/--board/--square-m (chessboard), "
                                 "--live --count/--board/--square-m (chessboard from the "
                                 "service), --rectified, --from-ros or --from-opencv");
        }
        // The chessboard options belong to the two chessboard forms.
        if (left->count() + live->count() == 0) {
            for (CLI::Option* chessboard_only : {board, preview, alpha, min_pairs, json}) {
                if (chessboard_only->count() > 0) {
                    throw CLI::ValidationError(chessboard_only->get_name(),
                                               "belongs to a chessboard calibration: --left "
                                               "--right or --live");
                }
            }
        }
    });
    return cmd;
}

CLI::App* declareExportRos(CLI::App& app, ExportRosOptions& o)
{
    CLI::App* cmd = app.add_subcommand(
        "export-ros", "write a calibration file as a ROS camera_info pair (left.yaml, right.yaml)");
    cmd->add_option("--calib", o.calib_path, "calibration file (YAML)")->required();
    cmd->add_option("--left", o.left_path, "left camera_info file to write")->required();
    cmd->add_option("--right", o.right_path, "right camera_info file to write")->required();
    cmd->add_option("--camera-name", o.camera_name, "camera_name prefix: NAME/left and NAME/right")
        ->capture_default_str();
    return cmd;
}

CLI::App* declareBoardDistance(CLI::App& app, BoardDistanceOptions& o)
{
    CLI::App* cmd = app.add_subcommand(
        "board-distance", "how far the chessboard in a raw left image is by its pose "
                          "(solvePnP), over the nearest-object region (exit 0 distance, 1 no "
                          "board in the region)");
    cmd->add_option("LEFT", o.left_path, "raw left image")->required();
    cmd->add_option("--calib", o.calib_path, "full calibration recording its board (YAML)")
        ->required();
    cmd->add_option("--config", o.config_path,
                    "take the region and percentile from this service configuration");
    cmd->add_flag("--json", o.json, "print the board's distance as JSON");
    return cmd;
}

CLI::App* declareCheckCalibration(CLI::App& app, CheckCalibrationOptions& o,
                                  CommandSockets& sockets)
{
    CLI::App* cmd = app.add_subcommand(
        "check-calibration",
        "how well a calibration still rectifies the rig's pairs, or (without --left) the "
        "running service's cameras: the row offset of matching features after "
        "rectification, a model of it over the image fitted to them, offset and roll "
        "(exit 0 ok, 1 degraded or failed, 2 no verdict, 3 no service)");
    CLI::Option* left =
        cmd->add_option("--left", o.left_glob, "raw left images: a glob, quoted, sorted");
    CLI::Option* right =
        cmd->add_option("--right", o.right_glob, "raw right images, paired in sorted order");
    CLI::Option* calib =
        cmd->add_option("--calib", o.calib_path,
                        "the calibration to check (YAML): full, or rectified-only for a camera "
                        "that delivers rectified pairs (they are checked as they come)");
    CLI::Option* socket =
        addSocketOption(cmd, o.service,
                        "without --left/--right/--calib: the running service's figures (its "
                        "calibration_health), from this socket (also before the command, or from "
                        "STEREOD_SOCKET)",
                        sockets);
    left->needs(right)->needs(calib)->excludes(socket);
    right->needs(left);
    calib->needs(left);
    CLI::Option* fix = cmd->add_flag(
        "--fix", o.fix,
        "estimate the small turn of the right camera that brings the rows back, and write "
        "the corrected calibration to --out (never to the checked file; a full calibration "
        "also when the checked one is rectified-only)");
    cmd->add_option("--out", o.out_path, "where --fix writes the corrected calibration (new file)")
        ->needs(fix);
    fix->needs(cmd->get_option("--out"));
    fix->needs(left);
    cmd->add_flag("--json", o.json, "print the figures per pair and overall as JSON");
    return cmd;
}

CLI::App* declareZones(CLI::App& app, ZonesOptions& o, CommandSockets& sockets)
{
    CLI::App* cmd = addServiceCommand(
        app, "zones",
        "the keep-out zones in the robot's frame: occupied, clear or unknown, the nearest point "
        "in each (exit 0 all clear, 1 any occupied, 2 unknown or stale, 3 no service)",
        o.service, sockets, &o.json, "print the zones as JSON");
    cmd->add_flag("--watch", o.watch, "one block per frame until interrupted (Ctrl-C)");
    cmd->add_option("--picture", o.picture_path,
                    "draw the zones, coloured by state, on the colourised depth of the latest "
                    "frame (.png)");
    cmd->add_option("--max-age-ms", o.max_age_ms, "zones older than this count as unknown")
        ->check(kPositive)
        ->capture_default_str();
    return cmd;
}

CLI::App* declareDevices(CLI::App& app, DevicesOptions& o)
{
    CLI::App* cmd = app.add_subcommand(
        "devices", "list the V4L2 cameras: formats, sizes, frame rates and stable "
                   "/dev/v4l/by-id paths (exit 1 when none is found)");
    cmd->add_flag("--json", o.json, "print the list as JSON");
    return cmd;
}

} // namespace

} // namespace stereod

int main(int argc, char** argv)
{
    using namespace stereod;
    // A file that reaches the size limit (ulimit -f) must fail its write with EFBIG, which
    // the command reports with what it wrote, rather than kill the process (SIGXFSZ) with
    // no word and the recording's count lost.
    std::signal(SIGXFSZ, SIG_IGN);
    CLI::App app("stereoctl: client and offline tools of the stereod stereo depth service",
                 "stereoctl");
    app.failure_message(oneLineFailure);
    app.require_subcommand(0, 1);
    Options o;
    // --socket before the command, as git, docker and systemctl take their global options;
    // the commands that do not talk to the service ignore it.
    std::string global_socket;
    CLI::Option* global_socket_option =
        app.add_option("--socket", global_socket,
                       "the service's Unix socket, for every command that talks to the service "
                       "(also from STEREOD_SOCKET; a command's own --socket wins)")
            ->envname("STEREOD_SOCKET");
    CommandSockets sockets;
    const std::vector<std::pair<CLI::App*, std::function<int()>>> commands = {
        {declareDistance(app, o.distance, sockets), [&] { return runDistance(o.distance); }},
        {addServiceCommand(app, "status",
                           "source state per camera, fps, dropped frames, pairing skew, "
                           "per-stage latency, clients",
                           o.status.service, sockets, &o.status.json,
                           "print the service's status object as JSON"),
         [&] { return runStatus(o.status); }},
        {addServiceCommand(app, "view",
                           "print the live view's addresses with its token (the viewer page, "
                           "Foxglove's WebSocket) and open a browser on the page when there is "
                           "a display",
                           o.view.service, sockets),
         [&] { return runView(o.view); }},
        {addServiceCommand(app, "watch", "one line per new reading until interrupted (Ctrl-C)",
                           o.watch.service, sockets, &o.watch.json,
                           "print each reading event as one JSON line"),
         [&] { return runWatch(o.watch); }},
        {declareSnapshot(app, o.snapshot, sockets), [&] { return runSnapshot(o.snapshot); }},
        {declareDepth(app, o.depth), [&] { return runDepth(o.depth); }},
        {declareCalibrate(app, o.calibrate, sockets), [&] { return runCalibrate(o.calibrate); }},
        {declareExportRos(app, o.export_ros), [&] { return runExportRos(o.export_ros); }},
        {declareBoardDistance(app, o.board_distance),
         [&] { return runBoardDistance(o.board_distance); }},
        {declareDevices(app, o.devices), [&] { return runDevices(o.devices); }},
        {declareRecord(app, o.record, sockets), [&] { return runRecord(o.record); }},
        {declareCheckCalibration(app, o.check_calibration, sockets),
         [&] { return runCheckCalibration(o.check_calibration); }},
        {declareZones(app, o.zones, sockets), [&] { return runZones(o.zones); }},
    };

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& error) {
        const int code = app.exit(error);
        return code == 0 ? kExitOk : kExitUsage;
    }
    resolveSockets(*global_socket_option, global_socket, sockets);

    try {
        for (const auto& [command, run] : commands) {
            if (command->parsed()) {
                return run();
            }
        }
        std::fputs(app.help().c_str(), stderr);
        return kExitUsage;
    } catch (const ClientError& error) {
        fmt::print(stderr, "stereoctl: {}\n", error.what());
        return kExitUnreachable;
    } catch (const nlohmann::ordered_json::exception& error) {
        // A reply with a field of the wrong type: the peer does not speak this protocol.
        fmt::print(stderr,
                   "stereoctl: the reply from the service does not follow the protocol: "
                   "{}\n",
                   error.what());
        return kExitUnreachable;
    } catch (const ServiceError& error) {
        fmt::print(stderr, "stereoctl: the service refused the request: {}\n", error.what());
        return kExitNotProducing;
    } catch (const std::exception& error) {
        // Bad arguments found after parsing (UsageError), calibration and configuration
        // files that cannot be used, files that cannot be written, settings the pipeline
        // refuses: all named by the thrower.
        fmt::print(stderr, "stereoctl: {}\n", error.what());
        return kExitUsage;
    }
}
