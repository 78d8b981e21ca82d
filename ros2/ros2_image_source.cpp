#include "ros2/ros2_image_source.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <stdexcept>
#include <string_view>
#include <utility>

#include <dds/ddsi/ddsi_serdata.h>
#include <spdlog/spdlog.h>

#include "base/clock.hpp"
#include "pipeline/calibration_formats.hpp"
#include "pipeline/cv_conversions.hpp"
#include "replay/image_message.hpp"
#include "ros2/messages.hpp"
#include "ros2/node_announcement.hpp"
#include "ros2/topic_names.hpp"
#include "ros2_dds_types.h"

namespace stereod::ros2 {

namespace {

constexpr int kLeft = 0;
constexpr int kRight = 1;
constexpr uint32_t kWakeAttach = 2; // the guard condition's attachment in the waitset
constexpr uint32_t kInfoAttach = 3; // + side: the camera_info readers'
// camera_info samples taken at once; a driver sends one with every image.
constexpr int kInfoDepth = 2;
// The largest camera_info message taken: its fixed part is under 400 bytes; room for a
// long frame id and distortion model.
constexpr std::size_t kMaxInfoBytes = 16384;
// How often the reading thread looks at stop_requested_ even when nothing arrives.
constexpr dds_duration_t kWaitNs = DDS_MSECS(200);
// How long one sample of the wall clock's offset converts stamps (it moves when NTP slews).
constexpr int64_t kOffsetRefreshNs = 1'000'000'000;

dds_entity_t checked(dds_entity_t entity, const char* what)
{
    if (entity < 0)
        throw std::runtime_error(std::string(what) + ": " + dds_strretcode(entity));
    return entity;
}

std::string sizeText(cv::Size size)
{
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

// The same camera model (everything but the header).
bool sameCamera(const CameraInfo& a, const CameraInfo& b)
{
    return a.width == b.width && a.height == b.height && a.distortion_model == b.distortion_model &&
           a.d == b.d && a.k == b.k && a.r == b.r && a.p == b.p && a.binning_x == b.binning_x &&
           a.binning_y == b.binning_y && a.roi.x_offset == b.roi.x_offset &&
           a.roi.y_offset == b.roi.y_offset && a.roi.width == b.roi.width &&
           a.roi.height == b.roi.height && a.roi.do_rectify == b.roi.do_rectify;
}

std::string publishers(uint32_t writers)
{
    return std::to_string(writers) + (writers == 1 ? " publisher" : " publishers");
}

} // namespace

std::size_t Ros2ImageSource::framesPerSide(std::size_t ring_capacity,
                                           const SyncSettings& sync) noexcept
{
    // The one being filled, the inbox, the sync's queue and the one it holds in hand, the
    // ring's pairs and the worker's.
    return 1 + kInboxCapacity + sync.max_pending + 1 + ring_capacity + 1;
}

Ros2ImageSource::Ros2ImageSource(Ros2SourceOptions options)
    : options_(std::move(options)),
      pool_(2 * framesPerSide(options_.ring_capacity, options_.sync), options_.frame_size),
      sync_(options_.sync, kInboxCapacity)
{
    if (options_.frame_size.empty())
        throw std::invalid_argument("ros2 source: the frame size " + sizeText(options_.frame_size) +
                                    " is empty");
    sides_[kLeft].topic = options_.left_topic;
    sides_[kRight].topic = options_.right_topic;
    infos_[kLeft].topic = options_.left_info_topic;
    infos_[kRight].topic = options_.right_info_topic;
    if (infos_[kLeft].topic.empty() != infos_[kRight].topic.empty())
        throw std::invalid_argument("ros2 source: a camera_info topic for one camera only");
}

Ros2ImageSource::~Ros2ImageSource()
{
    stop();
}

int Ros2ImageSource::start(PairRing& ring)
{
    if (running_)
        return -EBUSY;
    {
        const std::lock_guard lock(status_mutex_);
        start_error_.clear();
    }
    try {
        participant_ = std::make_unique<DdsParticipant>(options_.discovery);
        waitset_ = checked(dds_create_waitset(participant_->handle()), "DDS waitset");
        for (int side = kLeft; side <= kRight; ++side) {
            const dds_entity_t reader =
                participant_->makeReader(ddsTopicName(sides_[side].topic),
                                         sensor_msgs_msg_dds__Image__desc, QosProfile::SensorData);
            sides_[side].reader.store(reader, std::memory_order_release);
            const dds_entity_t condition =
                checked(dds_create_readcondition(reader, DDS_ANY_STATE), "DDS read condition");
            checked(dds_waitset_attach(waitset_, condition, side), "DDS waitset attach");
            if (infos_[side].topic.empty())
                continue;
            const dds_entity_t info_reader = participant_->makeReader(
                ddsTopicName(infos_[side].topic), sensor_msgs_msg_dds__CameraInfo__desc,
                QosProfile::SensorData);
            infos_[side].reader.store(info_reader, std::memory_order_release);
            const dds_entity_t info_condition =
                checked(dds_create_readcondition(info_reader, DDS_ANY_STATE), "DDS read condition");
            checked(dds_waitset_attach(waitset_, info_condition,
                                       kInfoAttach + static_cast<uint32_t>(side)),
                    "DDS waitset attach");
        }
        NodeEntities node{options_.node_namespace, kNodeName, {}, {}};
        for (const Side& side : sides_)
            node.readers.push_back(side.reader.load(std::memory_order_relaxed));
        for (const InfoSide& side : infos_)
            if (const dds_entity_t reader = side.reader.load(std::memory_order_relaxed))
                node.readers.push_back(reader);
        announceNode(*participant_, node);
        wake_ = checked(dds_create_guardcondition(participant_->handle()), "DDS guard condition");
        checked(dds_waitset_attach(waitset_, wake_, kWakeAttach), "DDS waitset attach");
    } catch (const std::exception& e) {
        for (Side& side : sides_)
            side.reader.store(0, std::memory_order_release);
        for (InfoSide& side : infos_)
            side.reader.store(0, std::memory_order_release);
        participant_.reset(); // deletes whatever was made on it
        const std::lock_guard lock(status_mutex_);
        start_error_ = std::string("cannot subscribe to ") + options_.left_topic + " and " +
                       options_.right_topic + ": " + e.what();
        return -EIO;
    }

    sync_.start(ring);
    started_ns_.store(monotonicNowNs(), std::memory_order_release);
    stop_requested_.store(false, std::memory_order_release);
    thread_ = std::thread([this] { run(); });
    running_ = true;
    return 0;
}

void Ros2ImageSource::stop() noexcept
{
    if (!running_)
        return;
    stop_requested_.store(true, std::memory_order_release);
    dds_set_guardcondition(wake_, true);
    thread_.join();
    // Then the sync thread, which gives back the frames it still holds.
    sync_.stop();
    for (Side& side : sides_)
        side.reader.store(0, std::memory_order_release);
    for (InfoSide& side : infos_)
        side.reader.store(0, std::memory_order_release);
    participant_.reset(); // the readers, conditions and waitset with it
    waitset_ = 0;
    wake_ = 0;
    started_ns_.store(0, std::memory_order_release);
    running_ = false;
}

void Ros2ImageSource::run() noexcept
{
    dds_attach_t triggered[5];
    while (!stop_requested_.load(std::memory_order_acquire)) {
        dds_waitset_wait(waitset_, triggered, 5, kWaitNs);
        // camera_info first: a calibration is taken as soon as a pair of it is in.
        const bool left_info = takeCameraInfo(kLeft);
        const bool right_info = takeCameraInfo(kRight);
        if (left_info || right_info)
            considerCameraInfo();
        // One take of each side in turn, so that a burst on one topic does not hold the
        // other's frames back.
        bool took = true;
        while (took && !stop_requested_.load(std::memory_order_acquire)) {
            const bool left = takeSamples(kLeft);
            const bool right = takeSamples(kRight);
            took = left || right;
        }
    }
}

bool Ros2ImageSource::takeSamples(int side)
{
    std::array<ddsi_serdata*, kReaderDepth> samples{};
    std::array<dds_sample_info_t, kReaderDepth> infos{};
    const dds_return_t count =
        dds_takecdr(sides_[side].reader.load(std::memory_order_acquire), samples.data(),
                    kReaderDepth, infos.data(), DDS_ANY_STATE);
    if (count <= 0)
        return false;
    // The largest message an image of the frame size can be: four bytes a pixel with rows
    // padded to twice their width, and room for the header.
    const auto max_bytes = static_cast<std::size_t>(options_.frame_size.area()) * 4 * 2 + 65536;
    for (int i = 0; i < count; ++i) {
        if (infos[static_cast<std::size_t>(i)].valid_data) {
            const std::size_t bytes = ddsi_serdata_size(samples[static_cast<std::size_t>(i)]);
            if (bytes > max_bytes) {
                noteBad(side, "message of " + std::to_string(bytes) +
                                  " bytes, more than an image of " + sizeText(options_.frame_size) +
                                  " can be (not decoded)");
            } else {
                message_.resize(bytes);
                ddsi_serdata_to_ser(samples[static_cast<std::size_t>(i)], 0, bytes,
                                    message_.data());
                handleMessage(side, message_);
            }
        }
        ddsi_serdata_unref(samples[static_cast<std::size_t>(i)]);
    }
    return true;
}

bool Ros2ImageSource::takeCameraInfo(int side)
{
    InfoSide& s = infos_[side];
    const dds_entity_t reader = s.reader.load(std::memory_order_acquire);
    if (reader == 0)
        return false;
    std::array<ddsi_serdata*, kInfoDepth> samples{};
    std::array<dds_sample_info_t, kInfoDepth> infos{};
    const dds_return_t count =
        dds_takecdr(reader, samples.data(), kInfoDepth, infos.data(), DDS_ANY_STATE);
    if (count <= 0)
        return false;
    for (int i = 0; i < count; ++i) {
        const auto index = static_cast<std::size_t>(i);
        if (infos[index].valid_data) {
            const std::size_t bytes = ddsi_serdata_size(samples[index]);
            if (bytes > kMaxInfoBytes) {
                noteCameraInfoProblem(s.topic + ": a message of " + std::to_string(bytes) +
                                      " bytes, more than a camera_info can be (not decoded)");
            } else {
                message_.resize(bytes);
                ddsi_serdata_to_ser(samples[index], 0, bytes, message_.data());
                try {
                    s.latest = parseCameraInfo(message_);
                } catch (const CdrError& e) {
                    noteCameraInfoProblem(s.topic + ": " + e.what());
                }
            }
        }
        ddsi_serdata_unref(samples[index]);
    }
    return true;
}

void Ros2ImageSource::considerCameraInfo()
{
    InfoSide& left = infos_[kLeft];
    InfoSide& right = infos_[kRight];
    if (left.taken) {
        // Calibrated: the rectification maps stay those of the first pair.
        for (InfoSide* side : {&left, &right}) {
            if (side->latest && !sameCamera(*side->latest, *side->taken) &&
                !side->changed.exchange(true, std::memory_order_relaxed))
                spdlog::warn("ros2 source: {} changed after the calibration was taken from it: "
                             "ignored, the calibration stays the first one (restart stereod to "
                             "take the new one)",
                             side->topic);
        }
        return;
    }
    if (!left.latest || !right.latest)
        return;
    // The same pair as the one refused last: refused again, without a word.
    if (refused_[kLeft] && refused_[kRight] && sameCamera(*left.latest, *refused_[kLeft]) &&
        sameCamera(*right.latest, *refused_[kRight]))
        return;
    try {
        StereoCalibration calibration =
            calibrationFromCameraInfoMessages(*left.latest, *right.latest, left.topic, right.topic);
        const cv::Size size = toCv(calibration.rectified.image_size);
        if (size != options_.frame_size)
            throwCalibrationError(left.topic, 0, "width",
                                  "the camera_info is for " + sizeText(size) +
                                      " images, the source's are " + sizeText(options_.frame_size) +
                                      " (source.ros2.width, source.ros2.height)");
        const std::string origin = left.topic + " + " + right.topic;
        spdlog::info("ros2 source: calibration from {}: {}x{}, focal {:.1f} px, baseline {:.4f} m",
                     origin, size.width, size.height, calibration.rectified.focal_px,
                     calibration.rectified.baseline_m);
        left.taken = left.latest;
        right.taken = right.latest;
        const std::lock_guard lock(status_mutex_);
        calibration_ = CameraInfoCalibration{std::move(calibration), origin};
        camera_info_problem_.clear();
    } catch (const std::exception& e) {
        refused_[kLeft] = left.latest;
        refused_[kRight] = right.latest;
        noteCameraInfoProblem(e.what());
    }
}

void Ros2ImageSource::noteCameraInfoProblem(std::string problem)
{
    const std::lock_guard lock(status_mutex_);
    if (problem == camera_info_problem_)
        return;
    spdlog::error("ros2 source: camera_info refused: {}; uncalibrated until a camera_info pair "
                  "passes",
                  problem);
    camera_info_problem_ = std::move(problem);
}

std::optional<CameraInfoCalibration> Ros2ImageSource::cameraInfoCalibration() const
{
    const std::lock_guard lock(status_mutex_);
    return calibration_;
}

void Ros2ImageSource::handleMessage(int side, std::string_view message)
{
    Side& s = sides_[side];
    const int64_t now_ns = monotonicNowNs();
    int64_t header_ns = 0;
    try {
        header_ns = parseImage(message).header.stamp.toNs();
    } catch (const CdrError& e) {
        noteBad(side, e.what());
        return;
    }
    FrameHandle frame = pool_.acquire();
    if (!frame) {
        s.dropped.fetch_add(1, std::memory_order_relaxed);
        noteArrival(s, now_ns);
        return;
    }
    // Decoded through a second header on the pool's buffer: the same size and type, so
    // nothing is allocated, and a refused message leaves the pool's frame as it was.
    cv::Mat pixels = frame->image;
    std::string reason;
    if (!decodeImageMessage(message, options_.frame_size, pixels, reason)) {
        noteBad(side, std::move(reason));
        return;
    }
    if (pixels.data != frame->image.data)
        pixels.copyTo(frame->image);
    frame->source_stamp_ns = header_ns;
    // One offset for a while rather than one per image: two images of one stamp get one
    // monotonic stamp (a fresh sample each time differs by the clock reads' time).
    if (offset_ns_ == 0 || now_ns - offset_sampled_ns_ > kOffsetRefreshNs) {
        offset_ns_ = realtimeOffsetNs();
        offset_sampled_ns_ = now_ns;
    }
    frame->stamp_ns = saturatingSubNs(header_ns, offset_ns_);
    frame->sequence = s.sequence++;
    s.frames.fetch_add(1, std::memory_order_relaxed);
    noteArrival(s, now_ns);
    sync_.offer(static_cast<StereoSide>(side), std::move(frame));
}

void Ros2ImageSource::noteBad(int side, std::string reason)
{
    Side& s = sides_[side];
    if (s.bad.fetch_add(1, std::memory_order_relaxed) == 0)
        spdlog::warn("ros2 source: {}: bad image message: {} (counted in status from now on)",
                     s.topic, reason);
    noteArrival(s, monotonicNowNs());
    const std::lock_guard lock(status_mutex_);
    bad_reasons_[static_cast<std::size_t>(side)] = std::move(reason);
}

void Ros2ImageSource::noteArrival(Side& side, int64_t now_ns) noexcept
{
    side.last_arrival_ns.store(now_ns, std::memory_order_release);
    side.fps.add(now_ns);
}

SourceStatus Ros2ImageSource::status() const
{
    SourceStatus out;
    out.kind = "ros2";
    const int64_t now_ns = monotonicNowNs();
    const int64_t started_ns = started_ns_.load(std::memory_order_acquire);
    const SyncStats sync = sync_.stats();

    std::string reasons;
    out.state = started_ns == 0 ? SourceState::Stopped : SourceState::Running;
    for (int side = kLeft; side <= kRight; ++side) {
        const Side& s = sides_[side];
        CameraStatus camera;
        camera.name = s.topic;
        camera.frames = s.frames.load(std::memory_order_relaxed);
        camera.dropped = s.dropped.load(std::memory_order_relaxed);
        camera.bad_frames = s.bad.load(std::memory_order_relaxed);
        camera.fps = s.fps.perSecond();
        camera.unpaired = sync.drops[side].total();
        {
            const std::lock_guard lock(status_mutex_);
            camera.last_bad_frame = bad_reasons_[static_cast<std::size_t>(side)];
        }
        if (started_ns == 0) {
            camera.state = SourceState::Stopped;
        } else {
            const int64_t last_ns = s.last_arrival_ns.load(std::memory_order_acquire);
            const int64_t since_ns = now_ns - (last_ns > started_ns ? last_ns : started_ns);
            const uint32_t writers =
                DdsParticipant::matchedWriters(s.reader.load(std::memory_order_acquire));
            char text[300];
            if (since_ns > options_.stall_timeout_ns) {
                camera.state = SourceState::Stalled;
                std::snprintf(text, sizeof text, "no image on %s for %.0f ms (%u %s)",
                              s.topic.c_str(), static_cast<double>(since_ns) / 1e6, writers,
                              writers == 1 ? "publisher" : "publishers");
                camera.last_error = text;
            } else if (last_ns < started_ns) {
                camera.state = SourceState::Starting;
                std::snprintf(text, sizeof text, "waiting for images on %s (%u %s)",
                              s.topic.c_str(), writers, writers == 1 ? "publisher" : "publishers");
                camera.last_error = text;
            } else {
                camera.state = SourceState::Running;
            }
        }
        // The worse of the two: stalled over starting over running.
        if (camera.state == SourceState::Stalled ||
            (camera.state == SourceState::Starting && out.state == SourceState::Running))
            out.state = camera.state;
        if (!camera.last_error.empty())
            reasons += (reasons.empty() ? "" : "; ") + camera.last_error;
        out.cameras.push_back(std::move(camera));
    }
    {
        const std::lock_guard lock(status_mutex_);
        if (!start_error_.empty()) {
            out.state = SourceState::Failed;
            out.last_error = start_error_;
        } else {
            out.last_error = reasons;
        }
    }

    if (started_ns != 0 && !infos_[kLeft].topic.empty()) {
        const std::lock_guard lock(status_mutex_);
        if (!calibration_ && !camera_info_problem_.empty()) {
            out.warnings.push_back("camera_info refused: " + camera_info_problem_ +
                                   "; uncalibrated until a camera_info pair passes");
        } else if (!calibration_) {
            const auto writers = [](const InfoSide& side) {
                return publishers(
                    DdsParticipant::matchedWriters(side.reader.load(std::memory_order_acquire)));
            };
            out.warnings.push_back("waiting for camera_info on " + infos_[kLeft].topic + " (" +
                                   writers(infos_[kLeft]) + ") and " + infos_[kRight].topic + " (" +
                                   writers(infos_[kRight]) + "): uncalibrated until both arrive");
        }
        for (const InfoSide& side : infos_)
            if (side.changed.load(std::memory_order_relaxed))
                out.warnings.push_back(side.topic +
                                       " changed after the calibration was taken from it: "
                                       "ignored (a restart takes the new one)");
    }
    addSyncFigures(sync, out);
    addClockOffsetWarning(sync, options_.sync.max_skew_ns, "the two topics' stamps", "images",
                          "the driver does not stamp a pair alike", out);
    return out;
}

} // namespace stereod::ros2
