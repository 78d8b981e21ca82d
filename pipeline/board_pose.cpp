#include "pipeline/board_pose.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/cv_conversions.hpp"
#include "pipeline/nearest_object.hpp"

namespace stereod {
namespace {

// A point of the board's plane, in squares from the first inner corner, in metres on the
// board (z = 0).
cv::Point3d onBoard(double x_squares, double y_squares, double square_m)
{
    return {x_squares * square_m, y_squares * square_m, 0.0};
}

} // namespace

double BoardPose::depthAt(cv::Point2d pixel, const RectifiedGeometry& geometry) const
{
    const cv::Vec3d ray((pixel.x - geometry.cx_px) / geometry.focal_px,
                        (pixel.y - geometry.cy_px) / geometry.focal_px, 1.0);
    const double along = normal.dot(ray);
    if (std::abs(along) < 1e-12)
        return 0.0;
    const double z = offset_m / along;
    return z > 0.0 ? z : 0.0;
}

BoardPose boardPoseFromCorners(const StereoCalibration& calibration, const ChessboardSpec& board,
                               const std::vector<cv::Point2f>& left_corners)
{
    if (calibration.kind != StereoCalibration::Kind::Full)
        throw std::invalid_argument("board pose: needs a full calibration (camera matrix and "
                                    "distortion of the raw left camera), got a rectified-only one");
    if (board.cols < 2 || board.rows < 2 || !(board.square_m > 0.0))
        throw std::invalid_argument("board pose: board must have at least 2x2 inner corners and "
                                    "a square size > 0, got " +
                                    std::to_string(board.cols) + "x" + std::to_string(board.rows) +
                                    " with " + std::to_string(board.square_m) + " m");
    const size_t count = static_cast<size_t>(board.cols) * static_cast<size_t>(board.rows);
    if (left_corners.size() != count)
        throw std::invalid_argument("board pose: " + std::to_string(left_corners.size()) +
                                    " corners for a board of " + std::to_string(board.cols) + "x" +
                                    std::to_string(board.rows) + " inner corners");

    std::vector<cv::Point3d> object;
    object.reserve(count);
    for (int y = 0; y < board.rows; ++y)
        for (int x = 0; x < board.cols; ++x)
            object.push_back(onBoard(x, y, board.square_m));
    std::vector<cv::Point2d> image(left_corners.begin(), left_corners.end());

    const CameraIntrinsics& camera = calibration.left;
    cv::Vec3d rvec, tvec;
    if (!cv::solvePnP(object, image, camera.camera_matrix, camera.distortion, rvec, tvec))
        throw std::invalid_argument("board pose: cv::solvePnP found no pose for the corners");
    std::vector<cv::Point2d> projected;
    cv::projectPoints(object, rvec, tvec, camera.camera_matrix, camera.distortion, projected);
    double squared = 0.0;
    for (size_t i = 0; i < count; ++i) {
        const cv::Point2d d = projected[i] - image[i];
        squared += d.dot(d);
    }

    // Board -> raw left camera (solvePnP), then raw -> rectified left camera (R1).
    cv::Matx33d rotation;
    cv::Rodrigues(rvec, rotation);
    const cv::Matx33d to_rectified = calibration.R1 * rotation;
    const cv::Vec3d origin = calibration.R1 * tvec;
    auto toCamera = [&](const cv::Point3d& p) {
        return cv::Vec3d(to_rectified * cv::Vec3d(p.x, p.y, p.z) + origin);
    };

    BoardPose pose;
    pose.normal = to_rectified * cv::Vec3d(0.0, 0.0, 1.0);
    pose.offset_m = pose.normal.dot(origin);
    pose.centre_m =
        toCamera(onBoard((board.cols - 1) / 2.0, (board.rows - 1) / 2.0, board.square_m));
    pose.reprojection_rms_px = std::sqrt(squared / static_cast<double>(count));
    const RectifiedGeometry& g = calibration.rectified;
    const std::array<cv::Point3d, 4> outline = {
        onBoard(-1, -1, board.square_m), onBoard(board.cols, -1, board.square_m),
        onBoard(board.cols, board.rows, board.square_m), onBoard(-1, board.rows, board.square_m)};
    for (size_t i = 0; i < outline.size(); ++i) {
        const cv::Vec3d x = toCamera(outline[i]);
        pose.outline_px[i] = {g.focal_px * x[0] / x[2] + g.cx_px,
                              g.focal_px * x[1] / x[2] + g.cy_px};
    }
    return pose;
}

std::optional<BoardDepthInRegion> boardDepthInRegion(const BoardPose& pose,
                                                     const RectifiedGeometry& geometry,
                                                     const NearestSettings& nearest)
{
    const cv::Rect region = regionPixels(nearest.roi, toCv(geometry.image_size));
    if (region.area() == 0)
        return std::nullopt;
    // The pattern's outline drawn into a mask of the region alone, in 1/16 px so that the
    // outline's sub-pixel position counts.
    constexpr int kShift = 4;
    std::vector<cv::Point> outline;
    for (const cv::Point2d& p : pose.outline_px)
        outline.emplace_back(static_cast<int>(std::lround((p.x - region.x) * (1 << kShift))),
                             static_cast<int>(std::lround((p.y - region.y) * (1 << kShift))));
    cv::Mat mask = cv::Mat::zeros(region.size(), CV_8UC1);
    cv::fillConvexPoly(mask, outline, cv::Scalar(255), cv::LINE_8, kShift);

    std::vector<double> depths;
    for (int y = 0; y < mask.rows; ++y) {
        const uchar* on_board = mask.ptr<uchar>(y);
        for (int x = 0; x < mask.cols; ++x) {
            if (!on_board[x])
                continue;
            const double z = pose.depthAt(
                {static_cast<double>(region.x + x), static_cast<double>(region.y + y)}, geometry);
            if (z > 0.0)
                depths.push_back(z);
        }
    }
    if (depths.empty())
        return std::nullopt;

    BoardDepthInRegion result;
    result.region_pixels = static_cast<uint32_t>(region.area());
    result.board_pixels = static_cast<uint32_t>(depths.size());
    result.coverage = static_cast<double>(depths.size()) / static_cast<double>(region.area());
    const auto [nearest_it, farthest_it] = std::minmax_element(depths.begin(), depths.end());
    result.nearest_m = *nearest_it;
    result.farthest_m = *farthest_it;
    const auto nth = depths.begin() + static_cast<std::ptrdiff_t>(
                                          percentileIndex(nearest.percentile, depths.size()));
    std::nth_element(depths.begin(), nth, depths.end());
    result.depth_m = *nth;
    return result;
}

} // namespace stereod
