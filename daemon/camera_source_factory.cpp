#include "daemon/camera_source_factory.hpp"

#include <cmath>
#include <stdexcept>

#include "capture/side_by_side_source.hpp"
#include "capture/stereo_camera_source.hpp"

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
        break;
    }
    throw std::invalid_argument("source.type replay is not a camera source");
}

} // namespace stereod
