// Calibration health on real rigs: the model of the row offset over the image fitted to
// the matches between the rectified images, and the verdict it gives.
//  - OpenCV's 13 chessboard pairs with the calibration made from them (the demo's rig):
//    ok on every pair, although the board's periodic squares give matches a row off.
//  - A Baumer rig (shared/data/real-rig/baumer): its calibration views with its own
//    calibration: ok; the scenes taken later, after the rig moved a little (about 1 px
//    between the rows of matching points): degraded; the correction estimated from some of
//    them brings the others back.
//  - Real rectified scenes with the right image turned: a third of a degree is degraded on
//    images 232 to 1282 px wide, and the model's roll reads the angle; a correction of a
//    rectified-only calibration turns it back.
//  - Swapped cameras; an image with no texture; the robust fit against matches a period
//    off.

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/calibration_formats.hpp"
#include "pipeline/calibration_health.hpp"
#include "pipeline/rectifier.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/demo_rig.hpp"

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
    std::printf("[health] %-38s %-8s %-18s %4d matches, rows up to %.2f px apart, offset %+.2f "
                "px, roll %+.3f deg, yaw %+.3f deg, scale %+.5f, residual %.2f px; median %+.2f "
                "px, p90 %.2f px\n",
                what.c_str(), healthStateName(m.state), m.reason.c_str(), m.matches,
                m.model.max_row_error_px, m.model.offset_px, m.model.roll_deg, m.model.yaw_deg,
                m.model.vertical_scale, m.model.residual_px, m.row_offset_px, m.row_offset_p90_px);
}

std::string two(int i)
{
    char text[8];
    std::snprintf(text, sizeof text, "%02d", i);
    return text;
}

// A rectified-only calibration of a scene's published geometry (principal point at the
// image centre).
StereoCalibration rectifiedRig(cv::Size size, double focal_px, double baseline_m,
                               double doffs_px = 0.0)
{
    return makeRectifiedCalibration(size, focal_px, baseline_m, std::nullopt, std::nullopt,
                                    doffs_px);
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

// The right image of a rectified scene turned about its centre by `degrees`
// (counter-clockwise as seen, cv::getRotationMatrix2D's sense).
cv::Mat turned(const cv::Mat& right, double degrees)
{
    const cv::Point2f centre((right.cols - 1) / 2.0f, (right.rows - 1) / 2.0f);
    cv::Mat out;
    cv::warpAffine(right, out, cv::getRotationMatrix2D(centre, degrees, 1.0), right.size(),
                   cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    return out;
}

RectifiedPair halfSize(const RectifiedPair& pair)
{
    RectifiedPair half;
    cv::resize(pair.left, half.left, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
    cv::resize(pair.right, half.right, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
    return half;
}

// A real rectified scene at its published geometry, and at half size.
struct Scene {
    std::string name;
    RectifiedPair pair;
    StereoCalibration calibration;
};

std::vector<Scene> sceneAndItsHalf(const std::string& name, const RectifiedPair& pair,
                                   double focal_px, double baseline_m, double doffs_px)
{
    return {{name, pair, rectifiedRig(pair.left.size(), focal_px, baseline_m, doffs_px)},
            {name + " at half size", halfSize(pair),
             rectifiedRig(pair.left.size() / 2, focal_px / 2.0, baseline_m, doffs_px / 2.0)}};
}

// Middlebury 2006 Aloe at full size (1282x1110: f 3740 px, B 160 mm, doffs 270 px) and
// 2005 Books at third size (463x370: f 3740 / 3 px, doffs its dmin 200 / 3 px), each also
// at half size: four widths from 232 to 1282 px.
std::vector<Scene> rollScenes()
{
    std::vector<Scene> scenes = sceneAndItsHalf(
        "Aloe", readPair(kSamples + "aloeL.jpg", kSamples + "aloeR.jpg"), 3740.0, 0.16, 270.0);
    for (Scene& scene : sceneAndItsHalf("Books",
                                        readPair(kData + "middlebury2005/Books/view1.png",
                                                 kData + "middlebury2005/Books/view5.png"),
                                        3740.0 / 3.0, 0.16, 200.0 / 3.0))
        scenes.push_back(scene);
    return scenes;
}

TEST(CalibrationHealth, DemoRigWithItsOwnCalibrationIsOkOnEveryPair)
{
    const test::DemoRigFiles files = test::demoRigFiles();
    const StereoCalibration calibration = test::demoRigCalibration();
    const Rectifier rectifier(calibration);
    CalibrationHealthChecker checker(calibration.rectified);
    std::vector<HealthMeasurement> all;
    for (size_t i = 0; i < files.left.size(); ++i) {
        const RectifiedPair pair = rectify(rectifier, files.left[i], files.right[i]);
        all.push_back(checker.measure(pair.left, pair.right));
        const HealthMeasurement& m = all.back();
        print("demo rig pair " + std::to_string(i + 1), m);
        // A pair with too few matches for a verdict is no alarm either.
        EXPECT_TRUE(m.state == HealthState::Ok || m.state == HealthState::Unknown)
            << "pair " << i + 1 << ": " << healthStateName(m.state) << " " << m.reason;
        if (m.state == HealthState::Ok) {
            // Well inside the limits, not just under them.
            EXPECT_LT(m.model.max_row_error_px, 0.5) << "pair " << i + 1;
            EXPECT_LT(std::abs(m.model.roll_deg), 0.1) << "pair " << i + 1;
        }
    }
    const HealthMeasurement pooled = checker.pool(all);
    print("demo rig, 13 pairs", pooled);
    EXPECT_EQ(pooled.state, HealthState::Ok) << pooled.reason;
    EXPECT_LT(pooled.model.max_row_error_px, 0.3);
    EXPECT_GT(pooled.matches, 200);
}

TEST(CalibrationHealth, BaumerCalibrationViewsAreOkAndTheLaterScenesDegraded)
{
    const StereoCalibration calibration = baumerCalibration();
    const Rectifier rectifier(calibration);
    CalibrationHealthChecker checker(calibration.rectified);
    std::vector<HealthMeasurement> views;
    for (int i = 1; i <= 14; ++i) {
        const RectifiedPair pair =
            rectify(rectifier, kBaumer + "Checkerboard_Baumer/left" + two(i) + ".png",
                    kBaumer + "Checkerboard_Baumer/right" + two(i) + ".png");
        views.push_back(checker.measure(pair.left, pair.right));
    }
    const HealthMeasurement pooled_views = checker.pool(views);
    print("baumer calibration views, 14 pairs", pooled_views);
    EXPECT_EQ(pooled_views.state, HealthState::Ok) << pooled_views.reason;

    for (int i = 1; i <= 8; ++i) {
        const RectifiedPair pair = baumerSample(rectifier, i);
        const HealthMeasurement m = checker.measure(pair.left, pair.right);
        print("baumer sample " + two(i), m);
        // About a pixel apart: what the data README describes.
        EXPECT_EQ(m.state, HealthState::Degraded) << "sample " << i;
        EXPECT_EQ(m.reason, "row_offset") << "sample " << i;
        EXPECT_GT(m.model.max_row_error_px, 0.8) << "sample " << i;
        EXPECT_LT(m.model.max_row_error_px, 1.5) << "sample " << i;
        EXPECT_GT(m.model.offset_px, 0.5) << "sample " << i;
    }
}

TEST(CalibrationHealth, CorrectionFromSomeBaumerScenesBringsTheOthersBelowAThirdOfAPixel)
{
    const StereoCalibration calibration = baumerCalibration();
    const Rectifier rectifier(calibration);
    CalibrationHealthChecker checker(calibration.rectified);
    std::vector<HealthMeasurement> estimate_from;
    for (int i : {1, 2, 3}) {
        const RectifiedPair pair = baumerSample(rectifier, i);
        estimate_from.push_back(checker.measure(pair.left, pair.right));
    }
    const HealthMeasurement pooled = checker.pool(estimate_from);
    cv::Vec2d degrees;
    const StereoCalibration corrected = correctRightRotation(calibration, pooled.used, &degrees);
    std::printf("[health] correction from samples 01-03: pitch %.4f deg, roll %.4f deg\n",
                degrees[0], degrees[1]);
    EXPECT_EQ(corrected.P2, calibration.P2); // depth stays as it was
    EXPECT_EQ(corrected.Q, calibration.Q);
    const Rectifier fixed(corrected);
    std::vector<HealthMeasurement> afterwards;
    for (int i = 4; i <= 8; ++i) {
        const RectifiedPair before = baumerSample(rectifier, i);
        const RectifiedPair after = baumerSample(fixed, i);
        const HealthMeasurement b = checker.measure(before.left, before.right);
        afterwards.push_back(checker.measure(after.left, after.right));
        const HealthMeasurement& a = afterwards.back();
        print("baumer sample " + two(i) + " before", b);
        print("baumer sample " + two(i) + " after the correction", a);
        EXPECT_LT(std::abs(a.model.offset_px), 1.0 / 3.0) << "sample " << i;
        EXPECT_LT(a.model.max_row_error_px, b.model.max_row_error_px) << "sample " << i;
    }
    const HealthMeasurement pooled_after = checker.pool(afterwards);
    print("baumer samples 04-08 after the correction", pooled_after);
    EXPECT_EQ(pooled_after.state, HealthState::Ok);
    EXPECT_LT(std::abs(pooled_after.model.offset_px), 0.3);
}

// A roll of the right camera moves the rows down on one side of the image and up on the
// other: a median of them reads zero. The model reads the angle, and the verdict is the
// same on an image of any width.
TEST(CalibrationHealth, TurnedRightImageIsDegradedOnAnyWidth)
{
    for (const Scene& scene : rollScenes()) {
        ASSERT_FALSE(scene.pair.left.empty() || scene.pair.right.empty()) << scene.name;
        CalibrationHealthChecker checker(scene.calibration.rectified);
        const std::string name =
            scene.name + " (" + std::to_string(scene.pair.left.cols) + " px wide)";
        const HealthMeasurement straight = checker.measure(scene.pair.left, scene.pair.right);
        print(name + " as rectified", straight);
        EXPECT_EQ(straight.state, HealthState::Ok) << name;
        for (const double degrees : {0.3, -0.3, 0.5}) {
            const HealthMeasurement m =
                checker.measure(scene.pair.left, turned(scene.pair.right, degrees));
            print(name + ", right turned " + cv::format("%+.1f", degrees) + " deg", m);
            EXPECT_EQ(m.state, HealthState::Degraded) << name << ", " << degrees << " deg";
            EXPECT_EQ(m.reason, "roll") << name << ", " << degrees << " deg";
            // The turn added to the scene's own (its rectification, a few hundredths).
            EXPECT_NEAR(m.model.roll_deg - straight.model.roll_deg, degrees, 0.05) << name;
        }
        const HealthMeasurement far =
            checker.measure(scene.pair.left, turned(scene.pair.right, 1.2));
        print(name + ", right turned +1.2 deg", far);
        EXPECT_EQ(far.state, HealthState::Failed) << name;
    }
}

// A factory-rectified camera whose right image has turned: the rectified-only calibration
// is checked with identity rectification, and its correction, a full calibration whose
// R2 turns the right image back, makes the pair ok again.
TEST(CalibrationHealth, RectifiedOnlyCalibrationIsCheckedAndCorrected)
{
    const std::vector<Scene> scenes = rollScenes();
    const Scene& scene = scenes[1]; // Aloe at half size
    const StereoCalibration& rig = scene.calibration;
    ASSERT_EQ(rig.kind, StereoCalibration::Kind::RectifiedOnly);
    const cv::Mat right = turned(scene.pair.right, 0.4);
    const Rectifier as_delivered(rig);
    cv::Mat left_rect, right_rect;
    as_delivered.rectifyLeft(scene.pair.left, left_rect);
    as_delivered.rectifyRight(right, right_rect);
    CalibrationHealthChecker checker(rig.rectified);
    const HealthMeasurement before = checker.measure(left_rect, right_rect);
    print("Aloe half, rectified-only, right +0.4 deg", before);
    ASSERT_EQ(before.state, HealthState::Degraded);

    cv::Vec2d degrees;
    const StereoCalibration corrected = correctRightRotation(rig, before.used, &degrees);
    std::printf("[health] correction: pitch %+.4f deg, roll %+.4f deg\n", degrees[0], degrees[1]);
    ASSERT_EQ(corrected.kind, StereoCalibration::Kind::Full);
    EXPECT_NEAR(degrees[1], 0.4, 0.03);
    // The same depth: the rectified geometry is the rectified-only calibration's.
    EXPECT_DOUBLE_EQ(corrected.rectified.focal_px, rig.rectified.focal_px);
    EXPECT_NEAR(corrected.rectified.baseline_m, rig.rectified.baseline_m, 1e-12);
    EXPECT_DOUBLE_EQ(corrected.rectified.doffs_px, rig.rectified.doffs_px);
    EXPECT_EQ(corrected.R1, cv::Matx33d::eye());
    // It is a calibration the loader takes.
    const StereoCalibration reread =
        parseCalibration(formatCalibration(corrected, "corrected"), "corrected");
    const Rectifier fixed(reread);
    fixed.rectifyLeft(scene.pair.left, left_rect);
    fixed.rectifyRight(right, right_rect);
    const HealthMeasurement after = checker.measure(left_rect, right_rect);
    print("Aloe half, after the correction", after);
    EXPECT_EQ(after.state, HealthState::Ok);
    EXPECT_LT(std::abs(after.model.roll_deg), 0.05);
    // The left image is only copied: identity rectification with the same camera.
    EXPECT_EQ(cv::norm(left_rect, scene.pair.left, cv::NORM_INF), 0.0);
}

// The fit against matches that agree on a wrong model: a third of them a period (9 px)
// off in rows, as a board's next row of squares gives them, and a tenth at random rows.
TEST(CalibrationHealth, FitIgnoresMatchesAPeriodOff)
{
    const StereoCalibration rig = rectifiedRig({640, 480}, 520.0, 0.08);
    RowOffsetModel truth;
    truth.focal_px = 520.0;
    truth.right_principal_px = {rig.rectified.cx_px, rig.rectified.cy_px};
    truth.pitch_px = 0.4;
    truth.roll_deg = 0.25;
    truth.vertical_scale = 0.001;
    truth.yaw_deg = 0.3;
    std::mt19937 random(7);
    std::uniform_real_distribution<float> column(20.f, 620.f), row(20.f, 460.f);
    std::uniform_real_distribution<double> anywhere(-20.0, 20.0);
    std::normal_distribution<double> noise(0.0, 0.08);
    std::vector<RowMatch> matches;
    for (int i = 0; i < 600; ++i) {
        const float x = column(random);
        const cv::Point2f right(x, row(random));
        double dy = truth.rowOffsetAt(right) + noise(random);
        if (i % 3 == 0)
            dy += 9.0;
        else if (i % 10 == 1)
            dy += anywhere(random);
        matches.push_back({{right.x + 30.f, static_cast<float>(right.y - dy)}, right});
    }
    RowOffsetModel model;
    std::vector<RowMatch> inliers;
    ASSERT_TRUE(fitRowOffsetModel(matches, rig.rectified, model, &inliers));
    std::printf("[health] fit: pitch %+.3f px, roll %+.4f deg, scale %+.5f, yaw %+.3f deg, "
                "%zu of %zu matches, residual %.3f px\n",
                model.pitch_px, model.roll_deg, model.vertical_scale, model.yaw_deg, inliers.size(),
                matches.size(), model.residual_px);
    EXPECT_NEAR(model.pitch_px, truth.pitch_px, 0.03);
    EXPECT_NEAR(model.roll_deg, truth.roll_deg, 0.005);
    EXPECT_NEAR(model.vertical_scale, truth.vertical_scale, 0.0002);
    EXPECT_NEAR(model.yaw_deg, truth.yaw_deg, 0.1);
    EXPECT_GT(inliers.size(), 300u);
    EXPECT_LT(inliers.size(), 420u);
    EXPECT_NEAR(model.residual_px, 0.08, 0.03);
}

// A checker is reused check after check: the same pair must give the same figures every
// time (OpenCV's knnMatch appends to the result it is given, and a checker that did not
// empty it re-processed every earlier check's matches).
TEST(CalibrationHealth, RepeatedChecksOfOnePairGiveTheSameFigures)
{
    const auto [left, right] = readPair(kData + "middlebury2014/Adirondack/im0.png",
                                        kData + "middlebury2014/Adirondack/im1.png");
    ASSERT_FALSE(left.empty() || right.empty());
    // Its calib.txt: f 1038.018 px, cx 322.037, cy 243.393, doffs 53.271, B 176.252 mm.
    CalibrationHealthChecker checker(
        makeRectifiedCalibration(left.size(), 1038.018, 0.176252, 322.037, 243.393, 53.271)
            .rectified);
    const HealthMeasurement first = checker.measure(left, right);
    print("Adirondack, first check", first);
    ASSERT_GT(first.matches, 100);
    for (int i = 2; i <= 4; ++i) {
        const HealthMeasurement again = checker.measure(left, right);
        print("Adirondack, check " + std::to_string(i), again);
        EXPECT_EQ(again.matches, first.matches) << "check " << i;
        EXPECT_EQ(again.state, first.state) << "check " << i;
        EXPECT_EQ(again.model.max_row_error_px, first.model.max_row_error_px) << "check " << i;
    }
}

TEST(CalibrationHealth, SwappedCamerasFail)
{
    const auto [left, right] =
        readPair(kData + "middlebury/venus/im2.png", kData + "middlebury/venus/im6.png");
    ASSERT_FALSE(left.empty() || right.empty());
    // Venus's focal length is not published; the image width stands in for it (it only
    // scales the model's second-order terms).
    CalibrationHealthChecker checker(rectifiedRig(left.size(), left.cols, 0.1).rectified);
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
    CalibrationHealthChecker checker(rectifiedRig(flat.size(), 500.0, 0.1).rectified);
    const HealthMeasurement m = checker.measure(flat, flat.clone());
    print("a grey wall", m);
    EXPECT_EQ(m.state, HealthState::Unknown);
    EXPECT_EQ(m.reason, "not_enough_matches");
}

TEST(CalibrationHealth, CorrectionNeedsMatchesThatAgree)
{
    const StereoCalibration rig = rectifiedRig({640, 480}, 500.0, 0.1);
    std::vector<RowMatch> few(5, RowMatch{{100, 100}, {90, 101}});
    EXPECT_THROW(correctRightRotation(rig, few), std::invalid_argument);
}

} // namespace
} // namespace stereod
