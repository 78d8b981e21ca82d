// The rectifier's own bilinear remap against cv::remap (INTER_LINEAR, BORDER_CONSTANT 0),
// the reference it replaces: on a real rig (OpenCV's chessboard pairs, calibrated here
// with alpha 1 so that the rectified images have black borders), on the benchmark's
// plausible rig with a real scene, and on maps made to hit every edge case of the border.
// Contract: at most 1 grey level apart anywhere, mean difference below 0.05, and pixels
// whose source lies outside the raw image are 0.

#include <cstdint>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench/bench_data.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/chessboard_calibration.hpp"
#include "pipeline/cv_conversions.hpp"
#include "pipeline/rectifier.hpp"
#include "pipeline/resample/remap_kernels.hpp"
#include "tests/support/data_paths.hpp"
#include "tests/support/files.hpp"

namespace stereod {
namespace {

const std::string kSamples = test::opencvSamplesDir() + "/";

std::string samplePath(const char* side, int index)
{
    char name[32];
    std::snprintf(name, sizeof name, "%s%02d.jpg", side, index);
    return kSamples + name;
}

cv::Mat readGray(const std::string& path)
{
    cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (image.empty())
        ADD_FAILURE() << "cannot read " << path << " (Debian package opencv-doc)";
    return image;
}

struct Difference {
    double max = 0.0;
    double mean = 0.0;
};

Difference difference(const cv::Mat& a, const cv::Mat& b)
{
    cv::Mat d;
    cv::absdiff(a, b, d);
    return {cv::norm(d, cv::NORM_INF), cv::mean(d)[0]};
}

cv::Mat openCvRemap(const cv::Mat& src, const cv::Mat& map_xy, const cv::Mat& map_frac)
{
    cv::Mat out;
    cv::remap(src, out, map_xy, map_frac, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
    return out;
}

// 255 where the 2x2 neighbourhood named by map_xy lies wholly outside a source of
// `size` (no raw data at all), else 0.
cv::Mat whollyOutside(const cv::Mat& map_xy, cv::Size size)
{
    cv::Mat mask(map_xy.size(), CV_8UC1);
    for (int y = 0; y < map_xy.rows; ++y)
        for (int x = 0; x < map_xy.cols; ++x) {
            const cv::Vec2s p = map_xy.at<cv::Vec2s>(y, x);
            const bool outside =
                p[0] < -1 || p[0] >= size.width || p[1] < -1 || p[1] >= size.height;
            mask.at<uint8_t>(y, x) = outside ? 255 : 0;
        }
    return mask;
}

// Pixels whose neighbourhood straddles the raw image's edge: some neighbours inside,
// some outside.
int countStraddling(const cv::Mat& map_xy, cv::Size size)
{
    int count = 0;
    for (int y = 0; y < map_xy.rows; ++y)
        for (int x = 0; x < map_xy.cols; ++x) {
            const cv::Vec2s p = map_xy.at<cv::Vec2s>(y, x);
            const bool x_edge = p[0] == -1 || p[0] == size.width - 1;
            const bool y_edge = p[1] == -1 || p[1] == size.height - 1;
            const bool x_in = p[0] >= -1 && p[0] < size.width;
            const bool y_in = p[1] >= -1 && p[1] < size.height;
            count += (x_in && y_in && (x_edge || y_edge)) ? 1 : 0;
        }
    return count;
}

// OpenCV's chessboard rig (640x480, wide angle), calibrated once from six pairs with
// alpha 1: every raw pixel is kept, so the rectified images have black borders where the
// raw image does not reach.
const StereoCalibration& realRig()
{
    static const StereoCalibration calibration = [] {
        std::vector<std::string> left, right;
        for (int i = 1; i <= 6; ++i) {
            left.push_back(samplePath("left", i));
            right.push_back(samplePath("right", i));
        }
        ChessboardCalibrationOptions options;
        options.board = {9, 6, 0.025};
        options.alpha = 1.0;
        return calibrateChessboard(left, right, options).calibration;
    }();
    return calibration;
}

struct Maps {
    cv::Mat xy, frac;
};

Maps fixedPointMaps(const CameraIntrinsics& camera, const cv::Matx33d& rotation,
                    const cv::Matx34d& projection, cv::Size size)
{
    Maps m;
    cv::initUndistortRectifyMap(camera.camera_matrix, camera.distortion, rotation, projection, size,
                                CV_16SC2, m.xy, m.frac);
    return m;
}

TEST(RealRig, RectifiesLikeOpenCvRemap)
{
    const StereoCalibration& c = realRig();
    const Rectifier rectifier(c);
    ASSERT_TRUE(rectifier.remaps());
    const cv::Size size = toCv(c.rectified.image_size);
    const Maps left_maps = fixedPointMaps(c.left, c.R1, c.P1, size);
    const Maps right_maps = fixedPointMaps(c.right, c.R2, c.P2, size);
    cv::Mat left_rect, right_rect;
    for (int i : {1, 4, 7, 12}) {
        const cv::Mat left = readGray(samplePath("left", i));
        const cv::Mat right = readGray(samplePath("right", i));
        ASSERT_FALSE(left.empty() || right.empty());
        rectifier.rectifyLeft(left, left_rect);
        rectifier.rectifyRight(right, right_rect);
        const Difference l = difference(left_rect, openCvRemap(left, left_maps.xy, left_maps.frac));
        const Difference r =
            difference(right_rect, openCvRemap(right, right_maps.xy, right_maps.frac));
        std::printf("[accuracy] pair %02d against cv::remap: max %.0f / %.0f, mean %.5f / %.5f "
                    "grey levels (left / right)\n",
                    i, l.max, r.max, l.mean, r.mean);
        EXPECT_LE(l.max, 1.0) << "pair " << i;
        EXPECT_LE(r.max, 1.0) << "pair " << i;
        EXPECT_LT(l.mean, 0.05) << "pair " << i;
        EXPECT_LT(r.mean, 0.05) << "pair " << i;
    }
}

TEST(RealRig, PixelsWithoutRawDataAreBlack)
{
    const StereoCalibration& c = realRig();
    const Rectifier rectifier(c);
    const cv::Mat left = readGray(samplePath("left", 1));
    ASSERT_FALSE(left.empty());
    cv::Mat rectified;
    rectifier.rectifyLeft(left, rectified);

    const Maps maps = fixedPointMaps(c.left, c.R1, c.P1, toCv(c.rectified.image_size));
    const cv::Mat outside = whollyOutside(maps.xy, left.size());
    const int outside_count = cv::countNonZero(outside);
    const int straddling = countStraddling(maps.xy, left.size());
    std::printf("[accuracy] alpha 1: %d rectified pixels without raw data, %d on the raw "
                "image's edge\n",
                outside_count, straddling);
    // Alpha 1 leaves black corners: the check below has pixels to look at.
    ASSERT_GT(outside_count, 1000);
    ASSERT_GT(straddling, 100);
    EXPECT_EQ(cv::countNonZero(rectified & outside), 0);
    // The raw image's content is there elsewhere (not an all-black output).
    EXPECT_GT(cv::countNonZero(rectified),
              (static_cast<int>(rectified.total()) - outside_count) / 2);
}

// The Rectifier's own paths (offsets found once per camera, both images in one call) give
// what remapBilinear() gives from the maps alone, to the grey level; a frame that is not a
// continuous image of the calibrated size takes the maps alone.
TEST(RealRig, OffsetsAndPairsResampleExactlyAsTheMaps)
{
    const StereoCalibration& c = realRig();
    const Rectifier rectifier(c);
    const cv::Size size = toCv(c.rectified.image_size);
    const Maps left_maps = fixedPointMaps(c.left, c.R1, c.P1, size);
    const Maps right_maps = fixedPointMaps(c.right, c.R2, c.P2, size);
    for (int i : {1, 6}) {
        const cv::Mat left = readGray(samplePath("left", i));
        const cv::Mat right = readGray(samplePath("right", i));
        ASSERT_TRUE(left.isContinuous() && right.isContinuous());
        cv::Mat expected_left, expected_right;
        remapBilinear(left, left_maps.xy, left_maps.frac, expected_left);
        remapBilinear(right, right_maps.xy, right_maps.frac, expected_right);
        cv::Mat pair_left, pair_right, one_left, one_right;
        rectifier.rectifyPair(left, right, pair_left, pair_right);
        rectifier.rectifyLeft(left, one_left);
        rectifier.rectifyRight(right, one_right);
        EXPECT_EQ(cv::countNonZero(pair_left != expected_left), 0) << "pair " << i;
        EXPECT_EQ(cv::countNonZero(pair_right != expected_right), 0) << "pair " << i;
        EXPECT_EQ(cv::countNonZero(one_left != expected_left), 0) << "pair " << i;
        EXPECT_EQ(cv::countNonZero(one_right != expected_right), 0) << "pair " << i;
        // Rows further apart than the calibrated width: the maps alone, the same result.
        cv::Mat wider(left.rows, left.cols + 16, CV_8UC1, cv::Scalar(255));
        left.copyTo(wider(cv::Rect(0, 0, left.cols, left.rows)));
        cv::Mat view_left;
        rectifier.rectifyLeft(wider(cv::Rect(0, 0, left.cols, left.rows)), view_left);
        EXPECT_EQ(cv::countNonZero(view_left != expected_left), 0) << "pair " << i;
    }
    // The offsets themselves: y * step + x inside, kOutside where no neighbour is inside,
    // kOnTheEdge between, as many of each as the maps have.
    const cv::Mat offsets = remapOffsets(left_maps.xy, size, static_cast<size_t>(size.width));
    ASSERT_EQ(offsets.type(), CV_32SC1);
    const cv::Mat outside = whollyOutside(left_maps.xy, size);
    int inside = 0, edge = 0;
    for (int y = 0; y < offsets.rows; ++y)
        for (int x = 0; x < offsets.cols; ++x) {
            const cv::Vec2s xy = left_maps.xy.at<cv::Vec2s>(y, x);
            const bool whole =
                xy[0] >= 0 && xy[0] < size.width - 1 && xy[1] >= 0 && xy[1] < size.height - 1;
            const int32_t expected = whole                            ? xy[1] * size.width + xy[0]
                                     : outside.at<uint8_t>(y, x) != 0 ? resample::kOutside
                                                                      : resample::kOnTheEdge;
            ASSERT_EQ(offsets.at<int32_t>(y, x), expected) << x << ", " << y;
            inside += whole ? 1 : 0;
            edge += expected == resample::kOnTheEdge ? 1 : 0;
        }
    // Alpha 1: corners without raw data, and pixels on the raw image's edge.
    EXPECT_GT(inside, static_cast<int>(offsets.total() / 2));
    EXPECT_GT(cv::countNonZero(outside), 1000);
    EXPECT_EQ(edge, countStraddling(left_maps.xy, size));
}

// The benchmark's rig (mild distortion, a 0.5 degree turn, alpha 0) on a real scene, the
// raw pair simulated from the rectified Aloe images.
TEST(PlausibleRig, RectifiesASimulatedRawPairLikeOpenCvRemap)
{
    const cv::Size size(640, 480);
    const StereoCalibration calibration = bench::makePlausibleRigCalibration(size);
    const bench::ImagePair raw =
        bench::simulateRawPair(calibration, bench::loadScene(bench::scenes()[0], size));
    const bench::RectifyMaps maps = bench::makeRectifyMaps(calibration);
    bench::ImagePair reference;
    bench::rectifyPair(maps, raw, reference);

    const Rectifier rectifier(calibration);
    cv::Mat left, right;
    rectifier.rectifyLeft(raw.left, left);
    rectifier.rectifyRight(raw.right, right);
    const Difference l = difference(left, reference.left);
    const Difference r = difference(right, reference.right);
    std::printf("[accuracy] plausible rig, aloe 640x480, against cv::remap: max %.0f / %.0f, "
                "mean %.5f / %.5f grey levels (left / right)\n",
                l.max, r.max, l.mean, r.mean);
    EXPECT_LE(l.max, 1.0);
    EXPECT_LE(r.max, 1.0);
    EXPECT_LT(l.mean, 0.05);
    EXPECT_LT(r.mean, 0.05);
}

// A real image (Aloe, cut to 97x61: odd sizes, no multiple of any vector width) and maps
// that put the neighbourhood everywhere around and across its edges: just inside, on the
// first and last row and column, one pixel out, far out, and at the limits of int16.
class EdgeMaps : public ::testing::Test {
  protected:
    void SetUp() override
    {
        const cv::Mat aloe = readGray(kSamples + "aloeL.jpg");
        ASSERT_FALSE(aloe.empty());
        cv::resize(aloe, src_, cv::Size(97, 61), 0.0, 0.0, cv::INTER_AREA);

        const cv::Size out_size(300, 200);
        map_xy_.create(out_size, CV_16SC2);
        map_frac_.create(out_size, CV_16UC1);
        cv::RNG rng(20240611);
        const std::vector<int> special_x = specialCoordinates(src_.cols);
        const std::vector<int> special_y = specialCoordinates(src_.rows);
        const auto pick = [&rng](const std::vector<int>& values) {
            return values[static_cast<size_t>(rng.uniform(0, static_cast<int>(values.size())))];
        };
        for (int y = 0; y < out_size.height; ++y)
            for (int x = 0; x < out_size.width; ++x) {
                // Mostly around the image; a special x every fifth pixel, a special y
                // every seventh, both now and then.
                const int sx = x % 5 == 0 ? pick(special_x) : rng.uniform(-3, src_.cols + 3);
                const int sy = x % 7 == 0 ? pick(special_y) : rng.uniform(-3, src_.rows + 3);
                map_xy_.at<cv::Vec2s>(y, x) =
                    cv::Vec2s(static_cast<short>(sx), static_cast<short>(sy));
                map_frac_.at<uint16_t>(y, x) = static_cast<uint16_t>(rng.uniform(0, 1024));
            }
    }

    // Coordinates of the top-left neighbour around an image side of n pixels.
    static std::vector<int> specialCoordinates(int n)
    {
        return {-32768, -1000, -2, -1, 0, 1, n - 2, n - 1, n, n + 1, 1000, 32767};
    }

    cv::Mat src_, map_xy_, map_frac_;
};

TEST_F(EdgeMaps, MatchOpenCvAtEveryEdgeCase)
{
    cv::Mat out;
    remapBilinear(src_, map_xy_, map_frac_, out);
    ASSERT_EQ(out.type(), CV_8UC1);
    ASSERT_EQ(out.size(), map_xy_.size());
    const Difference d = difference(out, openCvRemap(src_, map_xy_, map_frac_));
    std::printf("[accuracy] edge-case maps against cv::remap: max %.0f, mean %.5f grey levels\n",
                d.max, d.mean);
    EXPECT_LE(d.max, 1.0);
    EXPECT_LT(d.mean, 0.05);

    const cv::Mat outside = whollyOutside(map_xy_, src_.size());
    ASSERT_GT(cv::countNonZero(outside), 1000);
    ASSERT_GT(countStraddling(map_xy_, src_.size()), 1000);
    EXPECT_EQ(cv::countNonZero(out & outside), 0);
}

// The left camera's colour through the same maps: each channel exactly as the grey
// resampling of that channel alone (so the colour lines up with what was matched), and
// against cv::remap within the grey contract, black where there is no raw data.
TEST_F(EdgeMaps, ColourResamplesEachChannelAsGrey)
{
    cv::Mat aloe = cv::imread(kSamples + "aloeL.jpg", cv::IMREAD_COLOR);
    ASSERT_FALSE(aloe.empty());
    cv::Mat colour;
    cv::resize(aloe, colour, src_.size(), 0.0, 0.0, cv::INTER_AREA);
    cv::Mat out;
    remapBilinear(colour, map_xy_, map_frac_, out);
    ASSERT_EQ(out.type(), CV_8UC3);
    ASSERT_EQ(out.size(), map_xy_.size());

    std::vector<cv::Mat> in_planes, out_planes;
    cv::split(colour, in_planes);
    cv::split(out, out_planes);
    for (int c = 0; c < 3; ++c) {
        cv::Mat grey;
        remapBilinear(in_planes[static_cast<size_t>(c)], map_xy_, map_frac_, grey);
        EXPECT_EQ(cv::norm(grey, out_planes[static_cast<size_t>(c)], cv::NORM_INF), 0.0)
            << "channel " << c;
    }
    cv::Mat d;
    cv::absdiff(out, openCvRemap(colour, map_xy_, map_frac_), d);
    EXPECT_LE(cv::norm(d, cv::NORM_INF), 1.0);
    EXPECT_LT(cv::mean(d.reshape(1))[0], 0.05);
    const cv::Mat outside = whollyOutside(map_xy_, src_.size());
    EXPECT_EQ(cv::countNonZero(out_planes[0] & outside) +
                  cv::countNonZero(out_planes[1] & outside) +
                  cv::countNonZero(out_planes[2] & outside),
              0);
}

TEST_F(EdgeMaps, EdgePixelsFadeToBlackLikeAConstantBorder)
{
    // A white source: inside the image every output is 255; one neighbour column out,
    // the weights of the outside neighbours are lost.
    const cv::Mat white(4, 4, CV_8UC1, cv::Scalar(255));
    cv::Mat xy(1, 4, CV_16SC2);
    cv::Mat frac(1, 4, CV_16UC1);
    // (x, y, fx, fy): wholly inside; straddling the right edge at half a pixel; straddling
    // the top-left corner a quarter pixel in each way; just outside the right edge.
    xy.at<cv::Vec2s>(0, 0) = {1, 1};
    frac.at<uint16_t>(0, 0) = 16 * 32 + 16;
    xy.at<cv::Vec2s>(0, 1) = {3, 1};
    frac.at<uint16_t>(0, 1) = 0 * 32 + 16;
    xy.at<cv::Vec2s>(0, 2) = {-1, -1};
    frac.at<uint16_t>(0, 2) = 24 * 32 + 24;
    xy.at<cv::Vec2s>(0, 3) = {4, 1};
    frac.at<uint16_t>(0, 3) = 0;
    cv::Mat out;
    remapBilinear(white, xy, frac, out);
    EXPECT_EQ(out.at<uint8_t>(0, 0), 255);
    EXPECT_EQ(out.at<uint8_t>(0, 1), 128); // 255 * 1/2, rounded
    EXPECT_EQ(out.at<uint8_t>(0, 2), 143); // 255 * (3/4)^2 = 143.4
    EXPECT_EQ(out.at<uint8_t>(0, 3), 0);
    EXPECT_EQ(cv::norm(out, openCvRemap(white, xy, frac), cv::NORM_INF), 0.0);
}

TEST_F(EdgeMaps, ReadsARegionOfABiggerImageAndReusesTheOutput)
{
    // The source as a view with a row step larger than its width.
    cv::Mat big(src_.rows + 10, src_.cols + 30, CV_8UC1, cv::Scalar(77));
    const cv::Mat view = big(cv::Rect(13, 4, src_.cols, src_.rows));
    src_.copyTo(view);
    ASSERT_FALSE(view.isContinuous());

    cv::Mat out(map_xy_.size(), CV_8UC1);
    const uint8_t* buffer = out.data;
    remapBilinear(view, map_xy_, map_frac_, out);
    EXPECT_EQ(out.data, buffer);
    // Pixels outside the view are 0, not the 77 around it in the bigger image.
    EXPECT_LE(cv::norm(out, openCvRemap(src_, map_xy_, map_frac_), cv::NORM_INF), 1.0);
}

TEST_F(EdgeMaps, RefusesWhatItCannotResample)
{
    cv::Mat out;
    const cv::Mat two_channels(src_.size(), CV_8UC2, cv::Scalar::all(0));
    EXPECT_TRUE(test::contains(test::refusalMessage<std::invalid_argument>(
                                   [&] { remapBilinear(two_channels, map_xy_, map_frac_, out); }),
                               "CV_8UC1 or CV_8UC3"));
    EXPECT_TRUE(test::contains(test::refusalMessage<std::invalid_argument>(
                                   [&] { remapBilinear(cv::Mat(), map_xy_, map_frac_, out); }),
                               "source"));
    cv::Mat float_map;
    map_xy_.convertTo(float_map, CV_32FC2);
    EXPECT_TRUE(test::contains(test::refusalMessage<std::invalid_argument>(
                                   [&] { remapBilinear(src_, float_map, map_frac_, out); }),
                               "map_xy"));
    const cv::Mat short_frac = map_frac_.rowRange(0, 10);
    EXPECT_TRUE(test::contains(test::refusalMessage<std::invalid_argument>(
                                   [&] { remapBilinear(src_, map_xy_, short_frac, out); }),
                               "map_frac"));
    // In place: the output would overwrite pixels still to be read.
    cv::Mat same(map_xy_.size(), CV_8UC1, cv::Scalar(1));
    EXPECT_TRUE(test::contains(test::refusalMessage<std::invalid_argument>(
                                   [&] { remapBilinear(same, map_xy_, map_frac_, same); }),
                               "share"));
}

TEST(Rectifier, RectifiedOnlyCalibrationCopies)
{
    const Rectifier rectifier(makeRectifiedCalibration(cv::Size(64, 48), 100.0, 0.1));
    EXPECT_FALSE(rectifier.remaps());
    cv::Mat raw(48, 64, CV_8UC1);
    cv::randu(raw, 0, 256);
    cv::Mat out;
    rectifier.rectifyLeft(raw, out);
    EXPECT_EQ(cv::norm(out, raw, cv::NORM_INF), 0.0);
    EXPECT_NE(out.data, raw.data);
}

} // namespace
} // namespace stereod
