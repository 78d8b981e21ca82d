#pragma once
// The subcommands of `stereoctl`, each a function from its parsed options to an exit code
// (ctl/exit_codes.hpp). main.cpp declares the command line; these do the work and print.
//
// Reentrant, except that `watch` changes the process's signal mask while it runs.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core/types.hpp>

namespace stereod {

// A problem with the arguments that the command-line parser cannot see (a malformed
// --roi, a missing input file, ...). Printed as one line; exit code 2.
class UsageError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

// How to reach the service: what every command that talks to it shares.
struct ConnectionOptions {
    std::string socket_path = "/run/stereod/stereod.sock";
    int timeout_ms = 5000; // limit on each wait for the service
};

struct DistanceOptions {
    ConnectionOptions service;
    bool json = false;
    std::optional<double> max_age_ms;
};

struct StatusOptions {
    ConnectionOptions service;
    bool json = false;
};

struct WatchOptions {
    ConnectionOptions service;
    bool json = false;
};

struct SnapshotOptions {
    ConnectionOptions service;
    std::string depth_path;      // .png, uint16 millimetres
    std::string disparity_path;  // .pfm or .png (KITTI)
    std::string cloud_path;      // .ply
    std::string colormap_path;   // .png, colourised depth
    std::string left_path;       // .png, rectified left image
    std::string confidence_path; // .png, per-pixel match confidence (0 = no disparity)
};

// The geometry of a pair that comes rectified (--rectified --focal-px ...). The parser
// guarantees focal_px and baseline_m when `rectified` is set.
struct RectifiedOptions {
    bool rectified = false;
    std::optional<double> focal_px;
    std::optional<double> baseline_m;
    std::optional<double> cx_px; // default: the image centre
    std::optional<double> cy_px;
    double doffs_px = 0.0;
};

struct DepthOptions {
    std::string left_path;
    std::string right_path;
    std::string calib_path;
    std::string config_path; // a service configuration whose processing to use
    RectifiedOptions geometry;
    std::string matcher; // "" (the configured one) or a name of kMatcherAlgorithms
    std::string tuning;  // "", "natural", "planar", "patterns"
    std::optional<int> max_disparity;
    std::optional<double> min_depth_m;
    std::string roi; // "x,y,w,h" in fractions of the image
    std::string disparity_path;
    std::string depth_path;
    std::string cloud_path;
    std::string colormap_path;
    std::string confidence_path;
    bool json = false;
};

struct CalibrateOptions {
    RectifiedOptions geometry;
    std::string size; // "WxH"
    std::string out_path;
    // The chessboard form.
    std::string left_glob;
    std::string right_glob;
    std::string board; // "COLSxROWS", inner corners
    std::optional<double> square_m;
    std::string preview_path; // .png, the first pair rectified with row lines
    double alpha = 0.0;       // cv::stereoRectify's free scaling, 0..1
    int min_pairs = 6;
    bool json = false;
    // Other tools' files: two paths each.
    std::vector<std::string> from_ros;    // left.yaml, right.yaml (camera_info)
    std::vector<std::string> from_opencv; // intrinsics.yml, extrinsics.yml (stereo_calib)
    double unit_m = 1.0;                  // metres per unit of stereo_calib's T
    // The live chessboard form (--live): raw pairs from the running service.
    bool live = false;
    ConnectionOptions service;
    int count = 0;                   // accepted pairs to collect
    std::string save_pairs_dir;      // where accepted pairs go; default next to out_path
    std::optional<double> timeout_s; // stop collecting after this long; none: until Ctrl-C
    double max_hz = 4.0;             // pairs asked of the service per second
};

// `stereoctl devices`: exit 0 when a capture device was found, 1 when none.
struct DevicesOptions {
    bool json = false;
};

struct ExportRosOptions {
    std::string calib_path;
    std::string left_path;
    std::string right_path;
    std::string camera_name = "stereo";
};

// `stereoctl board-distance`: a chessboard's distance by its pose over the nearest-object
// region. Exit 0 with a distance, 1 when the board is not found or not in the region.
struct BoardDistanceOptions {
    std::string left_path;   // raw (unrectified) left image
    std::string calib_path;  // full calibration that records its board
    std::string config_path; // a service configuration whose region to use
    bool json = false;
};

// `stereoctl zones`: exit 0 all clear, 1 any occupied, 2 unknown, stale or none, 3 no service.
struct ZonesOptions {
    ConnectionOptions service;
    bool json = false;
    bool watch = false;         // one block per frame until interrupted
    double max_age_ms = 1000.0; // older zones count as unknown
    std::string picture_path;   // .png: the zones drawn on the colourised depth
};

// `stereoctl check-calibration`: how well a calibration still rectifies a rig's pairs.
// Exit 0 ok, 1 degraded or failed, 2 unknown (no verdict) or bad arguments.
struct CheckCalibrationOptions {
    // Without files: from the running service (its calibration_health).
    ConnectionOptions service;
    std::string left_glob;  // raw left images
    std::string right_glob; // raw right images, paired in sorted order
    std::string calib_path; // full calibration (YAML)
    bool fix = false;       // estimate a corrected rectification ...
    std::string out_path;   // ... and write it here (a new file)
    bool json = false;
};

// `stereoctl record`: the service's raw pairs written as a recording.
struct RecordOptions {
    ConnectionOptions service;
    std::string out_dir;            // a directory that must not exist or be empty, or a
                                    // new file ending in .mcap (a ROS 2 bag)
    std::optional<uint64_t> frames; // stop after this many pairs; none: until stopped
    // --with: the results to record beside each pair in a bag ("depth", "points"); checked
    // by runRecord().
    std::vector<std::string> with;
    std::size_t queue_pairs = 32; // pairs buffered between the socket and the disk
    bool json = false;
};

int runDistance(const DistanceOptions& options);
// ctl/devices_command.cpp
int runDevices(const DevicesOptions& options);
int runStatus(const StatusOptions& options);
// `stereoctl view`: the live view's address (from the service's status), and a browser
// opened on it when there is a display.
int runView(const StatusOptions& options);
int runWatch(const WatchOptions& options);
int runSnapshot(const SnapshotOptions& options);
int runDepth(const DepthOptions& options);
int runCalibrate(const CalibrateOptions& options);
// ctl/calibration_commands.cpp: the chessboard form of `calibrate`, its imports (the image
// size parsed from --size for --from-opencv) and `export-ros`.
int runChessboardCalibration(const CalibrateOptions& options);
// ctl/live_calibration.cpp: `calibrate --live`.
int runLiveCalibration(const CalibrateOptions& options);
int runCalibrationImport(const CalibrateOptions& options, cv::Size image_size);
int runExportRos(const ExportRosOptions& options);
// ctl/record_command.cpp
int runRecord(const RecordOptions& options);
// ctl/board_distance_command.cpp
int runBoardDistance(const BoardDistanceOptions& options);
// ctl/zones_command.cpp
int runZones(const ZonesOptions& options);
// ctl/check_calibration_command.cpp
int runCheckCalibration(const CheckCalibrationOptions& options);

} // namespace stereod
