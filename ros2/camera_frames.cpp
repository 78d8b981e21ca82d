#include "ros2/camera_frames.hpp"

#include <cmath>

#include "pipeline/cv_conversions.hpp"
#include "ros2/messages.hpp"

namespace stereod::ros2 {

std::array<double, 4> quaternionFromRpyDeg(const cv::Vec3d& rpy_deg)
{
    const double half = M_PI / 360.0; // degrees to half an angle in radians
    const double cr = std::cos(rpy_deg[0] * half), sr = std::sin(rpy_deg[0] * half);
    const double cp = std::cos(rpy_deg[1] * half), sp = std::sin(rpy_deg[1] * half);
    const double cy = std::cos(rpy_deg[2] * half), sy = std::sin(rpy_deg[2] * half);
    return {sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy};
}

std::array<FrameTransform, 3> cameraFrames(const CameraPose& pose, double baseline_m)
{
    // The optical frame in the body: its x (right) is the body's -y, its y (down) the
    // body's -z, its z the body's x; the quaternion of that rotation.
    constexpr std::array<double, 4> kOpticalInBody = {-0.5, 0.5, -0.5, 0.5};
    std::array<FrameTransform, 3> frames;
    frames[0] = {kBaseFrame,
                 kCameraBodyFrame,
                 {pose.translation_m[0], pose.translation_m[1], pose.translation_m[2]},
                 quaternionFromRpyDeg(toCv(pose.rpy_deg))};
    frames[1] = {kCameraBodyFrame, kLeftOpticalFrame, {0.0, 0.0, 0.0}, kOpticalInBody};
    frames[2] = {kCameraBodyFrame, kRightOpticalFrame, {0.0, -baseline_m, 0.0}, kOpticalInBody};
    return frames;
}

} // namespace stereod::ros2
