#include "pipeline/chessboard_calibration.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "base/system_error.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/rectifier.hpp"

namespace stereod {
namespace {

// Half window of cornerSubPix as a fraction of the distance from the corner to the
// nearest board line that does not pass through it (measurements in the header).
constexpr double kSubpixWindowFraction = 0.3;
constexpr int kSubpixMinHalfWindow = 2;
const cv::TermCriteria kSubpixCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 0.001);
// k1 k2 p1 p2: k3 fixed at 0 (measurements in the header).
constexpr int kDistortionFlags = cv::CALIB_FIX_K3;
constexpr int kDistortionCoefficients = 4;
const cv::TermCriteria kStereoCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-9);
// cv::undistortPoints stops after 5 iterations by default, short of convergence near the
// corners of a wide-angle image; the error figures must not carry that.
const cv::TermCriteria kUndistortCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100,
                                          1e-12);
// MAD to the standard deviation of a normal distribution.
constexpr double kMadToSigma = 1.4826;

std::string describeSize(cv::Size size)
{
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

std::string formatPx(double value)
{
    char text[32];
    std::snprintf(text, sizeof text, "%.3f", value);
    return text;
}

} // namespace

void validateChessboardOptions(const ChessboardCalibrationOptions& o)
{
    const ChessboardSpec& b = o.board;
    if (b.cols < 3 || b.rows < 3)
        throw std::invalid_argument("board: inner corners " + std::to_string(b.cols) + "x" +
                                    std::to_string(b.rows) +
                                    ": both counts must be >= 3 (OpenCV's detector needs them)");
    if (b.cols == b.rows)
        throw std::invalid_argument(
            "board: " + std::to_string(b.cols) + "x" + std::to_string(b.rows) +
            " inner corners: a square grid reads the same turned by 90 degrees, so the corners "
            "of the two cameras cannot be matched; use a board with different counts");
    if (!(b.square_m > 0.0) || !std::isfinite(b.square_m))
        throw std::invalid_argument("board: square size must be > 0 metres, got " +
                                    std::to_string(b.square_m));
    if (!(o.alpha >= 0.0 && o.alpha <= 1.0))
        throw std::invalid_argument("alpha: must lie in 0..1, got " + std::to_string(o.alpha));
    if (o.min_pairs < 3)
        throw std::invalid_argument("min_pairs: must be >= 3, got " + std::to_string(o.min_pairs));
    if (!(o.outlier_mads > 0.0) || !(o.outlier_floor_px >= 0.0))
        throw std::invalid_argument("outlier_mads must be > 0 and outlier_floor_px >= 0");
}

namespace {

cv::Size innerCorners(const ChessboardSpec& board)
{
    return {board.cols, board.rows};
}

std::vector<cv::Point3f> boardPoints(const ChessboardSpec& board)
{
    std::vector<cv::Point3f> points;
    points.reserve(static_cast<size_t>(board.cols * board.rows));
    for (int y = 0; y < board.rows; ++y)
        for (int x = 0; x < board.cols; ++x)
            points.emplace_back(static_cast<float>(x * board.square_m),
                                static_cast<float>(y * board.square_m), 0.0f);
    return points;
}

// Distance from p to the line through a and b.
double lineDistance(cv::Point2f p, cv::Point2f a, cv::Point2f b)
{
    const cv::Point2f d = b - a;
    return std::abs(d.x * (p.y - a.y) - d.y * (p.x - a.x)) / std::hypot(d.x, d.y);
}

// For each corner, the distance to the nearest board line (row or column of corners) that
// does not pass through it: the neighbouring rows and columns, taken locally.
std::vector<double> foreignLineDistances(const std::vector<cv::Point2f>& c, cv::Size grid)
{
    const int w = grid.width, h = grid.height;
    auto at = [&](int x, int y) { return c[static_cast<size_t>(y * w + x)]; };
    std::vector<double> out(c.size());
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            double nearest = HUGE_VAL;
            const cv::Point2f p = at(x, y);
            for (int dy : {-1, 1}) {
                const int yy = y + dy;
                if (yy >= 0 && yy < h)
                    nearest = std::min(nearest, lineDistance(p, at(std::max(0, x - 1), yy),
                                                             at(std::min(w - 1, x + 1), yy)));
            }
            for (int dx : {-1, 1}) {
                const int xx = x + dx;
                if (xx >= 0 && xx < w)
                    nearest = std::min(nearest, lineDistance(p, at(xx, std::max(0, y - 1)),
                                                             at(xx, std::min(h - 1, y + 1))));
            }
            out[static_cast<size_t>(y * w + x)] = nearest;
        }
    return out;
}

// Puts the right image's corners in the order of the left's. The detector may start a
// rectangular grid at either end (the grid maps onto itself turned by 180 degrees); both
// cameras see the board nearly the same way, so the directions of the board's rows and
// columns must agree between them.
void alignCornerOrder(const std::vector<cv::Point2f>& left, std::vector<cv::Point2f>& right,
                      cv::Size grid)
{
    const int w = grid.width, h = grid.height;
    const size_t last_in_row = static_cast<size_t>(w - 1);
    const size_t first_of_last_row = static_cast<size_t>((h - 1) * w);
    const bool rows_reversed =
        (left[last_in_row] - left[0]).dot(right[last_in_row] - right[0]) < 0.0f;
    const bool columns_reversed =
        (left[first_of_last_row] - left[0]).dot(right[first_of_last_row] - right[0]) < 0.0f;
    if (rows_reversed)
        for (int y = 0; y < h; ++y)
            std::reverse(right.begin() + y * w, right.begin() + (y + 1) * w);
    if (columns_reversed)
        for (int y = 0; y < h / 2; ++y)
            std::swap_ranges(right.begin() + y * w, right.begin() + (y + 1) * w,
                             right.begin() + (h - 1 - y) * w);
}

cv::Mat readGray(const std::string& path)
{
    if (::access(path.c_str(), R_OK) != 0)
        throw ChessboardCalibrationError("cannot read image " + path + ": " + errnoText(errno));
    cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (image.empty())
        throw ChessboardCalibrationError("cannot read image " + path +
                                         ": not an image format OpenCV can decode");
    return image;
}

// One run of both cameras' calibration and the stereo calibration over `views`.
struct StereoFit {
    cv::Mat K1, D1, K2, D2, R, T, E, F;
    cv::Mat per_view_rms; // views x 2 (left, right), pixels
    double rms_px = 0.0;
    double left_rms_px = 0.0;
    double right_rms_px = 0.0;
};

StereoFit fitStereo(const std::vector<const PairReport*>& views, cv::Size image_size,
                    const ChessboardSpec& board)
{
    const std::vector<std::vector<cv::Point3f>> objects(views.size(), boardPoints(board));
    std::vector<std::vector<cv::Point2f>> left, right;
    for (const PairReport* v : views) {
        left.push_back(v->left_corners);
        right.push_back(v->right_corners);
    }
    StereoFit fit;
    std::vector<cv::Mat> rvecs, tvecs;
    try {
        fit.left_rms_px = cv::calibrateCamera(objects, left, image_size, fit.K1, fit.D1, rvecs,
                                              tvecs, kDistortionFlags);
        fit.right_rms_px = cv::calibrateCamera(objects, right, image_size, fit.K2, fit.D2, rvecs,
                                               tvecs, kDistortionFlags);
        fit.rms_px =
            cv::stereoCalibrate(objects, left, right, fit.K1, fit.D1, fit.K2, fit.D2, image_size,
                                fit.R, fit.T, fit.E, fit.F, fit.per_view_rms,
                                kDistortionFlags | cv::CALIB_USE_INTRINSIC_GUESS, kStereoCriteria);
    } catch (const cv::Exception& error) {
        // Views that do not constrain the cameras (all boards parallel to the image, say).
        throw ChessboardCalibrationError("the calibration does not converge on these " +
                                         std::to_string(views.size()) + " pairs (" + error.err +
                                         "): vary the board's distance, position and tilt");
    }
    return fit;
}

double median(std::vector<double> values)
{
    const size_t mid = values.size() / 2;
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid),
                     values.end());
    const double upper = values[mid];
    if (values.size() % 2 == 1)
        return upper;
    const double lower =
        *std::max_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid));
    return 0.5 * (lower + upper);
}

void recordPerViewRms(const std::vector<PairReport*>& views, const StereoFit& fit)
{
    for (size_t i = 0; i < views.size(); ++i) {
        views[i]->left_rms_px = fit.per_view_rms.at<double>(static_cast<int>(i), 0);
        views[i]->right_rms_px = fit.per_view_rms.at<double>(static_cast<int>(i), 1);
    }
}

// Marks the views whose RMS lies far above the others' (rule in the options); returns
// how many.
int rejectOutliers(const std::vector<PairReport*>& views, const ChessboardCalibrationOptions& o)
{
    std::vector<double> rms;
    for (const PairReport* v : views)
        rms.push_back(std::sqrt(
            0.5 * (*v->left_rms_px * *v->left_rms_px + *v->right_rms_px * *v->right_rms_px)));
    const double mid = median(rms);
    std::vector<double> deviations;
    for (double r : rms)
        deviations.push_back(std::abs(r - mid));
    const double sigma = kMadToSigma * median(deviations);
    const double threshold = std::max(mid + o.outlier_mads * sigma, o.outlier_floor_px);
    int rejected = 0;
    for (size_t i = 0; i < views.size(); ++i) {
        if (rms[i] <= threshold)
            continue;
        views[i]->used = false;
        views[i]->rejection = "outlier: reprojection RMS " + formatPx(rms[i]) +
                              " px, above the limit " + formatPx(threshold) +
                              " px (median of the pairs " + formatPx(mid) + " px)";
        ++rejected;
    }
    return rejected;
}

// Per-pair epipolar figures with the final calibration; returns the sums over corners.
struct EpipolarSums {
    double row_px = 0.0;
    double line_px = 0.0;
    size_t corners = 0;
};

void measureEpipolar(PairReport& pair, const StereoFit& fit, const cv::Mat& R1, const cv::Mat& R2,
                     const cv::Mat& P1, const cv::Mat& P2, EpipolarSums& used_sums)
{
    std::vector<cv::Point2f> left_rect, right_rect;
    cv::undistortPoints(pair.left_corners, left_rect, fit.K1, fit.D1, R1, P1, kUndistortCriteria);
    cv::undistortPoints(pair.right_corners, right_rect, fit.K2, fit.D2, R2, P2, kUndistortCriteria);
    std::vector<cv::Point2f> left_px, right_px;
    cv::undistortPoints(pair.left_corners, left_px, fit.K1, fit.D1, cv::noArray(), fit.K1,
                        kUndistortCriteria);
    cv::undistortPoints(pair.right_corners, right_px, fit.K2, fit.D2, cv::noArray(), fit.K2,
                        kUndistortCriteria);
    std::vector<cv::Vec3f> lines; // in the right image, a^2 + b^2 = 1
    cv::computeCorrespondEpilines(left_px, 1, fit.F, lines);
    double row = 0.0, line = 0.0;
    for (size_t i = 0; i < left_rect.size(); ++i) {
        row += std::abs(left_rect[i].y - right_rect[i].y);
        line += std::abs(lines[i][0] * right_px[i].x + lines[i][1] * right_px[i].y + lines[i][2]);
    }
    const double n = static_cast<double>(left_rect.size());
    pair.epipolar_error_px = row / n;
    pair.epipolar_distance_px = line / n;
    if (pair.used) {
        used_sums.row_px += row;
        used_sums.line_px += line;
        used_sums.corners += left_rect.size();
    }
}

std::vector<double> distortionVector(const cv::Mat& d)
{
    std::vector<double> out(d.ptr<double>(), d.ptr<double>() + d.total());
    out.resize(kDistortionCoefficients);
    return out;
}

std::string refuseTooFew(int usable, const ChessboardCalibrationOptions& o, size_t pairs,
                         const std::string& why)
{
    return "only " + std::to_string(usable) + " usable pair" + (usable == 1 ? "" : "s") + " of " +
           std::to_string(pairs) + why + ", at least " + std::to_string(o.min_pairs) +
           " are needed: take more views of the board, whole in both images";
}

} // namespace

// cv::stereoRectify's own ROIs come from a sparse grid of points along the border
// and may take in edge pixels that map outside the raw image (on the sample rig at alpha
// 0 it gives the whole 640x480 image, though the left camera's top row maps outside).
// Here every pixel's map is checked; the bounding box of the valid pixels shrinks by its
// worst edge until no edge holds an invalid pixel.
cv::Rect validRectifiedRegion(const CameraIntrinsics& camera, const cv::Matx33d& rectification,
                              const cv::Matx34d& projection, cv::Size size)
{
    cv::Mat map_x, map_y;
    cv::initUndistortRectifyMap(camera.camera_matrix, camera.distortion, rectification, projection,
                                size, CV_32FC1, map_x, map_y);
    const float max_x = static_cast<float>(size.width - 1);
    const float max_y = static_cast<float>(size.height - 1);
    cv::Mat valid(size, CV_8UC1);
    for (int y = 0; y < size.height; ++y)
        for (int x = 0; x < size.width; ++x) {
            const float mx = map_x.at<float>(y, x), my = map_y.at<float>(y, x);
            valid.at<uchar>(y, x) = mx >= 0.0f && mx <= max_x && my >= 0.0f && my <= max_y;
        }
    cv::Rect r = cv::boundingRect(valid);
    while (r.width > 0 && r.height > 0) {
        const int top = r.width - cv::countNonZero(valid(cv::Rect(r.x, r.y, r.width, 1)));
        const int bottom =
            r.width - cv::countNonZero(valid(cv::Rect(r.x, r.br().y - 1, r.width, 1)));
        const int left = r.height - cv::countNonZero(valid(cv::Rect(r.x, r.y, 1, r.height)));
        const int right =
            r.height - cv::countNonZero(valid(cv::Rect(r.br().x - 1, r.y, 1, r.height)));
        const int worst = std::max({top, bottom, left, right});
        if (worst == 0)
            break;
        if (worst == top) {
            ++r.y;
            --r.height;
        } else if (worst == bottom) {
            --r.height;
        } else if (worst == left) {
            ++r.x;
            --r.width;
        } else {
            --r.width;
        }
    }
    return r;
}

namespace {

bool detectBoard(const cv::Mat& gray, cv::Size inner_corners, std::vector<cv::Point2f>& corners)
{
    if (!cv::findChessboardCorners(gray, inner_corners, corners,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE |
                                       cv::CALIB_CB_FAST_CHECK)) {
        corners.clear();
        return false;
    }
    return true;
}

// cornerSubPix on each corner with the window findBoardCorners describes.
void refineBoardCorners(const cv::Mat& gray, cv::Size inner_corners,
                        std::vector<cv::Point2f>& corners)
{
    const std::vector<double> room = foreignLineDistances(corners, inner_corners);
    std::vector<cv::Point2f> one(1);
    for (size_t i = 0; i < corners.size(); ++i) {
        const int half = std::max(kSubpixMinHalfWindow,
                                  static_cast<int>(std::floor(kSubpixWindowFraction * room[i])));
        one[0] = corners[i];
        cv::cornerSubPix(gray, one, {half, half}, {-1, -1}, kSubpixCriteria);
        corners[i] = one[0];
    }
}

void checkGray(const cv::Mat& gray, const char* where)
{
    if (gray.type() != CV_8UC1)
        throw std::invalid_argument(std::string(where) + ": expected an 8-bit grayscale image");
}

} // namespace

bool findBoardCorners(const cv::Mat& gray, cv::Size inner_corners,
                      std::vector<cv::Point2f>& corners)
{
    corners.clear();
    checkGray(gray, "findBoardCorners");
    if (!detectBoard(gray, inner_corners, corners))
        return false;
    refineBoardCorners(gray, inner_corners, corners);
    return true;
}

bool findBoardCornersFast(const cv::Mat& gray, cv::Size inner_corners,
                          std::vector<cv::Point2f>& corners, int detect_width_px)
{
    corners.clear();
    checkGray(gray, "findBoardCornersFast");
    if (detect_width_px < 1)
        throw std::invalid_argument("findBoardCornersFast: detection width must be >= 1 px, got " +
                                    std::to_string(detect_width_px));
    if (gray.cols <= detect_width_px)
        return findBoardCorners(gray, inner_corners, corners);
    const double scale = static_cast<double>(gray.cols) / detect_width_px;
    cv::Mat small;
    cv::resize(gray, small,
               {detect_width_px, std::max(1, static_cast<int>(std::lround(gray.rows / scale)))},
               0.0, 0.0, cv::INTER_AREA);
    if (!detectBoard(small, inner_corners, corners))
        return false;
    // Pixel centres: small (x + 0.5) * scale is full-size x + 0.5, per axis.
    const double scale_x = static_cast<double>(gray.cols) / small.cols;
    const double scale_y = static_cast<double>(gray.rows) / small.rows;
    for (cv::Point2f& c : corners)
        c = {static_cast<float>((c.x + 0.5) * scale_x - 0.5),
             static_cast<float>((c.y + 0.5) * scale_y - 0.5)};
    refineBoardCorners(gray, inner_corners, corners);
    return true;
}

ChessboardCalibrationResult calibrateFromCorners(std::vector<PairReport> pairs, cv::Size image_size,
                                                 const ChessboardCalibrationOptions& options)
{
    validateChessboardOptions(options);
    const ChessboardSpec& board = options.board;
    const cv::Size grid = innerCorners(board);
    const size_t corner_count = static_cast<size_t>(board.cols * board.rows);

    ChessboardCalibrationResult result;
    result.pairs = std::move(pairs);
    std::vector<PairReport*> views;
    int images_with_board = 0;
    for (PairReport& p : result.pairs) {
        p.used = false;
        images_with_board += (p.left_found ? 1 : 0) + (p.right_found ? 1 : 0);
        if (p.left_found && p.right_found) {
            if (p.left_corners.size() != corner_count || p.right_corners.size() != corner_count)
                throw std::invalid_argument("pair " + p.left_path + " / " + p.right_path + ": " +
                                            std::to_string(p.left_corners.size()) + " and " +
                                            std::to_string(p.right_corners.size()) +
                                            " corners, the board has " +
                                            std::to_string(corner_count));
            alignCornerOrder(p.left_corners, p.right_corners, grid);
            p.used = true;
            p.rejection.clear();
            views.push_back(&p);
        } else {
            p.rejection = !p.left_found && !p.right_found ? "board not found in either image"
                          : p.left_found                  ? "board not found in the right image"
                                                          : "board not found in the left image";
        }
    }

    const std::string board_text = std::to_string(board.cols) + "x" + std::to_string(board.rows);
    if (images_with_board == 0)
        throw ChessboardCalibrationError(
            "the " + board_text + " board was found in none of the " +
            std::to_string(result.pairs.size() * 2) +
            " images: check that COLSxROWS counts the INNER corners of the board, where four "
            "squares meet (a board of 10x7 squares has 9x6 inner corners)");
    if (static_cast<int>(views.size()) < options.min_pairs)
        throw ChessboardCalibrationError(refuseTooFew(static_cast<int>(views.size()), options,
                                                      result.pairs.size(),
                                                      " (the board found in both images)"));

    std::vector<const PairReport*> fit_views(views.begin(), views.end());
    StereoFit fit = fitStereo(fit_views, image_size, board);
    recordPerViewRms(views, fit);
    result.outliers_dropped = rejectOutliers(views, options);
    if (result.outliers_dropped > 0) {
        std::erase_if(views, [](const PairReport* p) { return !p->used; });
        if (static_cast<int>(views.size()) < options.min_pairs)
            throw ChessboardCalibrationError(
                refuseTooFew(static_cast<int>(views.size()), options, result.pairs.size(),
                             " after dropping " + std::to_string(result.outliers_dropped) +
                                 " outlier pair(s) whose corners fit far worse than the others'"));
        fit_views.assign(views.begin(), views.end());
        fit = fitStereo(fit_views, image_size, board);
        recordPerViewRms(views, fit);
    }

    // X_right = R X_left + T: a right camera to the right of the left one has T.x < 0.
    const cv::Vec3d t(fit.T.ptr<double>());
    if (std::abs(t[0]) < std::hypot(t[1], t[2]))
        throw ChessboardCalibrationError(
            "the cameras are displaced more vertically than horizontally (T = [" +
            std::to_string(t[0]) + ", " + std::to_string(t[1]) + ", " + std::to_string(t[2]) +
            "] m): only side-by-side rigs are supported");
    if (t[0] > 0.0)
        throw ChessboardCalibrationError(
            "the right images come from the camera on the left (T.x = +" + std::to_string(t[0]) +
            " m): are the left and right images swapped?");

    cv::Mat R1, R2, P1, P2, Q;
    StereoCalibration& c = result.calibration;
    cv::stereoRectify(fit.K1, fit.D1, fit.K2, fit.D2, image_size, fit.R, fit.T, R1, R2, P1, P2, Q,
                      cv::CALIB_ZERO_DISPARITY, options.alpha, image_size);

    EpipolarSums sums;
    for (PairReport& p : result.pairs)
        if (p.left_found && p.right_found)
            measureEpipolar(p, fit, R1, R2, P1, P2, sums);

    c.kind = StereoCalibration::Kind::Full;
    c.left.camera_matrix = cv::Matx33d(fit.K1);
    c.left.distortion = distortionVector(fit.D1);
    c.right.camera_matrix = cv::Matx33d(fit.K2);
    c.right.distortion = distortionVector(fit.D2);
    c.R = cv::Matx33d(fit.R);
    c.T = t;
    c.R1 = cv::Matx33d(R1);
    c.R2 = cv::Matx33d(R2);
    c.P1 = cv::Matx34d(P1);
    c.P2 = cv::Matx34d(P2);
    c.Q = cv::Matx44d(Q);
    c.rectified = rectifiedFromProjections(c.P1, c.P2, image_size);
    c.valid_roi_left = validRectifiedRegion(c.left, c.R1, c.P1, image_size);
    c.valid_roi_right = validRectifiedRegion(c.right, c.R2, c.P2, image_size);
    c.board = board;

    result.pairs_used = static_cast<int>(views.size());
    result.left_rms_px = fit.left_rms_px;
    result.right_rms_px = fit.right_rms_px;
    result.rms_px = fit.rms_px;
    result.epipolar_error_px = sums.row_px / static_cast<double>(sums.corners);
    result.epipolar_distance_px = sums.line_px / static_cast<double>(sums.corners);
    result.baseline_m = cv::norm(t);
    c.rms_px = result.rms_px;
    c.epipolar_error_px = result.epipolar_error_px;
    validateCalibration(c, "chessboard calibration");
    return result;
}

ChessboardCalibrationResult calibrateChessboard(const std::vector<std::string>& left_paths,
                                                const std::vector<std::string>& right_paths,
                                                const ChessboardCalibrationOptions& options,
                                                const CornerProgressCallback& progress)
{
    validateChessboardOptions(options);
    if (left_paths.empty())
        throw ChessboardCalibrationError("no image pairs given");
    if (left_paths.size() != right_paths.size())
        throw ChessboardCalibrationError(std::to_string(left_paths.size()) + " left images but " +
                                         std::to_string(right_paths.size()) +
                                         " right images: the pairs are taken in order, one of "
                                         "each");
    const cv::Size grid = innerCorners(options.board);
    std::vector<PairReport> pairs(left_paths.size());
    // The size of the calibration is that of the first pair with the board in both images;
    // a pair without the board is reported and skipped whatever its size (a glob such as
    // 'left*.jpg' may catch an unrelated picture), but every pair used must match.
    cv::Size image_size;
    const PairReport* first_used = nullptr;
    auto checkSize = [&](const cv::Mat& image, const std::string& path, const PairReport& pair) {
        if (image.size() == image_size)
            return;
        throw ChessboardCalibrationError(
            "image sizes differ in pair " + pair.left_path + " / " + pair.right_path + ": " + path +
            " is " + describeSize(image.size()) + " but the first pair used (" +
            first_used->left_path + " / " + first_used->right_path + ") is " +
            describeSize(image_size) +
            "; all the pairs used (the board found in both images) must come from the same "
            "two cameras at one resolution");
    };
    for (size_t i = 0; i < pairs.size(); ++i) {
        PairReport& p = pairs[i];
        p.left_path = left_paths[i];
        p.right_path = right_paths[i];
        const cv::Mat left = readGray(p.left_path);
        const cv::Mat right = readGray(p.right_path);
        if (image_size.empty())
            image_size = left.size(); // a fallback until a pair is used
        p.left_found = findBoardCorners(left, grid, p.left_corners);
        p.right_found = findBoardCorners(right, grid, p.right_corners);
        if (progress)
            progress({static_cast<int>(i) + 1, static_cast<int>(pairs.size()), &p});
        if (!p.left_found || !p.right_found)
            continue;
        if (first_used == nullptr) {
            first_used = &p;
            image_size = left.size();
        }
        checkSize(left, p.left_path, p);
        checkSize(right, p.right_path, p);
    }
    return calibrateFromCorners(std::move(pairs), image_size, options);
}

cv::Mat renderRectifiedPreview(const StereoCalibration& calibration, const cv::Mat& left_raw,
                               const cv::Mat& right_raw, cv::Size inner_corners,
                               const std::vector<cv::Point2f>& left_corners,
                               const std::vector<cv::Point2f>& right_corners, int line_step_px)
{
    const cv::Size size = toCv(calibration.rectified.image_size);
    checkFrameSize(calibration, left_raw.size(), "preview left image");
    checkFrameSize(calibration, right_raw.size(), "preview right image");
    if (line_step_px < 1)
        throw std::invalid_argument("preview: line step must be >= 1 px, got " +
                                    std::to_string(line_step_px));
    const Rectifier rectifier(calibration);
    cv::Mat left_rect, right_rect;
    rectifier.rectifyLeft(left_raw, left_rect);
    rectifier.rectifyRight(right_raw, right_rect);

    cv::Mat canvas(size.height, 2 * size.width, CV_8UC3);
    cv::Mat left_half = canvas(cv::Rect(0, 0, size.width, size.height));
    cv::Mat right_half = canvas(cv::Rect(size.width, 0, size.width, size.height));
    cv::cvtColor(left_rect, left_half, cv::COLOR_GRAY2BGR);
    cv::cvtColor(right_rect, right_half, cv::COLOR_GRAY2BGR);

    auto drawCorners = [&](cv::Mat& half, const std::vector<cv::Point2f>& raw,
                           const CameraIntrinsics& camera, const cv::Matx33d& rotation,
                           const cv::Matx34d& projection) {
        if (raw.empty())
            return;
        std::vector<cv::Point2f> rectified;
        cv::undistortPoints(raw, rectified, camera.camera_matrix, camera.distortion, rotation,
                            projection, kUndistortCriteria);
        cv::drawChessboardCorners(half, inner_corners, rectified, true);
    };
    if (calibration.kind == StereoCalibration::Kind::Full) {
        drawCorners(left_half, left_corners, calibration.left, calibration.R1, calibration.P1);
        drawCorners(right_half, right_corners, calibration.right, calibration.R2, calibration.P2);
    }
    const cv::Scalar line_colour(0, 255, 0);
    for (int y = line_step_px; y < size.height; y += line_step_px)
        cv::line(canvas, {0, y}, {canvas.cols - 1, y}, line_colour, 1, cv::LINE_8);
    return canvas;
}

void writeRectifiedPreview(const ChessboardCalibrationResult& result, const std::string& png_path,
                           int line_step_px)
{
    const auto first = std::find_if(result.pairs.begin(), result.pairs.end(),
                                    [](const PairReport& p) { return p.used; });
    if (first == result.pairs.end())
        throw ChessboardCalibrationError("preview " + png_path + ": no pair was used");
    const ChessboardSpec& board = *result.calibration.board;
    const cv::Mat canvas = renderRectifiedPreview(
        result.calibration, readGray(first->left_path), readGray(first->right_path),
        innerCorners(board), first->left_corners, first->right_corners, line_step_px);
    // Encoded here rather than by cv::imwrite, which picks the format from the file's
    // extension: the preview is PNG whatever the name.
    std::vector<uchar> bytes;
    if (!cv::imencode(".png", canvas, bytes))
        throw ChessboardCalibrationError("preview " + png_path + ": PNG encoding failed");
    std::ofstream out(png_path, std::ios::binary | std::ios::trunc);
    if (out)
        out.write(reinterpret_cast<const char*>(bytes.data()),
                  static_cast<std::streamsize>(bytes.size()));
    if (!out || !out.flush())
        throw ChessboardCalibrationError("cannot write preview " + png_path + ": " +
                                         errnoText(errno));
}

} // namespace stereod
