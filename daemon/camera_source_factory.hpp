#pragma once
// Builds the camera frame sources (source.type v4l2 and side_by_side, and ros2: a ROS 2
// camera driver's topics) from the service configuration: the glue between config/ and
// capture/ (and ros2/).

#include <memory>

#include "capture/frame_source.hpp"
#include "capture/v4l2_camera.hpp"
#include "config/service_config.hpp"
#include "ros2/ros2_image_source.hpp"

namespace stereod {

// The settings of one camera of `source` (buffer count sized for the ring and the sync).
// `device` is the camera's path; `keep_colour` whether it keeps its colour (where its format
// has one).
CameraSettings cameraSettings(const SourceConfig& source, const std::string& device,
                              bool keep_colour);

// The two-camera source or the side-by-side source, not started. Throws
// std::invalid_argument when the configuration is not of a camera source.
std::unique_ptr<FrameSource> makeCameraSource(const SourceConfig& source);

// The ROS 2 source of source.type ros2, not started, in the domain of ROS_DOMAIN_ID with
// the ROS 2 node's discovery (ros2.localhost_only); subscribed to the camera_info topics
// too when no calibration is configured. Throws std::invalid_argument for a ROS_DOMAIN_ID
// that is no domain or a configuration not of a ROS 2 source.
std::unique_ptr<ros2::Ros2ImageSource> makeRos2Source(const ServiceConfig& config);

} // namespace stereod
