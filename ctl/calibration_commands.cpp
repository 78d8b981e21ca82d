// The calibration commands beyond the rectified-only form:
//  - `stereoctl calibrate --left GLOB --right GLOB --board COLSxROWS --square-m S --out F`:
//    chessboard stereo calibration (pipeline/chessboard_calibration.hpp) with a progress
//    line per pair on stderr, the per-pair table and a summary (or JSON) on stdout;
//  - `stereoctl calibrate --from-ros L R` / `--from-opencv I E --size WxH`: other tools'
//    files into ours; `stereoctl export-ros`: ours out as a ROS camera_info pair
//    (pipeline/calibration_formats.hpp).

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "ctl/calibration_report.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "ctl/file_patterns.hpp"
#include "pipeline/calibration_formats.hpp"
#include "pipeline/chessboard_calibration.hpp"

namespace stereod {

namespace {

using json = nlohmann::ordered_json;

// "9x6" -> 9 inner corners per row, 6 rows.
ChessboardSpec parseBoard(const std::string& text, double square_m)
{
    ChessboardSpec board;
    board.square_m = square_m;
    const std::string_view view(text);
    const std::size_t x = view.find('x');
    const auto whole = [](std::string_view part, int& value) {
        const auto [end, error] = std::from_chars(part.data(), part.data() + part.size(), value);
        return error == std::errc() && end == part.data() + part.size() && value > 0;
    };
    if (x == std::string_view::npos || !whole(view.substr(0, x), board.cols) ||
        !whole(view.substr(x + 1), board.rows)) {
        throw UsageError(fmt::format("--board: expected COLSxROWS, the inner corners of the "
                                     "board (e.g. 9x6 for a board of 10x7 squares), got '{}'",
                                     text));
    }
    return board;
}

std::string optionalPx(const std::optional<double>& value)
{
    return value ? fmt::format("{:.3f}", *value) : "-";
}

json optionalJson(const std::optional<double>& value)
{
    return value ? json(*value) : json(nullptr);
}

void printProgress(const CornerProgress& progress)
{
    const PairReport& p = *progress.pair;
    const char* outcome = p.left_found && p.right_found ? "found"
                          : p.left_found                ? "not found in the right image"
                          : p.right_found               ? "not found in the left image"
                                                        : "not found";
    fmt::print(stderr, "corners: pair {}/{} {} {} ... {}\n", progress.index, progress.count,
               fileName(p.left_path), fileName(p.right_path), outcome);
    std::fflush(stderr);
}

std::string describeRect(const cv::Rect& r)
{
    return fmt::format("{}x{} at ({}, {})", r.width, r.height, r.x, r.y);
}

void printReport(const ChessboardCalibrationResult& r, const std::string& out_path,
                 const std::string& preview_path)
{
    std::size_t name_width = 4;
    for (const PairReport& p : r.pairs) {
        name_width =
            std::max(name_width, fileName(p.left_path).size() + 1 + fileName(p.right_path).size());
    }
    fmt::print("{:<{}}  found  RMS left  RMS right  epipolar (rows)  used\n", "pair", name_width);
    for (const PairReport& p : r.pairs) {
        fmt::print("{:<{}}  {}/{}    {:>8}  {:>9}  {:>15}  {}\n",
                   fileName(p.left_path) + " " + fileName(p.right_path), name_width,
                   p.left_found ? "L" : "-", p.right_found ? "R" : "-", optionalPx(p.left_rms_px),
                   optionalPx(p.right_rms_px), optionalPx(p.epipolar_error_px),
                   p.used ? "yes" : "no: " + p.rejection);
    }
    const StereoCalibration& c = r.calibration;
    fmt::print("\n{} of {} pairs used", r.pairs_used, r.pairs.size());
    if (r.outliers_dropped > 0) {
        fmt::print(" ({} dropped as outliers, calibrated again without them)", r.outliers_dropped);
    }
    fmt::print("\nRMS reprojection error {:.3f} px (each camera alone: left {:.3f} px, right "
               "{:.3f} px)\n",
               r.rms_px, r.left_rms_px, r.right_rms_px);
    fmt::print("epipolar error {:.3f} px (rows of matching corners after rectification); "
               "distance to epipolar lines {:.3f} px\n",
               r.epipolar_error_px, r.epipolar_distance_px);
    fmt::print("baseline {:.4f} m, rectified focal length {:.1f} px, {}x{} images; valid "
               "regions: left {}, right {}\n",
               r.baseline_m, c.rectified.focal_px, c.rectified.image_size.width,
               c.rectified.image_size.height, describeRect(c.valid_roi_left),
               describeRect(c.valid_roi_right));
    fmt::print("wrote calibration {}\n", out_path);
    if (!preview_path.empty()) {
        fmt::print("wrote preview {}\n", preview_path);
    }
}

json reportJson(const ChessboardCalibrationResult& r, const CalibrateOptions& options,
                const json& extra_json)
{
    json rejected = json::array();
    json pairs = json::array();
    for (const PairReport& p : r.pairs) {
        if (!p.used) {
            rejected.push_back(
                {{"left", p.left_path}, {"right", p.right_path}, {"reason", p.rejection}});
        }
        pairs.push_back({{"left", p.left_path},
                         {"right", p.right_path},
                         {"left_found", p.left_found},
                         {"right_found", p.right_found},
                         {"used", p.used},
                         {"left_rms_px", optionalJson(p.left_rms_px)},
                         {"right_rms_px", optionalJson(p.right_rms_px)},
                         {"epipolar_error_px", optionalJson(p.epipolar_error_px)},
                         {"epipolar_distance_px", optionalJson(p.epipolar_distance_px)},
                         {"rejection", p.used ? json(nullptr) : json(p.rejection)}});
    }
    const StereoCalibration& c = r.calibration;
    json files = {{"calibration", options.out_path}};
    if (!options.preview_path.empty()) {
        files["preview"] = options.preview_path;
    }
    json report = {
        {"rms_px", r.rms_px},
        {"epipolar_error_px", r.epipolar_error_px},
        {"epipolar_distance_px", r.epipolar_distance_px},
        {"pairs_used", r.pairs_used},
        {"pairs_total", r.pairs.size()},
        {"outliers_dropped", r.outliers_dropped},
        {"pairs_rejected", rejected},
        {"baseline_m", r.baseline_m},
        {"focal_px", c.rectified.focal_px},
        {"left_rms_px", r.left_rms_px},
        {"right_rms_px", r.right_rms_px},
        {"image",
         {{"width", c.rectified.image_size.width}, {"height", c.rectified.image_size.height}}},
        {"board",
         {{"cols", c.board->cols}, {"rows", c.board->rows}, {"square_m", c.board->square_m}}},
        {"alpha", options.alpha},
        {"pairs", pairs},
        {"files", files}};
    if (extra_json.is_object()) {
        report.update(extra_json);
    }
    return report;
}

} // namespace

ChessboardCalibrationOptions chessboardOptions(const CalibrateOptions& options)
{
    if (options.board.empty() || !options.square_m) {
        throw UsageError("a chessboard calibration needs --board COLSxROWS and --square-m S");
    }
    ChessboardCalibrationOptions calibration_options;
    calibration_options.board = parseBoard(options.board, *options.square_m);
    calibration_options.alpha = options.alpha;
    calibration_options.min_pairs = options.min_pairs;
    validateChessboardOptions(calibration_options);
    return calibration_options;
}

void finishChessboardCalibration(const ChessboardCalibrationResult& result,
                                 const CalibrateOptions& options, const json& extra_json)
{
    saveCalibration(result.calibration, options.out_path);
    if (!options.preview_path.empty()) {
        writeRectifiedPreview(result, options.preview_path);
    }
    if (options.json) {
        fmt::print("{}\n", reportJson(result, options, extra_json).dump(2));
    } else {
        printReport(result, options.out_path, options.preview_path);
    }
}

int runChessboardCalibration(const CalibrateOptions& options)
{
    if (options.left_glob.empty() || options.right_glob.empty() || options.board.empty() ||
        !options.square_m) {
        throw UsageError("chessboard calibration needs --left GLOB --right GLOB --board COLSxROWS "
                         "--square-m S");
    }
    const ChessboardCalibrationOptions calibration_options = chessboardOptions(options);
    const std::vector<std::string> left = expandGlob(options.left_glob, "--left");
    const std::vector<std::string> right = expandGlob(options.right_glob, "--right");
    if (left.size() != right.size()) {
        throw UsageError(fmt::format("--left matches {} files but --right matches {}: the pairs "
                                     "are taken in sorted order, one of each",
                                     left.size(), right.size()));
    }

    const ChessboardCalibrationResult result =
        calibrateChessboard(left, right, calibration_options, printProgress);
    finishChessboardCalibration(result, options, json::object());
    return kExitOk;
}

int runCalibrationImport(const CalibrateOptions& options, cv::Size image_size)
{
    StereoCalibration calibration;
    std::string from;
    if (!options.from_ros.empty()) {
        calibration = importRosCameraInfo(options.from_ros[0], options.from_ros[1]);
        from = fmt::format("ROS camera_info {} + {}", options.from_ros[0], options.from_ros[1]);
    } else {
        calibration = importOpenCvStereoCalib(options.from_opencv[0], options.from_opencv[1],
                                              image_size, options.unit_m);
        from = fmt::format("OpenCV stereo_calib {} + {}", options.from_opencv[0],
                           options.from_opencv[1]);
    }
    saveCalibration(calibration, options.out_path);
    const RectifiedGeometry& g = calibration.rectified;
    fmt::print("wrote calibration {} from {}: {}x{}, f {:.3f} px, B {:.4f} m\n", options.out_path,
               from, g.image_size.width, g.image_size.height, g.focal_px, g.baseline_m);
    return kExitOk;
}

int runExportRos(const ExportRosOptions& options)
{
    const StereoCalibration calibration = loadCalibration(options.calib_path);
    exportRosCameraInfo(calibration, options.left_path, options.right_path, options.camera_name);
    fmt::print("wrote ROS camera_info {} and {} from {}\n", options.left_path, options.right_path,
               options.calib_path);
    return kExitOk;
}

} // namespace stereod
