// What the main demo (scripts/demo.sh) shows, checked: the service's nearest-object
// reading on OpenCV's 13 real chessboard pairs (640x480 wide-angle rig, 9x6 inner
// corners; Debian package opencv-doc), with the calibration made from those pairs and
// the processing settings of config/examples/chessboard-demo.yaml, against the depth the
// board's pose gives over the same region (cv::solvePnP with the new calibration).
//
// The board is a periodic texture, the classic trap for correlation. The demo's settings
// must make every reading the service gives right, and turn the rest into "no reading"
// with a reason: never a wrong number.
//
// The square size of the sample board is not published: 25 mm is assumed, as in the
// demo. It scales the baseline, the readings and the board's depth alike.

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "config/service_config.hpp"
#include "pipeline/board_pose.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/nearest_object.hpp"
#include "pipeline/stereo_processor.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

const std::string kDemoConfig =
    std::string(STEREOD_SOURCE_DIR) + "/config/examples/chessboard-demo.yaml";
constexpr double kSquareM = 0.025;
// A reading the service gives must lie this close to the board's depth.
constexpr double kTolerance = 0.03;

std::string fileName(const std::string& path)
{
    return std::filesystem::path(path).filename().string();
}

class ChessboardDemoTest : public ::testing::Test {
  protected:
    // The demo's calibration (the 13 pairs: 01..14, the sample set has no 10) and its
    // configuration, once for all tests.
    static void SetUpTestSuite()
    {
        std::vector<std::string> left, right;
        test::chessboardSamples(left, right);
        ChessboardCalibrationOptions options;
        options.board = {9, 6, kSquareM};
        result_ = new ChessboardCalibrationResult(calibrateChessboard(left, right, options));
        // The file's replay path is the demo's recording under build/, which need not
        // exist here; the processing settings are what this test is about.
        ConfigOverrides overrides;
        overrides.replay_path = test::opencvSamplesDir();
        config_ = new ServiceConfig(loadConfig(kDemoConfig, overrides));
    }
    static void TearDownTestSuite()
    {
        delete result_;
        delete config_;
        result_ = nullptr;
        config_ = nullptr;
    }

    static const ChessboardCalibrationResult& result() { return *result_; }
    static const ServiceConfig& config() { return *config_; }

  private:
    static ChessboardCalibrationResult* result_;
    static ServiceConfig* config_;
};

ChessboardCalibrationResult* ChessboardDemoTest::result_ = nullptr;
ServiceConfig* ChessboardDemoTest::config_ = nullptr;

TEST_F(ChessboardDemoTest, EveryReadingOnTheBoardIsWithinAFewPercentOfItsPose)
{
    const StereoCalibration& calibration = result().calibration;
    const RectifiedGeometry& g = calibration.rectified;
    ASSERT_EQ(result().pairs_used, 13);
    ProcessorSettings settings = config().processing;
    settings.compute_cloud = false; // not needed for the reading
    const NearestSettings& nearest = settings.nearest;
    StereoProcessor processor(calibration, settings);
    const DisparityRange range = processor.disparityRange();
    std::printf("[accuracy] demo config: region x %.2f y %.2f %.2fx%.2f, percentile %.0f, "
                "range %.2f..%.2f m, min valid %.0f %%, min %d px; %d disparities (closest "
                "%.3f m), baseline %.4f m, focal %.1f px\n",
                nearest.roi.x, nearest.roi.y, nearest.roi.width, nearest.roi.height,
                nearest.percentile, nearest.min_depth_m, nearest.max_depth_m,
                100.0 * nearest.min_valid_fraction, nearest.min_pixels, range.num_disparities,
                range.closest_depth_m, g.baseline_m, g.focal_px);

    // The region lies where the matcher searches the whole range: left of column
    // min_disparity + num_disparities the match would fall outside the right image.
    const cv::Rect region = regionPixels(nearest.roi, toCv(g.image_size));
    EXPECT_GE(region.x, range.min_disparity + range.num_disparities) << region;

    std::printf("[accuracy] pair        board   valid  in range  reading    board pose (span)"
                "            error\n");
    DepthResult out;
    int readings = 0;
    double worst = 0.0;
    double closest_board_m = HUGE_VAL;
    for (size_t i = 0; i < result().pairs.size(); ++i) {
        const PairReport& pair = result().pairs[i];
        processor.process(cv::imread(pair.left_path, cv::IMREAD_GRAYSCALE),
                          cv::imread(pair.right_path, cv::IMREAD_GRAYSCALE), 0, i, out);
        const Reading& reading = out.reading;
        const BoardPose pose =
            boardPoseFromCorners(calibration, *calibration.board, pair.left_corners);
        const std::optional<BoardDepthInRegion> board = boardDepthInRegion(pose, g, nearest);
        ASSERT_TRUE(board.has_value()) << pair.left_path << ": the board is outside the region";
        closest_board_m = std::min(closest_board_m, board->nearest_m);
        // The board is what the demo shows: it lies within the configured depth range.
        EXPECT_GE(board->depth_m, nearest.min_depth_m) << pair.left_path;
        EXPECT_LE(board->depth_m, nearest.max_depth_m) << pair.left_path;

        std::printf("[accuracy] %-11s %5.1f %%  %5.1f %%  %6.1f %%  ",
                    fileName(pair.left_path).c_str(), 100.0 * board->coverage,
                    100.0 * reading.valid_fraction, 100.0 * reading.in_range_fraction);
        if (!reading.valid) {
            std::printf("no reading (%s)  %.4f m (%.3f..%.3f)\n", reasonCode(reading.reason),
                        board->depth_m, board->nearest_m, board->farthest_m);
            EXPECT_TRUE(reading.reason == NoReadingReason::TooFewValidPixels ||
                        reading.reason == NoReadingReason::NothingInRange)
                << pair.left_path << ": " << reasonCode(reading.reason);
            continue;
        }
        ++readings;
        const double error = (reading.distance_m - board->depth_m) / board->depth_m;
        worst = std::max(worst, std::abs(error));
        std::printf("%.4f m   %.4f m (%.3f..%.3f)   %+5.2f %% %s\n", reading.distance_m,
                    board->depth_m, board->nearest_m, board->farthest_m, 100.0 * error,
                    std::abs(error) <= kTolerance ? "ok" : "WRONG");
        EXPECT_LE(std::abs(error), kTolerance)
            << pair.left_path << ": reading " << reading.distance_m << " m, board "
            << board->depth_m << " m";
    }
    std::printf("[accuracy] %d readings of %zu pairs, worst %.2f %% from the board's pose; "
                "boards from %.3f m\n",
                readings, result().pairs.size(), 100.0 * worst, closest_board_m);
    // Refusing would be truthful and useless: the board is in plain view in every pair.
    EXPECT_EQ(readings, static_cast<int>(result().pairs.size()));
    // The disparity range reaches the nearest board (a nearer surface would be matched to
    // a wrong disparity).
    EXPECT_LE(range.closest_depth_m, closest_board_m);
}

// The reference itself, independently of solvePnP: each corner triangulated from its
// detected positions in both images (no matcher involved) lies on the pose's plane.
TEST_F(ChessboardDemoTest, BoardPoseAgreesWithTheCornersTriangulated)
{
    const StereoCalibration& c = result().calibration;
    const RectifiedGeometry& g = c.rectified;
    const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12);
    double worst = 0.0, worst_rms = 0.0;
    for (const PairReport& pair : result().pairs) {
        const BoardPose pose = boardPoseFromCorners(c, *c.board, pair.left_corners);
        worst_rms = std::max(worst_rms, pose.reprojection_rms_px);
        std::vector<cv::Point2f> left, right;
        cv::undistortPoints(pair.left_corners, left, c.left.camera_matrix, c.left.distortion, c.R1,
                            c.P1, criteria);
        cv::undistortPoints(pair.right_corners, right, c.right.camera_matrix, c.right.distortion,
                            c.R2, c.P2, criteria);
        for (size_t k = 0; k < left.size(); ++k) {
            const double triangulated = g.depthFromDisparity(left[k].x - right[k].x);
            const double plane = pose.depthAt(left[k], g);
            worst = std::max(worst, std::abs(triangulated - plane) / plane);
        }
        // The centre of the inner corners lies on the plane.
        EXPECT_NEAR(pose.normal.dot(pose.centre_m), pose.offset_m, 1e-9);
    }
    std::printf("[accuracy] corners triangulated vs the board's pose: worst %.2f %%; pose "
                "reprojection RMS up to %.3f px\n",
                100.0 * worst, worst_rms);
    EXPECT_LT(worst, 0.01);
    EXPECT_LT(worst_rms, 0.5);
}

TEST_F(ChessboardDemoTest, BoardDepthCountsOnlyThePixelsOnTheBoard)
{
    const StereoCalibration& c = result().calibration;
    const BoardPose pose = boardPoseFromCorners(c, *c.board, result().pairs[0].left_corners);
    NearestSettings nearest;
    // A region far off the board (pair 01 holds it in the upper middle): nothing.
    nearest.roi = {0.0, 0.9, 0.1, 0.1};
    EXPECT_FALSE(boardDepthInRegion(pose, c.rectified, nearest).has_value());
    // The whole image: the board covers part of it, and the percentiles are ordered.
    nearest.roi = {0.0, 0.0, 1.0, 1.0};
    nearest.percentile = 0.0;
    const auto nearest_part = boardDepthInRegion(pose, c.rectified, nearest);
    ASSERT_TRUE(nearest_part.has_value());
    EXPECT_GT(nearest_part->coverage, 0.05);
    EXPECT_LT(nearest_part->coverage, 0.9);
    EXPECT_EQ(nearest_part->region_pixels, 640u * 480u);
    EXPECT_DOUBLE_EQ(nearest_part->depth_m, nearest_part->nearest_m);
    nearest.percentile = 100.0;
    const auto farthest_part = boardDepthInRegion(pose, c.rectified, nearest);
    ASSERT_TRUE(farthest_part.has_value());
    EXPECT_DOUBLE_EQ(farthest_part->depth_m, farthest_part->farthest_m);
    EXPECT_GT(farthest_part->depth_m, nearest_part->depth_m);
    // The board's centre lies between its nearest and farthest points.
    EXPECT_GT(pose.centre_m[2], nearest_part->nearest_m);
    EXPECT_LT(pose.centre_m[2], farthest_part->farthest_m);
}

TEST_F(ChessboardDemoTest, BoardPoseRefusesWhatItCannotUse)
{
    const StereoCalibration& c = result().calibration;
    const std::vector<cv::Point2f>& corners = result().pairs[0].left_corners;
    EXPECT_THROW(boardPoseFromCorners(c, {9, 5, kSquareM}, corners), std::invalid_argument);
    EXPECT_THROW(boardPoseFromCorners(c, {9, 6, 0.0}, corners), std::invalid_argument);
    const StereoCalibration rectified = makeRectifiedCalibration({640, 480}, 500.0, 0.1);
    EXPECT_THROW(boardPoseFromCorners(rectified, {9, 6, kSquareM}, corners), std::invalid_argument);
}

} // namespace
} // namespace stereod
