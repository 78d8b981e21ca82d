// `stereoctl board-distance LEFT --calib FILE [--config FILE] [--json]`: how far a
// chessboard in a raw left image is, by its pose (pipeline/board_pose.hpp) rather than by
// stereo matching, over the region the service reads its nearest object from. A person
// holds a board in front of the rig and compares this with `stereoctl distance`; the
// demo does the same with the recorded pairs.

#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "config/service_config.hpp"
#include "ctl/commands.hpp"
#include "ctl/exit_codes.hpp"
#include "pipeline/board_pose.hpp"
#include "pipeline/chessboard_calibration.hpp"

namespace stereod {

int runBoardDistance(const BoardDistanceOptions& options)
{
    const StereoCalibration calibration = loadCalibration(options.calib_path);
    if (calibration.kind != StereoCalibration::Kind::Full || !calibration.board) {
        throw UsageError(fmt::format("{}: needs a full calibration that records its board (as "
                                     "`stereoctl calibrate --left ... --board ...` writes it)",
                                     options.calib_path));
    }
    const ChessboardSpec& board = *calibration.board;
    const NearestSettings nearest = options.config_path.empty()
                                        ? defaultConfig().processing.nearest
                                        : loadConfig(options.config_path).processing.nearest;
    const cv::Mat image = cv::imread(options.left_path, cv::IMREAD_GRAYSCALE);
    if (image.empty()) {
        throw UsageError(fmt::format("cannot read image {}: missing, or not an image OpenCV "
                                     "decodes",
                                     options.left_path));
    }
    checkFrameSize(calibration, image.size(), options.left_path);

    std::vector<cv::Point2f> corners;
    if (!findBoardCorners(image, {board.cols, board.rows}, corners)) {
        fmt::print("no board: the {}x{} board is not found in {}\n", board.cols, board.rows,
                   options.left_path);
        return kExitNoReading;
    }
    const BoardPose pose = boardPoseFromCorners(calibration, board, corners);
    const std::optional<BoardDepthInRegion> depth =
        boardDepthInRegion(pose, calibration.rectified, nearest);
    if (options.json) {
        nlohmann::ordered_json out = {
            {"image", options.left_path},
            {"board", {{"cols", board.cols}, {"rows", board.rows}, {"square_m", board.square_m}}},
            {"centre_depth_m", pose.centre_m[2]},
            {"reprojection_rms_px", pose.reprojection_rms_px},
            {"percentile", nearest.percentile}};
        if (depth) {
            out["distance_m"] = depth->depth_m;
            out["nearest_m"] = depth->nearest_m;
            out["farthest_m"] = depth->farthest_m;
            out["coverage"] = depth->coverage;
        } else {
            out["distance_m"] = nullptr;
        }
        fmt::print("{}\n", out.dump());
    } else if (depth) {
        fmt::print("{:.3f} m by the board's pose (percentile {:g} of its plane over the {:.0f} % "
                   "of the region it covers, {:.3f} to {:.3f} m; board centre at {:.3f} m)\n",
                   depth->depth_m, nearest.percentile, 100.0 * depth->coverage, depth->nearest_m,
                   depth->farthest_m, pose.centre_m[2]);
    } else {
        fmt::print("no board in the region: the board (centre at {:.3f} m) lies outside it\n",
                   pose.centre_m[2]);
    }
    return depth ? kExitOk : kExitNoReading;
}

} // namespace stereod
