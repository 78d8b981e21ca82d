#include "daemon/camera_source_factory.hpp"

#include <cmath>
#include <stdexcept>

#include "capture/side_by_side_source.hpp"
#include "capture/stereo_camera_source.hpp"
#include "ros2/ros2_image_source.hpp"

namespace stereod {

namespace {

constexpr std::size_t kInboxCapacity = 4;

SyncSettings syncSettings(const SourceConfig& source)
{
    SyncSettings sync;
    sync.max_skew_ns = std::llround(source.max_skew_ms * 1e6);
    return sync;
}

} // namespace

CameraSettings cameraSettings(const SourceConfig& source, const std::string& device,
                              bool keep_colour)
{
    const CamerasConfig& cameras = source.cameras;
    CameraSettings settings;
    settings.device = device;
    settings.format = cameras.format;
    settings.width = cameras.width;
    settings.height = cameras.height;
    settings.fps = cameras.fps;
    settings.controls = cameras.controls;
    settings.lock_exposure = cameras.lock_exposure;
    settings.keep_colour = keep_colour;
    const auto ring = static_cast<std::size_t>(source.ring_capacity);
    settings.buffer_count = cameraBufferCount(
        ring, source.kind == SourceKind::V4l2 ? syncSettings(source) : SyncSettings{0, 0},
        kInboxCapacity);
    return settings;
}

std::unique_ptr<FrameSource> makeCameraSource(const SourceConfig& source)
{
    switch (source.kind) {
    case SourceKind::V4l2: {
        StereoCameraOptions options;
        const CameraColour colour = source.cameras.colour;
        options.left = cameraSettings(source, source.cameras.left, colour != CameraColour::None);
        options.right = cameraSettings(source, source.cameras.right, colour == CameraColour::Both);
        options.sync = syncSettings(source);
        options.inbox_capacity = kInboxCapacity;
        return std::make_unique<StereoCameraSource>(std::move(options));
    }
    case SourceKind::SideBySide: {
        SideBySideOptions options;
        const CameraColour colour = source.cameras.colour;
        options.camera =
            cameraSettings(source, source.cameras.device, colour != CameraColour::None);
        options.right_colour = colour == CameraColour::Both;
        options.inbox_capacity = kInboxCapacity;
        options.ring_capacity = static_cast<std::size_t>(source.ring_capacity);
        return std::make_unique<SideBySideSource>(std::move(options));
    }
    case SourceKind::Replay:
    case SourceKind::Ros2:
        break;
    }
    throw std::invalid_argument("source.type replay or ros2 is not a camera source");
}

std::unique_ptr<ros2::Ros2ImageSource> makeRos2Source(const ServiceConfig& config)
{
    const SourceConfig& source = config.source;
    if (source.kind != SourceKind::Ros2)
        throw std::invalid_argument("source.type is not ros2");
    ros2::Ros2SourceOptions options;
    options.left_topic = source.ros2.left_topic;
    options.right_topic = source.ros2.right_topic;
    options.node_namespace = config.ros2.ns;
    if (config.calibration_path.empty()) {
        options.left_info_topic = leftCameraInfoTopic(source.ros2);
        options.right_info_topic = rightCameraInfoTopic(source.ros2);
    }
    options.frame_size = cv::Size(source.ros2.width, source.ros2.height);
    options.discovery = ros2::discoveryFromEnvironment(config.ros2.localhost_only);
    options.sync = syncSettings(source);
    options.stall_timeout_ns = std::llround(source.stall_timeout_ms * 1e6);
    options.ring_capacity = static_cast<std::size_t>(source.ring_capacity);
    return std::make_unique<ros2::Ros2ImageSource>(std::move(options));
}

} // namespace stereod
