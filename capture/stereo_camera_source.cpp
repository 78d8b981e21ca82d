#include "capture/stereo_camera_source.hpp"

#include <cerrno>
#include <cstdio>
#include <utility>

#include <spdlog/spdlog.h>

namespace stereod {

namespace {

// Buffers the driver keeps queued so that it always has one to fill.
constexpr int kDriverBuffers = 2;

// The worse of two camera states, for the source as a whole: a pair needs both.
int severity(SourceState state) noexcept
{
    switch (state) {
    case SourceState::Running:
        return 0;
    case SourceState::Stopped:
        return 1;
    case SourceState::Starting:
        return 2;
    case SourceState::Stalled:
        return 3;
    case SourceState::Finished:
        return 4;
    case SourceState::Failed:
        return 5;
    }
    return 5;
}

std::string describeCamera(const V4l2CameraStatus& camera)
{
    return camera.camera.name + " camera " + camera.device;
}

} // namespace

int cameraBufferCount(std::size_t ring_capacity, const SyncSettings& sync,
                      std::size_t inbox_capacity) noexcept
{
    // The worker holds one pair; the sync thread holds one frame in hand besides those
    // waiting.
    return static_cast<int>(kDriverBuffers + inbox_capacity + sync.max_pending + 1 + ring_capacity +
                            1);
}

std::vector<std::string> controlMismatches(const V4l2CameraStatus& left,
                                           const V4l2CameraStatus& right)
{
    std::vector<std::string> out;
    for (const ControlReading& l : left.controls) {
        const ControlReading* r = nullptr;
        for (const ControlReading& candidate : right.controls) {
            if (candidate.name == l.name)
                r = &candidate;
        }
        if (r == nullptr)
            continue;
        if (l.present != r->present) {
            out.push_back(l.name + ": only the " + (l.present ? "left" : "right") +
                          " camera has it");
        } else if (l.present && l.actual_value != r->actual_value) {
            out.push_back(l.name + ": left " + std::to_string(l.actual_value) + ", right " +
                          std::to_string(r->actual_value));
        }
        if (!l.error.empty())
            out.push_back(l.name + ": left camera: " + l.error);
        if (!r->error.empty())
            out.push_back(l.name + ": right camera: " + r->error);
    }
    return out;
}

StereoCameraSource::StereoCameraSource(StereoCameraOptions options)
    : options_(std::move(options)), sync_(options_.sync, options_.inbox_capacity),
      left_(options_.left, 0, "left"), right_(options_.right, 1, "right")
{
}

StereoCameraSource::~StereoCameraSource()
{
    stop();
}

int StereoCameraSource::start(PairRing& ring)
{
    if (running_)
        return -EBUSY;
    {
        std::lock_guard lock(error_mutex_);
        start_error_.clear();
    }
    sync_.start(ring);
    V4l2Camera* cameras[2] = {&left_, &right_};
    for (int side = 0; side < 2; ++side) {
        const int rc =
            cameras[side]->start(sync_.inbox(static_cast<StereoSide>(side)), &sync_.wake());
        if (rc < 0) {
            const V4l2CameraStatus failed = cameras[side]->status();
            {
                std::lock_guard lock(error_mutex_);
                start_error_ = describeCamera(failed) + ": " + failed.camera.last_error;
            }
            left_.stop();
            right_.stop();
            sync_.stop();
            return rc;
        }
    }
    running_ = true;
    const V4l2CameraStatus left = left_.status();
    const V4l2CameraStatus right = right_.status();
    for (const std::string& mismatch : controlMismatches(left, right))
        spdlog::warn("stereo cameras differ: {}: matching suffers", mismatch);
    if (left.format.format_name != right.format.format_name || left.format.fps != right.format.fps)
        spdlog::warn("stereo cameras differ: left {} at {:.2f} fps, right {} at {:.2f} fps",
                     left.format.format_name, left.format.fps, right.format.format_name,
                     right.format.fps);
    return 0;
}

void StereoCameraSource::stop() noexcept
{
    // Cameras first: nothing new enters the inboxes; then the sync thread, which returns
    // what it still holds to the cameras.
    left_.stop();
    right_.stop();
    sync_.stop();
    running_ = false;
}

V4l2CameraStatus StereoCameraSource::cameraStatus(StereoSide side) const
{
    return side == StereoSide::Left ? left_.status() : right_.status();
}

SourceStatus StereoCameraSource::status() const
{
    SourceStatus out;
    out.kind = "v4l2";
    const V4l2CameraStatus cameras[2] = {left_.status(), right_.status()};
    const SyncStats sync = sync_.stats();

    std::string reasons;
    out.state = SourceState::Running;
    for (int side = 0; side < 2; ++side) {
        CameraStatus camera = cameras[side].camera;
        camera.unpaired = sync.drops[side].total();
        if (severity(camera.state) > severity(out.state))
            out.state = camera.state;
        if (camera.state != SourceState::Running && !camera.last_error.empty()) {
            reasons += reasons.empty() ? "" : "; ";
            reasons += describeCamera(cameras[side]) + ": " + camera.last_error;
        }
        if (cameras[side].camera.state == SourceState::Running &&
            !cameras[side].kernel_monotonic_stamps)
            out.warnings.push_back(describeCamera(cameras[side]) +
                                   ": the driver gives no monotonic capture time; frames are "
                                   "stamped at dequeue, so pairing is only as good as delivery");
        out.cameras.push_back(std::move(camera));
    }
    {
        std::lock_guard lock(error_mutex_);
        out.last_error = !start_error_.empty() ? start_error_ : reasons;
    }

    addSyncFigures(sync, out);
    addClockOffsetWarning(sync, options_.sync.max_skew_ns, "the cameras' frames", "frames",
                          "not triggered together, or one stamps late", out);
    for (std::string& mismatch : controlMismatches(cameras[0], cameras[1]))
        out.warnings.push_back("controls differ: " + mismatch);
    return out;
}

cv::Size StereoCameraSource::frameSize() const
{
    return left_.frameSize();
}

} // namespace stereod
