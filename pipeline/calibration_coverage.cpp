#include "pipeline/calibration_coverage.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod {
namespace {

constexpr double kRadToDeg = 180.0 / CV_PI;

void checkCorners(const std::vector<cv::Point2f>& corners, cv::Size inner_corners)
{
    if (corners.size() != static_cast<size_t>(inner_corners.area()))
        throw std::invalid_argument("describeBoard: " + std::to_string(corners.size()) +
                                    " corners, the board has " +
                                    std::to_string(inner_corners.area()));
}

std::string joined(const std::vector<std::string>& names)
{
    std::string out;
    for (const std::string& name : names) {
        if (!out.empty())
            out += ", ";
        out += name;
    }
    return out;
}

// How far apart two appearances of a board are, by each of the duplicate test's measures.
struct Difference {
    double position_frac = 0.0; // of the image's diagonal
    double size_ratio = 0.0;    // |a - b| / max(a, b)
    double yaw_deg = 0.0;
    double pitch_deg = 0.0;
    double roll_deg = 0.0; // the smaller way round, modulo 180
};

Difference difference(const BoardAppearance& a, const BoardAppearance& b, cv::Size image)
{
    const double dx = (a.centre_frac.x - b.centre_frac.x) * image.width;
    const double dy = (a.centre_frac.y - b.centre_frac.y) * image.height;
    Difference d;
    d.position_frac = std::hypot(dx, dy) / std::hypot(image.width, image.height);
    d.size_ratio = std::abs(a.size_frac - b.size_frac) / std::max(a.size_frac, b.size_frac);
    d.yaw_deg = std::abs(a.yaw_deg - b.yaw_deg);
    d.pitch_deg = std::abs(a.pitch_deg - b.pitch_deg);
    const double roll = std::abs(a.roll_deg - b.roll_deg);
    d.roll_deg = std::min(roll, 180.0 - roll);
    return d;
}

bool closeEnough(const Difference& d, const CoverageOptions& o)
{
    return d.position_frac < o.duplicate_position_frac && d.size_ratio < o.duplicate_size_ratio &&
           d.yaw_deg < o.duplicate_tilt_deg && d.pitch_deg < o.duplicate_tilt_deg &&
           d.roll_deg < o.duplicate_tilt_deg;
}

} // namespace

BoardAppearance describeBoard(const std::vector<cv::Point2f>& corners, cv::Size inner_corners,
                              cv::Size image_size, double focal_px)
{
    checkCorners(corners, inner_corners);
    if (image_size.width <= 0 || image_size.height <= 0)
        throw std::invalid_argument("describeBoard: empty image size");
    BoardAppearance a;
    cv::Point2d sum(0.0, 0.0);
    for (const cv::Point2f& c : corners)
        sum += cv::Point2d(c);
    const double n = static_cast<double>(corners.size());
    a.centre_frac = {sum.x / n / image_size.width, sum.y / n / image_size.height};

    const int cols = inner_corners.width, rows = inner_corners.height;
    const std::vector<cv::Point2f> outline = {corners[0], corners[static_cast<size_t>(cols - 1)],
                                              corners[static_cast<size_t>(rows * cols - 1)],
                                              corners[static_cast<size_t>((rows - 1) * cols)]};
    a.size_frac = std::sqrt(std::abs(cv::contourArea(outline)) / image_size.area());
    const cv::Point2f row = outline[1] - outline[0];
    a.roll_deg = std::atan2(row.y, row.x) * kRadToDeg;
    if (a.roll_deg > 90.0)
        a.roll_deg -= 180.0;
    else if (a.roll_deg <= -90.0)
        a.roll_deg += 180.0;

    // Board plane (in squares) to image, then through the guessed camera: the columns of
    // K^-1 H are the board's axes in the camera frame, up to a common scale.
    std::vector<cv::Point2f> board;
    board.reserve(corners.size());
    for (int y = 0; y < rows; ++y)
        for (int x = 0; x < cols; ++x)
            board.emplace_back(static_cast<float>(x), static_cast<float>(y));
    const cv::Mat H = cv::findHomography(board, corners, 0);
    if (H.empty())
        return a; // degenerate corners (all on a line): no turn to measure
    const double f = focal_px > 0.0 ? focal_px : image_size.width;
    const cv::Matx33d K_inv(1.0 / f, 0.0, -0.5 * (image_size.width - 1) / f, 0.0, 1.0 / f,
                            -0.5 * (image_size.height - 1) / f, 0.0, 0.0, 1.0);
    const cv::Matx33d M = K_inv * cv::Matx33d(H);
    const cv::Vec3d r1 = cv::normalize(cv::Vec3d(M(0, 0), M(1, 0), M(2, 0)));
    const cv::Vec3d r2 = cv::normalize(cv::Vec3d(M(0, 1), M(1, 1), M(2, 1)));
    cv::Vec3d normal = cv::normalize(r1.cross(r2));
    if (normal[2] > 0.0)
        normal = -normal; // towards the camera, whichever way the detector ordered corners
    // On the plane n.X = c, depth changes along x at dZ/dX = -n_x / n_z: a board whose right
    // side is farther has n_x > 0 (with n_z < 0).
    a.yaw_deg = std::atan2(normal[0], -normal[2]) * kRadToDeg;
    a.pitch_deg = std::atan2(normal[1], -normal[2]) * kRadToDeg;
    return a;
}

std::string formatGaps(const CoverageGaps& gaps)
{
    if (gaps.complete())
        return "coverage complete";
    std::vector<std::string> parts;
    if (!gaps.left_cells.empty())
        parts.push_back("left image " + joined(gaps.left_cells));
    if (!gaps.right_cells.empty())
        parts.push_back("right image " + joined(gaps.right_cells));
    if (!gaps.tilts.empty())
        parts.push_back("tilts: " + joined(gaps.tilts));
    if (!gaps.distances.empty())
        parts.push_back("distances: " + joined(gaps.distances));
    std::string out = "missing: ";
    for (size_t i = 0; i < parts.size(); ++i)
        out += (i == 0 ? "" : "; ") + parts[i];
    return out;
}

CalibrationCoverage::CalibrationCoverage(cv::Size image_size, cv::Size inner_corners,
                                         CoverageOptions options)
    : image_size_(image_size), inner_corners_(inner_corners), options_(options)
{
    if (image_size.width <= 0 || image_size.height <= 0)
        throw std::invalid_argument("calibration coverage: empty image size");
    if (inner_corners.width < 2 || inner_corners.height < 2)
        throw std::invalid_argument("calibration coverage: a board needs at least 2x2 inner "
                                    "corners");
    const CoverageOptions& o = options_;
    if (o.min_corners_per_cell < 1 || !(o.tilt_deg > 0.0) || !(o.far_size_frac > 0.0) ||
        !(o.near_size_frac > o.far_size_frac) || !(o.duplicate_position_frac >= 0.0) ||
        !(o.duplicate_size_ratio >= 0.0) || !(o.duplicate_tilt_deg >= 0.0))
        throw std::invalid_argument("calibration coverage: options out of range (cells need >= "
                                    "1 corner, tilt > 0, 0 < far < near, duplicate limits >= 0)");
}

BoardView CalibrationCoverage::describe(const std::vector<cv::Point2f>& left_corners,
                                        const std::vector<cv::Point2f>& right_corners) const
{
    return {describeBoard(left_corners, inner_corners_, image_size_, options_.focal_px),
            describeBoard(right_corners, inner_corners_, image_size_, options_.focal_px)};
}

ViewJudgement CalibrationCoverage::judge(const std::vector<cv::Point2f>& left_corners,
                                         const std::vector<cv::Point2f>& right_corners) const
{
    ViewJudgement j;
    j.view = describe(left_corners, right_corners);
    for (size_t i = 0; i < views_.size(); ++i) {
        const Difference left = difference(j.view.left, views_[i].left, image_size_);
        const Difference right = difference(j.view.right, views_[i].right, image_size_);
        if (!closeEnough(left, options_) || !closeEnough(right, options_))
            continue;
        j.duplicate_of = static_cast<int>(i);
        char text[400];
        if (left.position_frac < 0.001 && left.size_ratio < 0.001 &&
            std::max({left.yaw_deg, left.pitch_deg, left.roll_deg}) < 0.1) {
            std::snprintf(text, sizeof text,
                          "the same view as accepted view %zu (the board has not moved): move "
                          "it, turn it or change its distance",
                          i + 1);
            j.reason = text;
            break;
        }
        std::snprintf(text, sizeof text,
                      "too close to accepted view %zu: in the left image the board moved %.1f %% "
                      "of the image, its size changed %.0f %%, it turned %.1f, %.1f and %.1f "
                      "degrees (yaw, pitch, roll); move it, turn it or change its distance more",
                      i + 1, 100.0 * left.position_frac, 100.0 * left.size_ratio, left.yaw_deg,
                      left.pitch_deg, left.roll_deg);
        j.reason = text;
        break;
    }
    return j;
}

void CalibrationCoverage::countCorners(const std::vector<cv::Point2f>& corners,
                                       std::array<int, kGridCols * kGridRows>& cells) const
{
    for (const cv::Point2f& c : corners) {
        const int col =
            std::clamp(static_cast<int>(c.x * kGridCols / image_size_.width), 0, kGridCols - 1);
        const int row =
            std::clamp(static_cast<int>(c.y * kGridRows / image_size_.height), 0, kGridRows - 1);
        ++cells[static_cast<size_t>(row * kGridCols + col)];
    }
}

void CalibrationCoverage::accept(const std::vector<cv::Point2f>& left_corners,
                                 const std::vector<cv::Point2f>& right_corners)
{
    const BoardView view = describe(left_corners, right_corners);
    countCorners(left_corners, left_cells_);
    countCorners(right_corners, right_cells_);
    // Buckets from the left camera: the right one sees the same board nearly the same way.
    const BoardAppearance& a = view.left;
    tilt_views_[0] += a.yaw_deg <= -options_.tilt_deg;
    tilt_views_[1] += a.yaw_deg >= options_.tilt_deg;
    tilt_views_[2] += a.pitch_deg <= -options_.tilt_deg;
    tilt_views_[3] += a.pitch_deg >= options_.tilt_deg;
    distance_views_[0] += a.size_frac >= options_.near_size_frac;
    distance_views_[1] += a.size_frac <= options_.far_size_frac;
    views_.push_back(view);
}

CoverageGaps CalibrationCoverage::gaps() const
{
    CoverageGaps g;
    for (int i = 0; i < kGridCols * kGridRows; ++i) {
        if (left_cells_[static_cast<size_t>(i)] < options_.min_corners_per_cell)
            g.left_cells.emplace_back(cellName(i));
        if (right_cells_[static_cast<size_t>(i)] < options_.min_corners_per_cell)
            g.right_cells.emplace_back(cellName(i));
    }
    for (int b = 0; b < kTiltBuckets; ++b)
        if (tilt_views_[static_cast<size_t>(b)] == 0)
            g.tilts.emplace_back(tiltName(b));
    for (int b = 0; b < kDistanceBuckets; ++b)
        if (distance_views_[static_cast<size_t>(b)] == 0)
            g.distances.emplace_back(distanceName(b));
    return g;
}

const char* CalibrationCoverage::cellName(int index)
{
    static const char* const kNames[kGridCols * kGridRows] = {
        "top-left", "top",         "top-right", "left",        "centre",
        "right",    "bottom-left", "bottom",    "bottom-right"};
    return index >= 0 && index < kGridCols * kGridRows ? kNames[index] : "?";
}

const char* CalibrationCoverage::tiltName(int bucket)
{
    // yaw < 0: the right side nearer; pitch < 0: the bottom nearer.
    static const char* const kNames[kTiltBuckets] = {"right edge nearer", "left edge nearer",
                                                     "bottom edge nearer", "top edge nearer"};
    return bucket >= 0 && bucket < kTiltBuckets ? kNames[bucket] : "?";
}

const char* CalibrationCoverage::distanceName(int bucket)
{
    static const char* const kNames[kDistanceBuckets] = {"near", "far"};
    return bucket >= 0 && bucket < kDistanceBuckets ? kNames[bucket] : "?";
}

} // namespace stereod
