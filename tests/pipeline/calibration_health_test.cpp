// Calibration health on real rigs: how far apart the rows of matching features are after
// rectification, and the verdict it gives.
//  - OpenCV's 13 chessboard pairs with the calibration made from them: ok.
//  - A Baumer rig (shared/data/real-rig/baumer): its calibration views with its own
//    calibration: ok; the scenes taken later, after the rig moved a little (about 1 px
//    between the rows of matching points): degraded; the correction estimated from some of
//    them brings the others back.
//  - A real scene with the right image turned by 0.1, 0.3 and 1 degree; swapped cameras;
//    an image with no texture.

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/calibration_formats.hpp"
#include "pipeline/calibration_health.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "pipeline/rectifier.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod {
namespace {

const std::string kSamples = test::opencvSamplesDir() + "/";
const std::string kBaumer = test::sharedDataDir() + "/real-rig/baumer/";
const std::string kData = test::sharedDataDir() + "/";

struct RectifiedPair {
    cv::Mat left, right;
};

// A pair of grey images as they are on disk (empty images when they cannot be read).
RectifiedPair readPair(const std::string& left_path, const std::string& right_path)
{
    RectifiedPair pair{cv::imread(left_path, cv::IMREAD_GRAYSCALE),
                       cv::imread(right_path, cv::IMREAD_GRAYSCALE)};
    EXPECT_FALSE(pair.left.empty()) << left_path;
    EXPECT_FALSE(pair.right.empty()) << right_path;
    return pair;
}

RectifiedPair rectify(const Rectifier& rectifier, const std::string& left_path,
                      const std::string& right_path)
{
    const RectifiedPair raw = readPair(left_path, right_path);
    RectifiedPair pair;
    rectifier.rectifyLeft(raw.left, pair.left);
    rectifier.rectifyRight(raw.right, pair.right);
    return pair;
}

void print(const std::string& what, const HealthMeasurement& m)
{
    std::printf("[health] %-34s %-8s %-18s %4d matches, row offset %+.2f px, p90 %.2f px, "
                "negative disparities %.0f %%\n",
                what.c_str(), healthStateName(m.state), m.reason.c_str(), m.matches,
                m.row_offset_px, m.row_offset_p90_px, 100.0 * m.negative_disparity_fraction);
}

std::string two(int i)
{
    char text[8];
    std::snprintf(text, sizeof text, "%02d", i);
    return text;
}

// The Baumer rig's own calibration (OpenCV stereo_calib files; T in squares, which only
// scales depth, not rows).
StereoCalibration baumerCalibration()
{
    return importOpenCvStereoCalib(kBaumer + "Checkerboard_Baumer/intrinsics.yml",
                                   kBaumer + "Checkerboard_Baumer/extrinsics.yml", {696, 524});
}

// The scenes of samples_baumer: the files named "right" come from the calibration's
// left camera (shared/data/README.md).
RectifiedPair baumerSample(const Rectifier& rectifier, int i)
{
    return rectify(rectifier, kBaumer + "samples_baumer/right" + two(i) + ".png",
                   kBaumer + "samples_baumer/left" + two(i) + ".png");
}

TEST(CalibrationHealth, OpenCvChessboardRigWithItsOwnCalibrationIsOk)
{
    std::vector<std::string> left, right;
    for (int i = 1; i <= 14; ++i) {
        if (i == 10)
            continue;
        left.push_back(kSamples + "left" + two(i) + ".jpg");
        right.push_back(kSamples + "right" + two(i) + ".jpg");
    }
    ChessboardCalibrationOptions options;
    options.board = {9, 6, 0.025};
    const StereoCalibration calibration = calibrateChessboard(left, right, options).calibration;
    const Rectifier rectifier(calibration);
    CalibrationHealthChecker checker;
    std::vector<HealthMeasurement> all;
    for (size_t i = 0; i < left.size(); ++i) {
        const RectifiedPair pair = rectify(rectifier, left[i], right[i]);
        all.push_back(checker.measure(pair.left, pair.right));
        print("opencv-doc chessboard pair " + std::to_string(i + 1), all.back());
    }
    const HealthMeasurement pooled = poolMeasurements(all, checker.settings());
    print("opencv-doc chessboard rig, 13 pairs", pooled);
    EXPECT_EQ(pooled.state, HealthState::Ok) << pooled.reason;
    EXPECT_LT(std::abs(pooled.row_offset_px), 0.3);
    EXPECT_GT(pooled.matches, 200);
}

TEST(CalibrationHealth, BaumerCalibrationViewsAreOkAndTheLaterScenesDegraded)
{
    const StereoCalibration calibration = baumerCalibration();
    const Rectifier rectifier(calibration);
    CalibrationHealthChecker checker;
    std::vector<HealthMeasurement> views;
    for (int i = 1; i <= 14; ++i) {
        const RectifiedPair pair =
            rectify(rectifier, kBaumer + "Checkerboard_Baumer/left" + two(i) + ".png",
                    kBaumer + "Checkerboard_Baumer/right" + two(i) + ".png");
        views.push_back(checker.measure(pair.left, pair.right));
    }
    const HealthMeasurement pooled_views = poolMeasurements(views, checker.settings());
    print("baumer calibration views, 14 pairs", pooled_views);
    EXPECT_EQ(pooled_views.state, HealthState::Ok) << pooled_views.reason;

    int degraded = 0;
    for (int i = 1; i <= 8; ++i) {
        const RectifiedPair pair = baumerSample(rectifier, i);
        const HealthMeasurement m = checker.measure(pair.left, pair.right);
        print("baumer sample " + two(i), m);
        degraded += m.state == HealthState::Degraded;
        if (i <= 4 || i == 6) {
            // About a pixel apart: what the data README describes.
            EXPECT_EQ(m.state, HealthState::Degraded) << "sample " << i;
            EXPECT_GT(std::abs(m.row_offset_px), 0.8) << "sample " << i;
            EXPECT_LT(std::abs(m.row_offset_px), 1.4) << "sample " << i;
        }
    }
    EXPECT_GE(degraded, 5);
}

TEST(CalibrationHealth, CorrectionFromSomeBaumerScenesBringsTheOthersBelowAThirdOfAPixel)
{
    const StereoCalibration calibration = baumerCalibration();
    const Rectifier rectifier(calibration);
    CalibrationHealthChecker checker;
    std::vector<HealthMeasurement> estimate_from;
    for (int i : {1, 2, 3}) {
        const RectifiedPair pair = baumerSample(rectifier, i);
        estimate_from.push_back(checker.measure(pair.left, pair.right));
    }
    const HealthMeasurement pooled = poolMeasurements(estimate_from, checker.settings());
    cv::Vec2d degrees;
    const StereoCalibration corrected = correctRightRotation(calibration, pooled.used, &degrees);
    std::printf("[health] correction from samples 01-03: pitch %.4f deg, roll %.4f deg\n",
                degrees[0], degrees[1]);
    EXPECT_EQ(corrected.P2, calibration.P2); // depth stays as it was
    EXPECT_EQ(corrected.Q, calibration.Q);
    const Rectifier fixed(corrected);
    for (int i = 4; i <= 8; ++i) {
        const RectifiedPair before = baumerSample(rectifier, i);
        const RectifiedPair after = baumerSample(fixed, i);
        const HealthMeasurement b = checker.measure(before.left, before.right);
        const HealthMeasurement a = checker.measure(after.left, after.right);
        print("baumer sample " + two(i) + " before", b);
        print("baumer sample " + two(i) + " after the correction", a);
        EXPECT_LT(std::abs(a.row_offset_px), 0.3) << "sample " << i;
        EXPECT_EQ(a.state, HealthState::Ok) << "sample " << i;
    }
}

// A real rectified scene with the right image turned about its centre: the rows drift
// apart in proportion to the distance from the centre.
TEST(CalibrationHealth, TurnedRightImageIsDetectedAtTheRightLevel)
{
    const auto [left, right] = readPair(kData + "middlebury2014/Adirondack/im0.png",
                                        kData + "middlebury2014/Adirondack/im1.png");
    ASSERT_FALSE(left.empty() || right.empty());
    CalibrationHealthChecker checker;
    const HealthMeasurement straight = checker.measure(left, right);
    print("Adirondack as rectified", straight);
    EXPECT_EQ(straight.state, HealthState::Ok);
    const struct {
        double degrees;
        HealthState expected;
    } cases[] = {{0.1, HealthState::Ok}, {0.3, HealthState::Degraded}, {1.0, HealthState::Failed}};
    for (const auto& c : cases) {
        const cv::Point2f centre(right.cols / 2.0f, right.rows / 2.0f);
        cv::Mat turned;
        cv::warpAffine(right, turned, cv::getRotationMatrix2D(centre, c.degrees, 1.0), right.size(),
                       cv::INTER_LINEAR, cv::BORDER_REPLICATE);
        const HealthMeasurement m = checker.measure(left, turned);
        print("Adirondack, right turned " + std::to_string(c.degrees) + " deg", m);
        EXPECT_EQ(m.state, c.expected) << c.degrees << " degrees";
    }
}

// A checker is reused check after check: the same pair must give the same figures every
// time (OpenCV's knnMatch appends to the result it is given, and a checker that did not
// empty it re-processed every earlier check's matches).
TEST(CalibrationHealth, RepeatedChecksOfOnePairGiveTheSameFigures)
{
    const auto [left, right] = readPair(kData + "middlebury2014/Adirondack/im0.png",
                                        kData + "middlebury2014/Adirondack/im1.png");
    ASSERT_FALSE(left.empty() || right.empty());
    CalibrationHealthChecker checker;
    const HealthMeasurement first = checker.measure(left, right);
    print("Adirondack, first check", first);
    ASSERT_GT(first.matches, 100);
    for (int i = 2; i <= 4; ++i) {
        const HealthMeasurement again = checker.measure(left, right);
        print("Adirondack, check " + std::to_string(i), again);
        EXPECT_EQ(again.matches, first.matches) << "check " << i;
        EXPECT_EQ(again.state, first.state) << "check " << i;
        EXPECT_EQ(again.row_offset_px, first.row_offset_px) << "check " << i;
    }
}

TEST(CalibrationHealth, SwappedCamerasFail)
{
    const cv::Mat left = cv::imread(kData + "middlebury/venus/im2.png", cv::IMREAD_GRAYSCALE);
    const cv::Mat right = cv::imread(kData + "middlebury/venus/im6.png", cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(left.empty() || right.empty());
    CalibrationHealthChecker checker;
    EXPECT_EQ(checker.measure(left, right).state, HealthState::Ok);
    const HealthMeasurement swapped = checker.measure(right, left);
    print("venus, cameras swapped", swapped);
    EXPECT_EQ(swapped.state, HealthState::Failed);
    EXPECT_EQ(swapped.reason, "cameras_swapped");
}

TEST(CalibrationHealth, NoTextureGivesNoVerdict)
{
    cv::Mat flat(480, 640, CV_8UC1, cv::Scalar(128));
    cv::Mat noise(480, 640, CV_8UC1);
    cv::randn(noise, 0, 1);
    flat += noise;
    CalibrationHealthChecker checker;
    const HealthMeasurement m = checker.measure(flat, flat.clone());
    print("a grey wall", m);
    EXPECT_EQ(m.state, HealthState::Unknown);
    EXPECT_EQ(m.reason, "not_enough_matches");
}

TEST(CalibrationHealth, CorrectionRefusesARectifiedOnlyCalibration)
{
    const StereoCalibration rectified = makeRectifiedCalibration({640, 480}, 500.0, 0.1);
    std::vector<RowMatch> matches(20, RowMatch{{100, 100}, {90, 101}});
    EXPECT_THROW(correctRightRotation(rectified, matches), std::invalid_argument);
}

} // namespace
} // namespace stereod
