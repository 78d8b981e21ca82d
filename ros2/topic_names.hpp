#pragma once
// ROS 2 names on DDS: a ROS topic `/ns/name` is the DDS topic `rt/ns/name` (rmw's "rt"
// prefix for topics), and a namespace is checked against ROS 2's rules before any topic
// is made from it.
//
// Reentrant: pure functions.

#include <string>
#include <string_view>

namespace stereod::ros2 {

// Why `ns` is not a ROS 2 namespace, or "" when it is one: it starts with '/', has
// tokens of letters, digits and '_' separated by single '/', no token starts with a
// digit, no '/' at the end (except "/" alone), at most 200 characters.
std::string namespaceProblem(std::string_view ns);

// The ROS 2 topic `relative` (like "left/image_rect") under `ns` ("/stereo"):
// "/stereo/left/image_rect". `ns` must pass namespaceProblem().
std::string rosTopicName(std::string_view ns, std::string_view relative);

// The camera_info topic beside an image topic, as ROS 2's camera drivers and
// image_transport pair them: "/stereo/left/image_raw" -> "/stereo/left/camera_info".
std::string cameraInfoTopicBeside(std::string_view image_topic);

// The DDS topic that carries the ROS 2 topic `ros_name` ("/stereo/depth"): "rt/stereo/depth".
std::string ddsTopicName(std::string_view ros_name);

} // namespace stereod::ros2
