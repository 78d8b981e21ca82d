// Chessboard stereo calibration on a real rig: OpenCV's 13 sample pairs (640x480, wide
// angle, 9x6 inner corners; Debian package opencv-doc). Targets of the calibration issue:
// all 13 pairs used, stereo RMS <= 0.30 px, mean epipolar error <= 0.15 px; depth on the
// board within 5 % of the board's pose in at least 9 of the 13 pairs. Then the refusals.
//
// The square size of the sample board is not published: 25 mm is assumed. Every check
// here is independent of it (the baseline and all depths scale with it together).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/matcher.hpp"
#include "pipeline/rectifier.hpp"
#include "pipeline/stereo_processor.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/files.hpp"
#include "tests/support/temp_dir.hpp"

namespace stereod {
namespace {

const std::string kSamples = test::opencvSamplesDir() + "/";
constexpr double kSquareM = 0.025;
const cv::TermCriteria kUndistort(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12);

using test::chessboardSample;
using test::chessboardSamples;

ChessboardCalibrationOptions sampleOptions()
{
    ChessboardCalibrationOptions options;
    options.board = {9, 6, kSquareM};
    return options;
}

std::string basename(const std::string& path)
{
    return std::filesystem::path(path).filename().string();
}

class ChessboardCalibrationTest : public ::testing::Test {
  protected:
    // Corner search and calibration of the 13 pairs, once for all tests.
    static void SetUpTestSuite()
    {
        std::vector<std::string> left, right;
        chessboardSamples(left, right);
        result_ = new ChessboardCalibrationResult(
            calibrateChessboard(left, right, sampleOptions(), [](const CornerProgress& p) {
                ASSERT_NE(p.pair, nullptr);
                std::printf("corners: pair %d/%d %s %s: %s\n", p.index, p.count,
                            basename(p.pair->left_path).c_str(),
                            basename(p.pair->right_path).c_str(),
                            p.pair->left_found && p.pair->right_found ? "found" : "not found");
            }));
    }
    static void TearDownTestSuite()
    {
        delete result_;
        result_ = nullptr;
    }

    static const ChessboardCalibrationResult& result() { return *result_; }

  private:
    static ChessboardCalibrationResult* result_;
};

ChessboardCalibrationResult* ChessboardCalibrationTest::result_ = nullptr;

double rotationAngleDeg(const cv::Matx33d& r)
{
    cv::Vec3d rvec;
    cv::Rodrigues(r, rvec);
    return cv::norm(rvec) * 180.0 / CV_PI;
}

TEST_F(ChessboardCalibrationTest, UsesAllThirteenRealPairsWithinTheTargets)
{
    const ChessboardCalibrationResult& r = result();
    std::printf(
        "[accuracy] pair        found  RMS left  RMS right  epipolar (rows)  epipolar (F)\n");
    for (const PairReport& p : r.pairs) {
        std::printf("[accuracy] %-11s %s/%s   %8.3f  %9.3f  %15.3f  %12.3f  %s\n",
                    basename(p.left_path).c_str(), p.left_found ? "L" : "-",
                    p.right_found ? "R" : "-", p.left_rms_px.value_or(NAN),
                    p.right_rms_px.value_or(NAN), p.epipolar_error_px.value_or(NAN),
                    p.epipolar_distance_px.value_or(NAN), p.rejection.c_str());
    }
    std::printf("[accuracy] chessboard calibration: %d pairs used; RMS %.3f px (left alone "
                "%.3f, right alone %.3f); epipolar error %.3f px (rectified rows), %.3f px "
                "(distance to F's lines); baseline %.4f m with %.0f mm squares\n",
                r.pairs_used, r.rms_px, r.left_rms_px, r.right_rms_px, r.epipolar_error_px,
                r.epipolar_distance_px, r.baseline_m, kSquareM * 1000.0);

    ASSERT_EQ(r.pairs.size(), 13u);
    EXPECT_EQ(r.pairs_used, 13);
    EXPECT_EQ(r.outliers_dropped, 0);
    for (const PairReport& p : r.pairs) {
        EXPECT_TRUE(p.used) << p.left_path << ": " << p.rejection;
        EXPECT_TRUE(p.rejection.empty()) << p.left_path;
    }
    // Targets of the issue; OpenCV's stereo_calib sample reports 0.634 px and 0.445 px (its
    // epipolar figure adds the distances in both images, about twice epipolar_distance_px).
    EXPECT_LE(r.rms_px, 0.30);
    EXPECT_LE(r.epipolar_error_px, 0.15);
    EXPECT_LE(r.epipolar_distance_px, 0.15);

    const StereoCalibration& c = r.calibration;
    EXPECT_EQ(c.kind, StereoCalibration::Kind::Full);
    ASSERT_TRUE(c.board.has_value());
    EXPECT_EQ(c.board->cols, 9);
    EXPECT_EQ(c.board->rows, 6);
    EXPECT_EQ(c.board->square_m, kSquareM);
    EXPECT_EQ(c.rms_px, r.rms_px);
    EXPECT_EQ(c.epipolar_error_px, r.epipolar_error_px);
    EXPECT_EQ(c.rectified.image_size, (ImageSize{640, 480}));
    EXPECT_EQ(c.left.distortion.size(), 4u);
    // alpha 0: (nearly) every rectified pixel has image data in both cameras, and every
    // pixel of the valid regions does.
    for (const auto& [camera, rotation, projection, roi] :
         {std::tuple(c.left, c.R1, c.P1, c.valid_roi_left),
          std::tuple(c.right, c.R2, c.P2, c.valid_roi_right)}) {
        EXPECT_GE(roi.area(), 0.99 * 640 * 480) << roi;
        cv::Mat map_x, map_y;
        cv::initUndistortRectifyMap(camera.camera_matrix, camera.distortion, rotation, projection,
                                    {640, 480}, CV_32FC1, map_x, map_y);
        double min_x, max_x, min_y, max_y;
        cv::minMaxLoc(map_x(roi), &min_x, &max_x);
        cv::minMaxLoc(map_y(roi), &min_y, &max_y);
        EXPECT_GE(min_x, 0.0);
        EXPECT_LE(max_x, 639.0);
        EXPECT_GE(min_y, 0.0);
        EXPECT_LE(max_y, 479.0);
    }

    // A plausible side-by-side rig: nearly parallel cameras, displaced along x, the right
    // camera on the right.
    EXPECT_LT(rotationAngleDeg(c.R), 3.0);
    EXPECT_LT(c.T[0], 0.0);
    EXPECT_GT(std::abs(c.T[0]), 0.99 * cv::norm(c.T));
    EXPECT_NEAR(r.baseline_m, cv::norm(c.T), 1e-12);
    EXPECT_NEAR(c.rectified.baseline_m, r.baseline_m, 1e-9);

    // The baseline, independently per pair: the board's pose seen by each camera alone
    // (solvePnP) puts the right camera's centre somewhere in the left camera's frame.
    std::vector<cv::Point3f> board;
    for (int y = 0; y < 6; ++y)
        for (int x = 0; x < 9; ++x)
            board.emplace_back(static_cast<float>(x * kSquareM), static_cast<float>(y * kSquareM),
                               0.0f);
    std::vector<double> baselines;
    for (const PairReport& p : r.pairs) {
        cv::Vec3d rl, tl, rr, tr;
        ASSERT_TRUE(
            cv::solvePnP(board, p.left_corners, c.left.camera_matrix, c.left.distortion, rl, tl));
        ASSERT_TRUE(cv::solvePnP(board, p.right_corners, c.right.camera_matrix, c.right.distortion,
                                 rr, tr));
        cv::Matx33d Rl, Rr;
        cv::Rodrigues(rl, Rl);
        cv::Rodrigues(rr, Rr);
        // Camera centres in board coordinates: -R^T t.
        baselines.push_back(cv::norm(Rl.t() * tl - Rr.t() * tr));
    }
    std::sort(baselines.begin(), baselines.end());
    const double pnp_baseline = baselines[baselines.size() / 2];
    std::printf("[accuracy] baseline %.4f m; from each pair's poses: median %.4f m, range "
                "%.4f..%.4f m\n",
                r.baseline_m, pnp_baseline, baselines.front(), baselines.back());
    EXPECT_NEAR(r.baseline_m, pnp_baseline, 0.01 * pnp_baseline);
}

TEST_F(ChessboardCalibrationTest, RoundTripsThroughTheCalibrationFile)
{
    // Saved, loaded and saved again: the same text, so every number came back exactly
    // (the format writes the shortest text that reads back to the same double).
    const StereoCalibration& c = result().calibration;
    test::TempDir dir;
    const std::string first = dir.file("first.yaml"), second = dir.file("second.yaml");
    saveCalibration(c, first);
    const StereoCalibration loaded = loadCalibration(first);
    saveCalibration(loaded, second);
    EXPECT_EQ(test::readFile(first), test::readFile(second));
    // And what went in is what was calibrated.
    EXPECT_EQ(loaded.P2, c.P2);
    EXPECT_EQ(loaded.left.distortion, c.left.distortion);
    EXPECT_EQ(loaded.rms_px, result().rms_px);
    EXPECT_EQ(loaded.epipolar_error_px, result().epipolar_error_px);
    ASSERT_TRUE(loaded.board.has_value());
    EXPECT_EQ(loaded.board->cols, 9);
    EXPECT_EQ(loaded.board->square_m, kSquareM);
    EXPECT_EQ(loaded.valid_roi_left, c.valid_roi_left);
}

// The board's plane of each pair, in the rectified left camera's frame (by its pose:
// solvePnP on the detected corners), and the nearest corner's depth over all pairs.
struct BoardPlane {
    cv::Vec3d normal; // rectified left camera frame
    double offset_m;  // normal . X = offset for points X of the board

    double depthAt(const RectifiedGeometry& g, double x, double y) const
    {
        const cv::Vec3d ray((x - g.cx_px) / g.focal_px, (y - g.cy_px) / g.focal_px, 1.0);
        return offset_m / normal.dot(ray);
    }
};

std::vector<BoardPlane> boardPlanes(const ChessboardCalibrationResult& r, double& nearest_m)
{
    const StereoCalibration& c = r.calibration;
    std::vector<cv::Point3f> board;
    for (int y = 0; y < 6; ++y)
        for (int x = 0; x < 9; ++x)
            board.emplace_back(static_cast<float>(x * kSquareM), static_cast<float>(y * kSquareM),
                               0.0f);
    std::vector<BoardPlane> planes;
    nearest_m = HUGE_VAL;
    for (const PairReport& p : r.pairs) {
        cv::Vec3d rvec, tvec;
        EXPECT_TRUE(cv::solvePnP(board, p.left_corners, c.left.camera_matrix, c.left.distortion,
                                 rvec, tvec));
        cv::Matx33d rotation;
        cv::Rodrigues(rvec, rotation);
        const cv::Vec3d normal = c.R1 * (rotation * cv::Vec3d(0, 0, 1));
        const cv::Vec3d origin = c.R1 * tvec;
        planes.push_back({normal, normal.dot(origin)});
        for (const cv::Point3f& corner : board) {
            const cv::Vec3d x = c.R1 * (rotation * cv::Vec3d(corner.x, corner.y, corner.z) + tvec);
            nearest_m = std::min(nearest_m, x[2]);
        }
    }
    return planes;
}

// The board in the rectified left image: the quadrilateral of the outer inner corners.
cv::Mat boardMask(const StereoCalibration& c, const PairReport& p, std::vector<cv::Point2f>& rect)
{
    cv::undistortPoints(p.left_corners, rect, c.left.camera_matrix, c.left.distortion, c.R1, c.P1,
                        kUndistort);
    const std::vector<cv::Point> outline = {rect[0], rect[8], rect[53], rect[45]};
    cv::Mat mask = cv::Mat::zeros(toCv(c.rectified.image_size), CV_8UC1);
    cv::fillConvexPoly(mask, outline, cv::Scalar(255));
    return mask;
}

// Depth on the board against the board's pose. For each pair: solvePnP of the left
// corners with the new calibration gives the board's plane; the processor's depth
// (census-sgm, the service's defaults) over the board region is compared with the plane's
// depth at the same pixels. The board's squares are uniform and repeat: census-sgm gives
// depth along their edges only, and where fewer than 5 % of the region's pixels get a
// depth, the pair counts as "no reading", not as a pass.
TEST_F(ChessboardCalibrationTest, DepthOnTheBoardAgreesWithTheBoardsPose)
{
    const ChessboardCalibrationResult& r = result();
    const StereoCalibration& c = r.calibration;
    const RectifiedGeometry& g = c.rectified;
    double nearest_m = HUGE_VAL;
    const std::vector<BoardPlane> planes = boardPlanes(r, nearest_m);

    ProcessorSettings settings;
    settings.matcher.min_depth_m = 0.95 * nearest_m; // every board within the range
    settings.compute_cloud = false;
    StereoProcessor processor(c, settings);
    DepthResult out;
    std::printf("[accuracy] boards from %.3f m: %d disparities searched\n", nearest_m,
                processor.disparityRange().num_disparities);

    int within = 0, no_reading = 0;
    double worst_corner_error = 0.0;
    for (size_t i = 0; i < r.pairs.size(); ++i) {
        const PairReport& p = r.pairs[i];
        processor.process(cv::imread(p.left_path, cv::IMREAD_GRAYSCALE),
                          cv::imread(p.right_path, cv::IMREAD_GRAYSCALE), 0, i, out);

        std::vector<cv::Point2f> rect;
        const cv::Mat mask = boardMask(c, p, rect);

        // The corners' own disparity, matched by the detector rather than the matcher:
        // separates the calibration's share of any error from the matcher's.
        std::vector<cv::Point2f> right_rect;
        cv::undistortPoints(p.right_corners, right_rect, c.right.camera_matrix, c.right.distortion,
                            c.R2, c.P2, kUndistort);
        double corner_error = 0.0;
        for (size_t k = 0; k < rect.size(); ++k) {
            const double z = g.depthFromDisparity(rect[k].x - right_rect[k].x);
            const double z_plane = planes[i].depthAt(g, rect[k].x, rect[k].y);
            corner_error = std::max(corner_error, std::abs(z - z_plane) / z_plane);
        }
        worst_corner_error = std::max(worst_corner_error, corner_error);

        std::vector<double> measured, expected;
        int region = 0;
        for (int y = 0; y < mask.rows; ++y)
            for (int x = 0; x < mask.cols; ++x) {
                if (!mask.at<uchar>(y, x))
                    continue;
                ++region;
                const float z = out.depth_m.at<float>(y, x);
                if (!(z > 0.0f))
                    continue;
                measured.push_back(z);
                expected.push_back(planes[i].depthAt(g, x, y));
            }
        const double valid = static_cast<double>(measured.size()) / region;
        if (valid < 0.05) {
            ++no_reading;
            std::printf("[accuracy] %-11s board %5d px, %4.1f %% with depth: no reading; "
                        "corners' depth within %.2f %%\n",
                        basename(p.left_path).c_str(), region, 100.0 * valid, 100.0 * corner_error);
            continue;
        }
        auto median = [](std::vector<double> v) {
            std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
            return v[v.size() / 2];
        };
        const double z_measured = median(measured);
        const double z_plane = median(expected);
        const double error = (z_measured - z_plane) / z_plane;
        const bool ok = std::abs(error) <= 0.05;
        within += ok ? 1 : 0;
        std::printf("[accuracy] %-11s board %5d px, %4.1f %% with depth: median %.4f m, "
                    "plane %.4f m, %+5.2f %% %s; corners' depth within %.2f %%\n",
                    basename(p.left_path).c_str(), region, 100.0 * valid, z_measured, z_plane,
                    100.0 * error, ok ? "ok" : "OFF", 100.0 * corner_error);
    }
    std::printf("[accuracy] depth on the board within 5 %% of the plane in %d of %zu pairs "
                "(%d no reading)\n",
                within, r.pairs.size(), no_reading);
    EXPECT_GE(within, 9);
    EXPECT_LT(worst_corner_error, 0.01);
}

// Every pixel of the board, matcher against the board's pose: of the board, the share
// with depth (density) and the share of those more than 5 % off its plane, split into
// too far (an obstacle hidden) and too near.
struct BoardPixels {
    long board = 0, reported = 0, too_far = 0, too_near = 0;
    double density() const { return 100.0 * reported / board; }
    double off() const { return 100.0 * (too_far + too_near) / std::max(1L, reported); }
    double tooFar() const { return 100.0 * too_far / std::max(1L, reported); }
};

BoardPixels boardPixels(const ChessboardCalibrationResult& r, const MatcherSettings& matcher,
                        const char* name)
{
    const StereoCalibration& c = r.calibration;
    double nearest_m = HUGE_VAL;
    const std::vector<BoardPlane> planes = boardPlanes(r, nearest_m);
    ProcessorSettings settings;
    settings.matcher = matcher;
    settings.matcher.min_depth_m = 0.95 * nearest_m;
    settings.compute_cloud = false;
    StereoProcessor processor(c, settings);
    DepthResult out;
    BoardPixels all;
    for (size_t i = 0; i < r.pairs.size(); ++i) {
        const PairReport& p = r.pairs[i];
        processor.process(cv::imread(p.left_path, cv::IMREAD_GRAYSCALE),
                          cv::imread(p.right_path, cv::IMREAD_GRAYSCALE), 0, i, out);
        std::vector<cv::Point2f> rect;
        const cv::Mat mask = boardMask(c, p, rect);
        BoardPixels pair;
        for (int y = 0; y < mask.rows; ++y)
            for (int x = 0; x < mask.cols; ++x) {
                if (!mask.at<uchar>(y, x))
                    continue;
                ++pair.board;
                const float z = out.depth_m.at<float>(y, x);
                if (!(z > 0.0f))
                    continue;
                ++pair.reported;
                const double error = (z - planes[i].depthAt(c.rectified, x, y)) /
                                     planes[i].depthAt(c.rectified, x, y);
                pair.too_far += error > 0.05 ? 1 : 0;
                pair.too_near += error < -0.05 ? 1 : 0;
            }
        std::printf("[board] %-10s %-11s density %5.1f %%, off %5.2f %% (too far %5.2f %%)\n", name,
                    basename(p.left_path).c_str(), pair.density(), pair.off(), pair.tooFar());
        all.board += pair.board;
        all.reported += pair.reported;
        all.too_far += pair.too_far;
        all.too_near += pair.too_near;
    }
    std::printf("[board] %-10s all pairs: density %5.1f %%, off %5.2f %% (too far %5.2f %%)\n",
                name, all.density(), all.off(), all.tooFar());
    return all;
}

// The real rig's board, every pixel, census-sgm beside OpenCV's SGBM 3-way and 8-path
// (MODE_HH) with the service's range (every board within it: 224 disparities, some two
// periods of the board's pattern). The target of our matcher's issue, at least 75 % of the
// board reported with at most 3 % of it more than 5 % off, is not met by the natural
// tuning (the default, for textured scenes), and this test says
// where things stand instead: census-sgm reports 16 % of the board, 4 % of it off (too
// far: one period of the pattern off); OpenCV's 3-way reports 62 %, 24 % of it off. The
// board's squares are uniform and repeat along the rows, so that a row matches about as
// well one period off; what tells the periods apart is the board's border and the scene
// around it. The natural tuning lowers P2 at every intensity edge (a likely depth edge),
// so its paths carry that into the board no further than the first square. Eight paths
// do not either: OpenCV's MODE_HH without any filter reports 78 % of the board with 18 %
// of it off. census-sgm declines the ambiguous pixels rather than guess, so that no wrong
// depth hides an obstacle: the honest one of the three. The planar tuning (below) meets
// the target.
TEST_F(ChessboardCalibrationTest, CensusSgmReportsLessOfTheBoardButFarLessOfItOff)
{
    const MatcherSettings census = matcherDefaults(MatcherKind::CensusSgm);
    const MatcherSettings three_way = matcherDefaults(MatcherKind::Sgbm, SgbmMode::ThreeWay);
    MatcherSettings eight_paths_raw = matcherDefaults(MatcherKind::Sgbm, SgbmMode::Hh);
    eight_paths_raw.uniqueness_ratio = 0;
    eight_paths_raw.lr_max_diff_px = -1;
    eight_paths_raw.speckle_window_px = 0;
    const BoardPixels ours = boardPixels(result(), census, "census-sgm");
    const BoardPixels opencv = boardPixels(result(), three_way, "sgbm-3way");
    const BoardPixels eight = boardPixels(result(), eight_paths_raw, "sgbm-hh raw");
    // Where it stands, as bounds a regression would cross.
    EXPECT_LE(ours.off(), 5.0);
    EXPECT_LE(ours.off(), opencv.off() / 4.0);
    EXPECT_GE(ours.density(), 12.0);
    // The issue's target is out of reach of eight paths too.
    EXPECT_GT(eight.off(), 10.0);
}

// The planar tuning, made for such scenes (pipeline/matcher_settings.hpp): P2 at full
// height across the squares' edges carries what the board's ends say about the period
// along the rows, the texture check keeps what the census does not match out, and short
// gaps between agreeing disparities (the squares' insides, their edges) are bridged. The
// target: at least 75 % of the board with at most 3 % of it more than 5 % off.
TEST_F(ChessboardCalibrationTest, PlanarTuningReportsThreeQuartersOfTheBoardOnIt)
{
    MatcherSettings planar =
        matcherDefaults(MatcherKind::CensusSgm, SgbmMode::Sgbm, MatcherTuning::Planar);
    planar.threads = 2; // the bands' seams move with the thread count: the same on any machine
    const BoardPixels board = boardPixels(result(), planar, "planar");
    EXPECT_GE(board.density(), 75.0);
    EXPECT_LE(board.off(), 3.0);
    // The natural tuning reports a fifth of that.
    const BoardPixels natural =
        boardPixels(result(), matcherDefaults(MatcherKind::CensusSgm), "natural");
    EXPECT_GT(board.density(), 4.0 * natural.density());
}

// The patterns tuning: the natural one, with planar's steps only where a row runs
// through a strong pattern that repeats along it (pipeline/sgm/periodic_pattern.hpp), so
// that one matcher serves scenes holding both. Measured: 68.2 % of the board, 2.2 % of it
// more than 5 % off (planar 75.5 % and 2.1 %, natural 16.2 % and 4.1 %): about 2 points
// are rows where a tilted board's corners meet and too few regular edges are seen, the
// rest planar's larger speckles (400 px, 2 px steps), which the natural scenes pay for.
// The issue's target for one default (75 %) is not met by it.
TEST_F(ChessboardCalibrationTest, PatternsTuningReportsTwoThirdsOfTheBoard)
{
    MatcherSettings patterns =
        matcherDefaults(MatcherKind::CensusSgm, SgbmMode::Sgbm, MatcherTuning::Patterns);
    patterns.threads = 2;
    const BoardPixels board = boardPixels(result(), patterns, "patterns");
    EXPECT_GE(board.density(), 66.0);
    EXPECT_LE(board.off(), 3.0);
    const BoardPixels natural =
        boardPixels(result(), matcherDefaults(MatcherKind::CensusSgm), "natural");
    EXPECT_GT(board.density(), 4.0 * natural.density());
}

TEST_F(ChessboardCalibrationTest, PreviewShowsTheFirstPairRectifiedWithRowLines)
{
    test::TempDir dir;
    const std::string path = dir.file("preview.whatever");
    writeRectifiedPreview(result(), path, 40);
    const cv::Mat preview = cv::imread(path, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(preview.empty()) << "not a PNG OpenCV can read: " << path;
    std::ifstream file(path, std::ios::binary);
    char magic[4] = {};
    file.read(magic, 4);
    EXPECT_EQ(std::string(magic + 1, 3), "PNG");
    ASSERT_EQ(preview.size(), cv::Size(1280, 480));
    ASSERT_EQ(preview.type(), CV_8UC3);
    for (int y = 40; y < 480; y += 40)
        for (int x : {5, 320, 700, 1275})
            EXPECT_EQ(preview.at<cv::Vec3b>(y, x), cv::Vec3b(0, 255, 0)) << "line at y " << y;

    // Between the lines: the rectified images, left then right.
    const StereoCalibration& c = result().calibration;
    const Rectifier rectifier(c);
    cv::Mat left, right;
    rectifier.rectifyLeft(cv::imread(chessboardSample("left", 1), cv::IMREAD_GRAYSCALE), left);
    rectifier.rectifyRight(cv::imread(chessboardSample("right", 1), cv::IMREAD_GRAYSCALE), right);
    const cv::Rect band(0, 2, 640, 10); // above the board, no corner drawn there
    cv::Mat left_band, right_band;
    cv::extractChannel(preview(band), left_band, 0);
    cv::extractChannel(preview(band + cv::Point(640, 0)), right_band, 0);
    EXPECT_EQ(cv::norm(left_band, left(band), cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(right_band, right(band), cv::NORM_INF), 0.0);
}

TEST_F(ChessboardCalibrationTest, MatchesTheRightCornersToTheLeftWhicheverEndTheyStartAt)
{
    std::vector<PairReport> pairs = result().pairs;
    std::reverse(pairs[3].right_corners.begin(), pairs[3].right_corners.end());
    const ChessboardCalibrationResult again =
        calibrateFromCorners(pairs, cv::Size(640, 480), sampleOptions());
    EXPECT_EQ(again.pairs_used, 13);
    EXPECT_NEAR(again.rms_px, result().rms_px, 1e-9);
}

TEST_F(ChessboardCalibrationTest, DropsAPairWhoseCornersFitFarWorseAndCalibratesAgain)
{
    // Pair 5 with its right corners disturbed by up to 2 px, as a blurred or mis-detected
    // view would have them.
    std::vector<PairReport> pairs = result().pairs;
    cv::RNG rng(12345);
    for (cv::Point2f& corner : pairs[4].right_corners)
        corner += cv::Point2f(rng.uniform(-2.0f, 2.0f), rng.uniform(-2.0f, 2.0f));
    const ChessboardCalibrationResult r =
        calibrateFromCorners(pairs, cv::Size(640, 480), sampleOptions());
    EXPECT_EQ(r.outliers_dropped, 1);
    EXPECT_EQ(r.pairs_used, 12);
    EXPECT_FALSE(r.pairs[4].used);
    EXPECT_NE(r.pairs[4].rejection.find("outlier"), std::string::npos) << r.pairs[4].rejection;
    std::printf("pair 5 disturbed: %s\n", r.pairs[4].rejection.c_str());
    // Calibrated again without it: as good as the clean set.
    EXPECT_LE(r.rms_px, result().rms_px + 0.02);
    EXPECT_LE(r.epipolar_error_px, 0.15);
}

TEST_F(ChessboardCalibrationTest, AlphaOneKeepsEveryRawPixel)
{
    ChessboardCalibrationOptions options = sampleOptions();
    options.alpha = 1.0;
    const ChessboardCalibrationResult r =
        calibrateFromCorners(result().pairs, cv::Size(640, 480), options);
    const StereoCalibration& c = r.calibration;
    // The raw image's corners and edge midpoints all land inside the rectified image.
    const std::vector<cv::Point2f> edge = {{0, 0},     {319.5f, 0},   {639, 0}, {639, 239.5f},
                                           {639, 479}, {319.5f, 479}, {0, 479}, {0, 239.5f}};
    for (const auto& [camera, rotation, projection] :
         {std::tuple(c.left, c.R1, c.P1), std::tuple(c.right, c.R2, c.P2)}) {
        std::vector<cv::Point2f> rectified;
        cv::undistortPoints(edge, rectified, camera.camera_matrix, camera.distortion, rotation,
                            projection, kUndistort);
        for (const cv::Point2f& p : rectified) {
            EXPECT_GE(p.x, -0.5f);
            EXPECT_LE(p.x, 639.5f);
            EXPECT_GE(p.y, -0.5f);
            EXPECT_LE(p.y, 479.5f);
        }
    }
    // Zoomed out: a shorter focal length, and black borders outside the valid regions.
    EXPECT_LT(c.rectified.focal_px, 0.9 * result().calibration.rectified.focal_px);
    EXPECT_LT(c.valid_roi_left.area(), 0.9 * 640 * 480);
    std::printf("alpha 1: focal %.1f px (alpha 0: %.1f px), valid left %dx%d at (%d, %d)\n",
                c.rectified.focal_px, result().calibration.rectified.focal_px,
                c.valid_roi_left.width, c.valid_roi_left.height, c.valid_roi_left.x,
                c.valid_roi_left.y);
}

TEST(ChessboardCalibration, ReportsAPairWithoutTheBoardAndCalibratesFromTheRest)
{
    test::TempDir dir;
    const std::string blank = dir.file("blank.png");
    ASSERT_TRUE(cv::imwrite(blank, cv::Mat(480, 640, CV_8UC1, cv::Scalar(128))));
    std::vector<std::string> left, right;
    chessboardSamples(left, right, 6);
    left.push_back(chessboardSample("left", 12));
    right.push_back(blank);
    const ChessboardCalibrationResult r = calibrateChessboard(left, right, sampleOptions());
    EXPECT_EQ(r.pairs_used, 6);
    EXPECT_TRUE(r.pairs[6].left_found);
    EXPECT_FALSE(r.pairs[6].right_found);
    EXPECT_FALSE(r.pairs[6].used);
    EXPECT_EQ(r.pairs[6].rejection, "board not found in the right image");
    EXPECT_FALSE(r.pairs[6].epipolar_error_px.has_value());
}

// Runs the calibration expecting a refusal; returns its message.
std::string refusal(const std::vector<std::string>& left, const std::vector<std::string>& right,
                    const ChessboardCalibrationOptions& options = sampleOptions())
{
    return test::refusalMessage<ChessboardCalibrationError>(
        [&] { calibrateChessboard(left, right, options); });
}

using test::contains;

// `--left 'left*.jpg'` in opencv-doc's folder also catches left.jpg (612x459, no board):
// such a pair is reported and skipped, its size never compared with the others'.
TEST(ChessboardCalibration, SkipsAPairWithoutTheBoardWhateverItsSize)
{
    std::vector<std::string> left = {kSamples + "left.jpg"};
    std::vector<std::string> right = {kSamples + "right.jpg"};
    chessboardSamples(left, right, 7);
    ASSERT_EQ(cv::imread(left[0], cv::IMREAD_GRAYSCALE).size(), cv::Size(612, 459));
    int reported = 0;
    const ChessboardCalibrationResult r = calibrateChessboard(
        left, right, sampleOptions(), [&](const CornerProgress&) { ++reported; });
    EXPECT_EQ(reported, 7);
    EXPECT_EQ(r.pairs_used, 6);
    EXPECT_FALSE(r.pairs[0].used);
    EXPECT_EQ(r.pairs[0].rejection, "board not found in either image");
    EXPECT_EQ(r.calibration.rectified.image_size, (ImageSize{640, 480}));
}

// Two used pairs (the board found in both images) of different sizes: refused, naming the
// odd pair, the file and both sizes.
TEST(ChessboardCalibration, RefusesUsedPairsOfDifferingSizesNamingThem)
{
    test::TempDir dir;
    // A border added on the right and at the bottom (700x520): the board itself is as in
    // the original pair, so it is found in both images of the odd pair.
    std::vector<std::string> large;
    for (const char* side : {"left", "right"}) {
        large.push_back(dir.file(std::string(side) + "02_large.png"));
        cv::Mat image = cv::imread(chessboardSample(side, 2), cv::IMREAD_GRAYSCALE);
        cv::copyMakeBorder(image, image, 0, 40, 0, 60, cv::BORDER_REPLICATE);
        ASSERT_TRUE(cv::imwrite(large.back(), image));
    }
    const std::string message =
        refusal({chessboardSample("left", 1), large[0]}, {chessboardSample("right", 1), large[1]});
    EXPECT_TRUE(contains(message, "pair " + large[0] + " / " + large[1])) << message;
    EXPECT_TRUE(contains(message, "700x520")) << message;
    EXPECT_TRUE(contains(message, chessboardSample("left", 1))) << message;
    EXPECT_TRUE(contains(message, "640x480")) << message;
}

TEST(ChessboardCalibration, RefusesTooFewUsablePairsSayingHowMany)
{
    std::vector<std::string> left, right;
    chessboardSamples(left, right, 3);
    const std::string message = refusal(left, right);
    EXPECT_TRUE(contains(message, "only 3 usable pairs of 3")) << message;
    EXPECT_TRUE(contains(message, "at least 6")) << message;
}

TEST(ChessboardCalibration, RefusesABoardSizeFoundNowhereSuggestingInnerCorners)
{
    std::vector<std::string> left, right;
    chessboardSamples(left, right, 2);
    ChessboardCalibrationOptions options = sampleOptions();
    options.board.cols = 10; // the squares counted, not the inner corners
    options.board.rows = 7;
    const std::string message = refusal(left, right, options);
    EXPECT_TRUE(contains(message, "10x7 board was found in none of the 4 images")) << message;
    EXPECT_TRUE(contains(message, "INNER corners")) << message;
}

TEST(ChessboardCalibration, RefusesUnreadableFilesNamingThem)
{
    test::TempDir dir;
    const std::string missing = dir.file("left99.jpg");
    std::string message = refusal({missing}, {chessboardSample("right", 1)});
    EXPECT_TRUE(contains(message, missing)) << message;
    EXPECT_TRUE(contains(message, "No such file or directory")) << message;

    const std::string text = dir.file("right01.png");
    std::ofstream(text) << "not an image\n";
    message = refusal({chessboardSample("left", 1)}, {text});
    EXPECT_TRUE(contains(message, text)) << message;
    EXPECT_TRUE(contains(message, "not an image")) << message;
}

TEST(ChessboardCalibration, RefusesUnequalCountsOfLeftAndRightImages)
{
    const std::string message = refusal({chessboardSample("left", 1), chessboardSample("left", 2)},
                                        {chessboardSample("right", 1)});
    EXPECT_TRUE(contains(message, "2 left images but 1 right images")) << message;
}

TEST(ChessboardCalibration, RefusesSwappedCamerasSayingSo)
{
    std::vector<std::string> left, right;
    chessboardSamples(left, right, 6);
    const std::string message = refusal(right, left);
    EXPECT_TRUE(contains(message, "swapped")) << message;
}

TEST(ChessboardCalibration, RefusesOptionsItCannotUse)
{
    std::vector<std::string> left, right;
    chessboardSamples(left, right, 1);
    ChessboardCalibrationOptions options = sampleOptions();
    options.board.rows = 9;
    EXPECT_THROW(calibrateChessboard(left, right, options), std::invalid_argument);
    options = sampleOptions();
    options.alpha = 1.5;
    EXPECT_THROW(calibrateChessboard(left, right, options), std::invalid_argument);
    options = sampleOptions();
    options.board.square_m = 0.0;
    EXPECT_THROW(calibrateChessboard(left, right, options), std::invalid_argument);
}

} // namespace
} // namespace stereod
