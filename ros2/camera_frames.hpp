#pragma once
// The camera's frames for /tf_static (REP 103 and 105): `base_link` -> the camera body
// `stereo_link` (x forward, y left, z up; placed by robot.camera_pose) -> the optical frames
// of the rectified pair, `stereo_left_optical_frame` at the body's origin and
// `stereo_right_optical_frame` one baseline to the right (z forward, x right, y down).
//
// Reentrant: pure functions. Units: metres; rotations as unit quaternions (x, y, z, w).

#include <array>
#include <string>

#include "pipeline/zones.hpp"

namespace stereod::ros2 {

inline constexpr const char* kBaseFrame = "base_link";
inline constexpr const char* kCameraBodyFrame = "stereo_link";

struct FrameTransform {
    std::string parent;
    std::string child;
    std::array<double, 3> translation_m{};
    std::array<double, 4> rotation_xyzw{0.0, 0.0, 0.0, 1.0};
};

// Roll, pitch, yaw in degrees (fixed axes x, y, z: R = Rz(yaw) Ry(pitch) Rx(roll), as
// robot.camera_pose and tf2's setRPY) as a quaternion.
std::array<double, 4> quaternionFromRpyDeg(const cv::Vec3d& rpy_deg);

// The three transforms: base -> body, body -> left optical, body -> right optical.
std::array<FrameTransform, 3> cameraFrames(const CameraPose& pose, double baseline_m);

} // namespace stereod::ros2
