// ROS 2's rules as stereod follows them, without DDS: names, the Range of every kind of
// reading, the camera's frames (/tf_static) and ROS's image conventions.
#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "ros2/camera_frames.hpp"
#include "ros2/conventions.hpp"
#include "ros2/range_reading.hpp"
#include "ros2/topic_names.hpp"

namespace stereod::ros2 {
namespace {

TEST(Ros2Names, NamespacesFollowRos2Rules)
{
    for (const char* good : {"/", "/stereo", "/robot_1/front_stereo"})
        EXPECT_EQ(namespaceProblem(good), "") << good;
    EXPECT_EQ(namespaceProblem(""), "must start with '/'");
    EXPECT_EQ(namespaceProblem("stereo"), "must start with '/'");
    EXPECT_EQ(namespaceProblem("/stereo/"), "must not end with '/'");
    EXPECT_EQ(namespaceProblem("/a//b"), "has an empty name between two '/'");
    EXPECT_EQ(namespaceProblem("/1stereo"), "has a name that starts with a digit");
    EXPECT_EQ(namespaceProblem("/ste-reo"),
              "has '-': only letters, digits, '_' and '/' are allowed");
    EXPECT_EQ(namespaceProblem("/" + std::string(200, 'a')), "longer than 200 characters");
}

TEST(Ros2Names, TopicsUnderTheNamespaceAndOnDds)
{
    EXPECT_EQ(rosTopicName("/stereo", "left/image_rect"), "/stereo/left/image_rect");
    EXPECT_EQ(rosTopicName("/", "depth"), "/depth");
    EXPECT_EQ(ddsTopicName("/stereo/depth"), "rt/stereo/depth");
    EXPECT_EQ(ddsTopicName("/tf_static"), "rt/tf_static");
}

// Tsukuba's geometry: 384 px wide, f = 615 px, the region the middle half.
RectifiedGeometry geometry()
{
    RectifiedGeometry g;
    g.image_size = ImageSize{384, 288};
    g.focal_px = 615.0;
    g.cx_px = 192.0;
    g.cy_px = 144.0;
    g.baseline_m = 0.1;
    return g;
}

TEST(Ros2Range, EveryReasonAsTheMessageDefinesIt)
{
    NearestSettings nearest;
    nearest.min_depth_m = 0.1;
    nearest.max_depth_m = 20.0;
    Reading reading;
    reading.closest_m = 0.5; // the matcher sees from 0.5 m: nearer cannot be reported
    reading.valid = true;
    reading.distance_m = 1.25;
    RangeValues v = rangeFromReading(reading, nearest, geometry());
    EXPECT_FLOAT_EQ(v.range, 1.25f);
    EXPECT_FLOAT_EQ(v.min_range, 0.5f);
    EXPECT_FLOAT_EQ(v.max_range, 20.0f);
    // The middle half of 384 px at f = 615 px: 2 * atan(96 / 615).
    EXPECT_NEAR(v.field_of_view, 2.0 * std::atan(96.0 / 615.0), 1e-6);

    reading.valid = false;
    reading.reason = NoReadingReason::NearerThanRange;
    v = rangeFromReading(reading, nearest, geometry());
    EXPECT_TRUE(std::isinf(v.range) && v.range < 0) << v.range;
    reading.reason = NoReadingReason::NothingInRange;
    v = rangeFromReading(reading, nearest, geometry());
    EXPECT_TRUE(std::isinf(v.range) && v.range > 0) << v.range;
    for (const NoReadingReason reason :
         {NoReadingReason::NoFrameYet, NoReadingReason::TooFewValidPixels,
          NoReadingReason::OutOfSync, NoReadingReason::SourceDown, NoReadingReason::BadFrame,
          NoReadingReason::CalibrationSuspect, NoReadingReason::Stale,
          NoReadingReason::Uncalibrated}) {
        reading.reason = reason;
        EXPECT_TRUE(std::isnan(rangeFromReading(reading, nearest, geometry()).range))
            << reasonCode(reason);
    }

    // No matcher behind the reading: the configured minimum.
    reading.closest_m = 0.0;
    EXPECT_FLOAT_EQ(rangeFromReading(reading, nearest, geometry()).min_range, 0.1f);
}

cv::Matx33d rotationOf(const std::array<double, 4>& q)
{
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    return {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
            2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y)};
}

TEST(Ros2Frames, RollPitchYawAsFixedAxes)
{
    const cv::Vec3d rpy(10.0, -20.0, 35.0);
    const double k = M_PI / 180.0;
    const double r = rpy[0] * k, p = rpy[1] * k, y = rpy[2] * k;
    const cv::Matx33d rx(1, 0, 0, 0, std::cos(r), -std::sin(r), 0, std::sin(r), std::cos(r));
    const cv::Matx33d ry(std::cos(p), 0, std::sin(p), 0, 1, 0, -std::sin(p), 0, std::cos(p));
    const cv::Matx33d rz(std::cos(y), -std::sin(y), 0, std::sin(y), std::cos(y), 0, 0, 0, 1);
    const cv::Matx33d expected = rz * ry * rx;
    const cv::Matx33d got = rotationOf(quaternionFromRpyDeg(rpy));
    for (int i = 0; i < 9; ++i)
        EXPECT_NEAR(got.val[i], expected.val[i], 1e-12) << i;
}

TEST(Ros2Frames, BaseToBodyToOpticalFrames)
{
    CameraPose pose;
    pose.translation_m = {0.2, 0.0, 0.5};
    pose.rpy_deg = {0.0, 15.0, 0.0};
    const auto frames = cameraFrames(pose, 0.12);
    EXPECT_EQ(frames[0].parent, "base_link");
    EXPECT_EQ(frames[0].child, "stereo_link");
    EXPECT_EQ(frames[0].translation_m, (std::array<double, 3>{0.2, 0.0, 0.5}));
    EXPECT_EQ(frames[1].parent, "stereo_link");
    EXPECT_EQ(frames[1].child, "stereo_left_optical_frame");
    EXPECT_EQ(frames[2].child, "stereo_right_optical_frame");
    // The right camera one baseline to the right: the body's -y.
    EXPECT_EQ(frames[2].translation_m, (std::array<double, 3>{0.0, -0.12, 0.0}));
    // Optical z (forward) is the body's x, optical x (right) its -y, optical y (down) its -z.
    const cv::Matx33d optical = rotationOf(frames[1].rotation_xyzw);
    const cv::Vec3d z = optical * cv::Vec3d(0, 0, 1), x = optical * cv::Vec3d(1, 0, 0),
                    y = optical * cv::Vec3d(0, 1, 0);
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(z[i], (cv::Vec3d(1, 0, 0))[i], 1e-12);
        EXPECT_NEAR(x[i], (cv::Vec3d(0, -1, 0))[i], 1e-12);
        EXPECT_NEAR(y[i], (cv::Vec3d(0, 0, -1))[i], 1e-12);
    }
}

TEST(Ros2Conventions, DepthNanDisparityBelowRangeRightCameraP3)
{
    cv::Mat depth = (cv::Mat_<float>(1, 3) << 0.0f, 1.5f, 0.0f);
    std::vector<float> out;
    depthWithNan(depth, out);
    ASSERT_EQ(out.size(), 3u);
    EXPECT_TRUE(std::isnan(out[0]) && std::isnan(out[2]));
    EXPECT_FLOAT_EQ(out[1], 1.5f);

    cv::Mat disparity = (cv::Mat_<float>(1, 2) << std::numeric_limits<float>::infinity(), 12.25f);
    disparityForRos(disparity, 4.0f, out);
    EXPECT_FLOAT_EQ(out[0], 3.0f); // below min_disparity: invalid
    EXPECT_FLOAT_EQ(out[1], 12.25f);

    const CameraInfo left = rectifiedCameraInfo(geometry(), false, 5);
    const CameraInfo right = rectifiedCameraInfo(geometry(), true, 5);
    EXPECT_EQ(left.header.frame_id, "stereo_left_optical_frame");
    EXPECT_EQ(right.header.frame_id, "stereo_right_optical_frame");
    EXPECT_DOUBLE_EQ(left.p[3], 0.0);
    EXPECT_DOUBLE_EQ(right.p[3], -615.0 * 0.1);
    EXPECT_DOUBLE_EQ(left.k[0], 615.0);
}

// Colour as ROS carries it: the left image rgb8 (red first) or mono8, and a cloud point's
// colour as PCL packs it, 0x00RRGGBB's bits in a float32, interleaved after x y z
// intensity; the subsampled cloud keeps each point's own colour.
TEST(Ros2Conventions, ColourLeftImageAndPackedCloudColours)
{
    DepthResult result;
    result.left_rectified = cv::Mat(2, 3, CV_8UC1, cv::Scalar(9));
    cv::Mat out;
    EXPECT_STREQ(ros2::leftImageForRos(result, out), "mono8");
    EXPECT_EQ(out.type(), CV_8UC1);
    result.left_rectified_colour = cv::Mat(2, 3, CV_8UC3, cv::Scalar(1, 2, 3)); // B G R
    EXPECT_STREQ(ros2::leftImageForRos(result, out), "rgb8");
    EXPECT_EQ(out.at<cv::Vec3b>(1, 2), cv::Vec3b(3, 2, 1));

    const float packed = ros2::packedRgb({0x12, 0x34, 0x56});
    uint32_t bits = 0;
    std::memcpy(&bits, &packed, sizeof bits);
    EXPECT_EQ(bits, 0x00123456u);

    for (int i = 0; i < 5; ++i) {
        const auto v = static_cast<float>(i);
        result.cloud.push_back({v, v + 0.5f, v + 1.0f, 10.0f * v});
        result.cloud_colour.push_back({static_cast<uint8_t>(i), 0, 0});
    }
    std::vector<CloudPoint> points;
    std::vector<CloudColour> colours;
    ros2::subsampleCloud(result, 2, points, colours);
    ASSERT_EQ(points.size(), 3u);
    ASSERT_EQ(colours.size(), 3u);
    EXPECT_EQ(points[2].x, 4.0f);
    EXPECT_EQ(colours[2].r, 4);
    std::vector<float> interleaved;
    ros2::xyziRgbCloud(points, colours, interleaved);
    ASSERT_EQ(interleaved.size(), 15u);
    EXPECT_EQ(interleaved[5], 2.0f);  // the second point's x
    EXPECT_EQ(interleaved[8], 20.0f); // its intensity
    std::memcpy(&bits, &interleaved[9], sizeof bits);
    EXPECT_EQ(bits, 0x00020000u); // its colour, red 2

    // A grey result: no colours, so the cloud goes out without the rgb field.
    result.cloud_colour.clear();
    ros2::subsampleCloud(result, 1, points, colours);
    EXPECT_EQ(points.size(), 5u);
    EXPECT_TRUE(colours.empty());
}

} // namespace
} // namespace stereod::ros2
