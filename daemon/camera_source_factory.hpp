#pragma once
// Builds the camera frame sources (source.type v4l2 and side_by_side) from the service
// configuration: the glue between config/ and capture/.

#include <memory>

#include "capture/frame_source.hpp"
#include "capture/v4l2_camera.hpp"
#include "config/service_config.hpp"

namespace stereod {

// The settings of one camera of `source` (buffer count sized for the ring and the sync).
// `device` is the camera's path; `keep_colour` whether it keeps its colour (where its format
// has one).
CameraSettings cameraSettings(const SourceConfig& source, const std::string& device,
                              bool keep_colour);

// The two-camera source or the side-by-side source, not started. Throws
// std::invalid_argument when the configuration is not of a camera source.
std::unique_ptr<FrameSource> makeCameraSource(const SourceConfig& source);

} // namespace stereod
