#pragma once
// What a set of chessboard views covers, for collecting calibration views from live
// cameras: where each view puts the board in each image and how it is turned, whether a
// new view adds anything to the accepted ones (a near-duplicate does not), and what is
// still missing.
//
// Why these measures: a calibration is only as good as the views it is fitted to. The
// lens distortion is pinned down only where corners have been seen, so every part of
// both images needs corners (a 3x3 grid of cells per camera); the focal length and the
// principal point are pinned down only by boards seen at an angle (turned about the
// vertical and about the horizontal axis, both ways); and views at different distances
// separate the focal length from the board's distance. Views that repeat an accepted one
// add weight to that view without adding information.
//
// The board's turn is measured from the homography between the board and the image with
// an assumed pinhole camera (focal length guessed, principal point at the image centre,
// no distortion): the calibration is not known yet. The angles are approximate (a wrong
// focal length guess scales them), their signs are not.

#include <array>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/types.hpp>

namespace stereod {

// Where a board lies in one image and how it is turned, from its inner corners.
struct BoardAppearance {
    // Mean of the corners, as fractions of the image's width and height (0..1).
    cv::Point2d centre_frac;
    // Square root of the area of the corners' outline (the quadrilateral of the four
    // outer corners) over the image's area: about the fraction of the image's side the
    // board spans. Grows as the board comes nearer.
    double size_frac = 0.0;
    // Turn of the board about the image's vertical axis, degrees: > 0 when its side on
    // the image's right is farther from the camera than its side on the left.
    double yaw_deg = 0.0;
    // Turn about the image's horizontal axis, degrees: > 0 when its side at the bottom of
    // the image is farther than its side at the top.
    double pitch_deg = 0.0;
    // Turn within the image: the angle of the board's rows against the image's rows,
    // degrees in (-90, 90], > 0 clockwise as seen in the image (y down). The detector may
    // list a row either way round, hence modulo 180.
    double roll_deg = 0.0;
};

// Measures a board in an image. `corners` are the board's inner corners row by row
// (cols x rows of `inner_corners`, as findBoardCorners gives them, in either of the
// detector's orders); `focal_px` is the guessed focal length (<= 0: the image's width,
// a lens of about 53 degrees across). Throws std::invalid_argument when the corner count
// does not match the board or the image size is empty.
BoardAppearance describeBoard(const std::vector<cv::Point2f>& corners, cv::Size inner_corners,
                              cv::Size image_size, double focal_px = 0.0);

struct CoverageOptions {
    // A cell of the 3x3 grid counts as covered in a camera once this many corners of the
    // accepted views have landed in it: a board grazing a cell says little about the
    // distortion there. (OpenCV's 13 sample views put 4 and 9 corners into the left
    // image's top-left and bottom-left cells, slivers of boards that lie elsewhere, and
    // nothing at all into the outer 150 px on the left: those cells want more views.)
    int min_corners_per_cell = 10;
    // A view fills a tilt bucket when the board is turned at least this much that way.
    double tilt_deg = 15.0;
    // Distance buckets by the board's apparent size (BoardAppearance::size_frac): "near"
    // from near_size_frac up, "far" up to far_size_frac.
    double near_size_frac = 0.5;
    double far_size_frac = 0.3;
    // A view is a near-duplicate of an accepted view when, in both cameras, its board's
    // centre lies within duplicate_position_frac of the image's diagonal of the other's,
    // its size differs by less than duplicate_size_ratio (relative), and its yaw, pitch
    // and roll each differ by less than duplicate_tilt_deg.
    double duplicate_position_frac = 0.05;
    double duplicate_size_ratio = 0.10;
    double duplicate_tilt_deg = 5.0;
    // The guessed focal length for describeBoard (<= 0: the image's width).
    double focal_px = 0.0;
};

// One view of the board: its appearance in each camera.
struct BoardView {
    BoardAppearance left;
    BoardAppearance right;
};

// What a candidate view would add.
struct ViewJudgement {
    BoardView view;
    // The accepted view (0-based index) that this one nearly repeats, if any.
    std::optional<int> duplicate_of;
    // Why it is a near-duplicate, for people: the differences to that view.
    std::string reason;
};

// The kinds of view the accepted ones lack. Names are for people ("top-left",
// "left edge nearer", "near").
struct CoverageGaps {
    std::vector<std::string> left_cells; // cells of the left image with too few corners
    std::vector<std::string> right_cells;
    std::vector<std::string> tilts;
    std::vector<std::string> distances;
    bool complete() const
    {
        return left_cells.empty() && right_cells.empty() && tilts.empty() && distances.empty();
    }
};

// One line for people: "missing: left image top-left, top-right; right image top-left;
// tilts: left edge nearer; distances: far", or "coverage complete".
std::string formatGaps(const CoverageGaps& gaps);

// The accepted views of a live calibration and what they cover.
//
// Thread-bound: one thread judges and adds views.
class CalibrationCoverage {
  public:
    static constexpr int kGridCols = 3;
    static constexpr int kGridRows = 3;
    // Tilt buckets, in this order: yaw < 0, yaw > 0, pitch < 0, pitch > 0.
    static constexpr int kTiltBuckets = 4;
    // Distance buckets: near, far.
    static constexpr int kDistanceBuckets = 2;

    // Throws std::invalid_argument for an empty image size, a board with fewer than 2
    // corners either way, or options out of range.
    CalibrationCoverage(cv::Size image_size, cv::Size inner_corners, CoverageOptions options = {});

    // Measures a view (board corners in both images, as describeBoard takes them) and
    // compares it with every accepted view.
    ViewJudgement judge(const std::vector<cv::Point2f>& left_corners,
                        const std::vector<cv::Point2f>& right_corners) const;

    // Accepts a view (judged or not): its corners count towards the cells, its turn and
    // size towards the buckets.
    void accept(const std::vector<cv::Point2f>& left_corners,
                const std::vector<cv::Point2f>& right_corners);

    CoverageGaps gaps() const;

    const std::vector<BoardView>& views() const noexcept { return views_; }
    // Corners of the accepted views per cell, row by row (top-left first).
    const std::array<int, kGridCols * kGridRows>& leftCellCorners() const noexcept
    {
        return left_cells_;
    }
    const std::array<int, kGridCols * kGridRows>& rightCellCorners() const noexcept
    {
        return right_cells_;
    }
    // Accepted views per tilt bucket (order above) and distance bucket (near, far).
    const std::array<int, kTiltBuckets>& tiltViews() const noexcept { return tilt_views_; }
    const std::array<int, kDistanceBuckets>& distanceViews() const noexcept
    {
        return distance_views_;
    }

    // The people's names of cells and buckets, in the orders above.
    static const char* cellName(int index);
    static const char* tiltName(int bucket);
    static const char* distanceName(int bucket);

  private:
    BoardView describe(const std::vector<cv::Point2f>& left_corners,
                       const std::vector<cv::Point2f>& right_corners) const;
    void countCorners(const std::vector<cv::Point2f>& corners,
                      std::array<int, kGridCols * kGridRows>& cells) const;

    cv::Size image_size_;
    cv::Size inner_corners_;
    CoverageOptions options_;
    std::vector<BoardView> views_;
    std::array<int, kGridCols * kGridRows> left_cells_{};
    std::array<int, kGridCols * kGridRows> right_cells_{};
    std::array<int, kTiltBuckets> tilt_views_{};
    std::array<int, kDistanceBuckets> distance_views_{};
};

} // namespace stereod
