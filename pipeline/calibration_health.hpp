#pragma once
// How well a calibration still rectifies, measured without a chessboard: sparse features
// (ORB) matched between the rectified left and right images, and how far apart the rows of
// the matches are. After a good rectification matching points lie on the same row (within
// about 0.1 px); a knock, heat or a loose mount turns one camera and the rows drift apart,
// while every depth still looks valid. Swapped cameras show as matches whose disparity is
// negative.
//
// The verdict comes from a model of the row offset over the image fitted to the matches,
// not from a median of them: a roll moves the rows down on one side and up on the other,
// and a median of the two reads zero.
//
// The model. In the rectified right image take x_r, y (pixels), its principal point
// (cx + doffs, cy), the focal length f, and u = (x_r - cx - doffs) / f, v = (y - cy) / f.
// A small turn of the right camera away from the rotation the rectification gives it
// moves its image points, to first order in the angles (the rotational image motion of a
// camera; Longuet-Higgins and Prazdny, 1980), by
//     pitch a (about x):  dv = a (1 + v^2)
//     yaw   b (about y):  dv = -b u v            (and du = -b (1 + u^2): disparities)
//     roll  c (about z):  dv = -c u
// and a vertical scale difference s between the two images (focal lengths that differ in
// y) by dv = s v. A row offset of the principal points is a constant, which pitch already
// has to first order. So matching rows are apart, right minus left, by
//     dy(x, y) = offset (1 + v^2) - tan(roll) f u + s f v - b f u v          pixels
// four parameters: the offset at the principal point (pitch), the roll (rows apart in
// proportion to the column: an angle, the same fault on an image of any width), the
// vertical scale and the yaw (in proportion to column times row, over f). Left out:
//  - a vertical shift t_y of the right camera, which moves rows by d t_y / B (d the
//    disparity, B the baseline): on a flat scene, a board or a wall, d is linear in x and
//    y, so that term cannot be told from offset, roll and scale; and no turn of R2 undoes
//    it;
//  - lens distortion the calibration left (higher orders in u and v): it stays in the
//    residuals, where it shows as noise.
// The fit is robust: matches that a repeating pattern (a chessboard's squares) puts a
// row or a period off agree with no model near the truth, so a RANSAC search (the offset
// and roll that most matches agree with within 1 px; scale and yaw would let a model bend
// through the right matches in one part of the image and a group a period off in
// another) followed by iteratively reweighted least squares of all four terms with
// Tukey's redescending weight gives them no say. Scale and yaw have priors (zero, 0.1 %
// and 0.1 deg): the matches of one pair, often in a few clusters, hardly tell them from
// roll and offset. Before the fit, matches must pass Lowe's ratio test on their
// descriptors, lie within max_row_offset_px rows (the epipolar gate), correlate clearly,
// and be one to one (no right point matched from two left points).
//
// The verdict reads the model, not single matches: its largest |dy| where the matches are
// (measured there, not extrapolated to corners without a match), its offset at the image
// centre, and the roll in degrees.
//
// Thread-bound: a CalibrationHealthChecker keeps its feature detector and buffers. The free
// functions are reentrant.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "base/name_table.hpp"
#include "pipeline/calibration.hpp"

namespace stereod {

struct HealthSettings {
    int max_features = 2000;         // ORB keypoints per image
    double max_row_offset_px = 24.0; // matches further apart in rows are not the same point
    int min_matches = 30;            // fewer the model explains: "unknown", no verdict
    // Verdict on the model. Degraded: rows more than ok_row_error_px apart somewhere in the
    // matches' area, or a roll of degraded_roll_deg or more. Failed: rows failed_offset_px
    // or more apart at the principal point (the middle of the image, where readings come
    // from, is off too), failed_row_error_px anywhere in the area, or a roll of
    // failed_roll_deg or more. A roll is judged by its angle, so that the same turn of the
    // camera gets the same verdict on an image of any width.
    double ok_row_error_px = 0.7;
    double degraded_roll_deg = 0.2;
    double failed_offset_px = 2.0;
    double failed_row_error_px = 6.0;
    double failed_roll_deg = 1.0;
    // Above this fraction of matches with a negative disparity the cameras are swapped.
    double swapped_fraction = 0.6;
};

enum class HealthState { Unknown, Ok, Degraded, Failed };

// The states as status and `check-calibration` write them, one table for naming and
// parsing them.
inline constexpr NameTable<HealthState, 4> kHealthStates{{{
    {HealthState::Unknown, "unknown"},
    {HealthState::Ok, "ok"},
    {HealthState::Degraded, "degraded"},
    {HealthState::Failed, "failed"},
}}};
static_assert(kHealthStates.wellFormed());

// "unknown", "ok", "degraded", "failed".
const char* healthStateName(HealthState state) noexcept;

// One match between the rectified images, in pixels.
struct RowMatch {
    cv::Point2f left;
    cv::Point2f right;
};

// The row offset over the image, fitted to matches (the model in the comment at the top).
struct RowOffsetModel {
    // The image the model is for: focal length and the right image's principal point.
    double focal_px = 0.0;
    cv::Point2d right_principal_px;
    // The four terms.
    double pitch_px = 0.0;       // right row - left row at the principal point: f x pitch
    double roll_deg = 0.0;       // the right image turned counter-clockwise as seen (+)
    double vertical_scale = 0.0; // right image rows stretched by this fraction about cy
    double yaw_deg = 0.0;        // the right camera turned outwards, away from the left (+)
    // Right row - left row at the image centre, where readings come from (not the principal
    // point, which a shifted crop such as Middlebury's puts far from it).
    double offset_px = 0.0;
    // The largest |right row - left row| the model gives at the matches it explains: over
    // the part of the image they cover, never extrapolated to corners without a match.
    double max_row_error_px = 0.0;
    double row_error_px = 0.0; // signed: right - left where |dy| is largest
    // 1.4826 x the median absolute residual of the matches the model explains.
    double residual_px = 0.0;

    // Right row - left row the model gives at a point of the right image.
    double rowOffsetAt(cv::Point2d right) const;
};

struct HealthMeasurement {
    HealthState state = HealthState::Unknown;
    // Machine code of the verdict: "not_enough_matches", "row_offset", "roll",
    // "cameras_swapped", or "" when ok.
    std::string reason;
    int matches = 0; // matches the model explains, behind every figure
    RowOffsetModel model;
    double row_offset_px = 0.0;     // signed median of right row - left row
    double row_offset_p90_px = 0.0; // 90th percentile of |right row - left row|
    double negative_disparity_fraction = 0.0;
    std::vector<RowMatch> used; // the matches behind the figures
};

// The verdict for the figures of a measurement (state and reason are set).
void classifyHealth(HealthMeasurement& measurement, const HealthSettings& settings);

// Which terms a fit has: all four, or only those a turn of R2 can undo (pitch and roll;
// the vertical scale and the yaw stay 0).
enum class ModelTerms { All, PitchAndRoll };

// The model fitted to `matches`, robustly (see the top). `geometry` gives the focal length,
// principal points and image size. Returns false when fewer than 4 matches agree on one;
// `inliers` receives the matches the model explains.
bool fitRowOffsetModel(const std::vector<RowMatch>& matches, const RectifiedGeometry& geometry,
                       RowOffsetModel& model, std::vector<RowMatch>* inliers = nullptr,
                       ModelTerms terms = ModelTerms::All);

class CalibrationHealthChecker {
  public:
    // `geometry`: the rectified images' (focal length, principal point, doffs).
    explicit CalibrationHealthChecker(const RectifiedGeometry& geometry,
                                      const HealthSettings& settings = {});
    ~CalibrationHealthChecker();

    // left, right: a rectified CV_8UC1 pair of the geometry's image size.
    HealthMeasurement measure(const cv::Mat& left, const cv::Mat& right);

    // The figures over several measurements (their matches pooled), classified.
    HealthMeasurement pool(const std::vector<HealthMeasurement>& measurements) const;

    const HealthSettings& settings() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The small rotation of the right camera, about its rectified x axis (pitch: moves every
// row) and z axis (roll: moves rows in proportion to the column), that brings the rows of
// `matches` together: the model of those two terms alone fitted to them (the rotation
// that leaves the least row error, whatever scale and yaw would explain); never about the y axis,
// which would shift disparities and so every depth. Returns the calibration with R2 (and
// the rectification maps made from it) turned by that rotation; P1, P2 and Q, hence depth,
// stay as they were, and so do R and T (the rig as calibrated). A rectified-only
// calibration (a factory-rectified camera) becomes its full form (fullFromRectified in
// pipeline/calibration_formats.hpp) with R2 turned: the one way the format has to say
// that the right images must be turned. Throws std::invalid_argument when the matches are
// too few to fit the model.
// `rotation_deg` receives the pitch and roll applied, in degrees.
StereoCalibration correctRightRotation(const StereoCalibration& calibration,
                                       const std::vector<RowMatch>& matches,
                                       cv::Vec2d* rotation_deg = nullptr);

} // namespace stereod
