#pragma once
// Where a chessboard is, by its pose rather than by stereo matching: the board's plane
// from its corners in the raw left image and a full calibration (cv::solvePnP), and the
// distance that plane gives inside the region the service reads its nearest object from.
//
// This is the reference a person (`stereoctl board-distance`, the demo) and the accuracy
// tests hold the service's reading against: it comes from the corners and the
// calibration alone, not from the matcher, so a periodic board that fools correlation
// does not fool it.
//
// Reentrant: no state outside the arguments.

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include <opencv2/core/matx.hpp>
#include <opencv2/core/types.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/nearest_settings.hpp"

namespace stereod {

// The board's plane in the frame of the rectified left camera (x right, y down, z forward,
// metres): the frame the service's depth map is in.
struct BoardPose {
    cv::Vec3d normal;      // unit normal of the plane
    double offset_m = 0.0; // normal . X = offset_m for every point X of the plane
    cv::Vec3d centre_m;    // centre of the inner corners
    // The printed pattern's outer edge (the inner corners' outline grown by one square on
    // every side) in the rectified left image, pixels, in order around the board. The
    // board's frame and margins, which lie beyond, are not counted as board.
    std::array<cv::Point2d, 4> outline_px;
    double reprojection_rms_px = 0.0; // of the corners under the pose, raw left image

    // Depth (z, metres) of the plane along the ray of rectified left pixel `pixel`;
    // 0 when the ray misses the plane (parallel, or the plane behind the camera).
    double depthAt(cv::Point2d pixel, const RectifiedGeometry& geometry) const;
};

// The board's pose from its inner corners in the raw (unrectified) left image, row by row
// as findBoardCorners (pipeline/chessboard_calibration.hpp) gives them. Throws
// std::invalid_argument when the calibration is not a full one, the corner count does
// not match the board, or the board's square size is not > 0.
BoardPose boardPoseFromCorners(const StereoCalibration& calibration, const ChessboardSpec& board,
                               const std::vector<cv::Point2f>& left_corners);

// What the board's plane says the service's reading should be in a region.
struct BoardDepthInRegion {
    uint32_t region_pixels = 0; // pixels of the region (NearestSettings::roi)
    uint32_t board_pixels = 0;  // of those, the pixels on the board's pattern
    double coverage = 0.0;      // board_pixels / region_pixels
    // The configured percentile (NearestSettings::percentile, the same index rule as the
    // service's nearest object) of the plane's depths at the board's pixels in the
    // region: the distance of the nearest object when the board is it.
    double depth_m = 0.0;
    double nearest_m = 0.0; // the plane's depth range over those pixels
    double farthest_m = 0.0;
};

// The board's depth over the pixels of the region that lie on its pattern; std::nullopt
// when none does. Depths outside [min_depth_m, max_depth_m] are not filtered out: the
// plane is the truth, and a board outside the service's range is the caller's finding.
std::optional<BoardDepthInRegion> boardDepthInRegion(const BoardPose& pose,
                                                     const RectifiedGeometry& geometry,
                                                     const NearestSettings& nearest);

} // namespace stereod
