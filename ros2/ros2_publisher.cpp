#include "ros2/ros2_publisher.hpp"

#include <algorithm>
#include <chrono>

#include <spdlog/spdlog.h>

#include "base/clock.hpp"
#include "ros2/camera_frames.hpp"
#include "ros2/conventions.hpp"
#include "ros2/messages.hpp"
#include "ros2/node_announcement.hpp"
#include "ros2/range_reading.hpp"
#include "ros2/topic_names.hpp"
#include "ros2_dds_types.h"

namespace stereod::ros2 {

namespace {

constexpr int64_t kStatusSilenceNs = 1'000'000'000; // no frame for this long: status speaks
constexpr auto kMatchRefresh = std::chrono::milliseconds(200);
constexpr uint8_t kRadiationInfrared = 1; // sensor_msgs/msg/Range: light, not sound

// Cyclone reads the strings and sequences of a sample during dds_write() and keeps
// nothing: the samples below borrow our buffers.
char* borrow(const std::string& text)
{
    return const_cast<char*>(text.c_str());
}
char* borrow(const char* text)
{
    return const_cast<char*>(text);
}

dds_sequence_octet borrowBytes(const void* data, std::size_t size)
{
    const auto length = static_cast<uint32_t>(size);
    return {length, length, static_cast<uint8_t*>(const_cast<void*>(data)), false};
}

void fillHeader(std_msgs_msg_dds__Header_& header, const Time& stamp, const char* frame_id)
{
    header.stamp.sec = stamp.sec;
    header.stamp.nanosec = stamp.nanosec;
    header.frame_id = borrow(frame_id);
}

void fillImage(sensor_msgs_msg_dds__Image_& image, const Time& stamp, const char* frame_id,
               const cv::Mat& size, const char* encoding, uint32_t step, const void* data)
{
    fillHeader(image.header, stamp, frame_id);
    image.height = static_cast<uint32_t>(size.rows);
    image.width = static_cast<uint32_t>(size.cols);
    image.encoding = borrow(encoding);
    image.is_bigendian = 0;
    image.step = step;
    image.data = borrowBytes(data, std::size_t{step} * image.height);
}

} // namespace

const std::array<Ros2ChannelSpec, kRos2ChannelCount>& ros2Channels()
{
    static const std::array<Ros2ChannelSpec, kRos2ChannelCount> channels = {{
        {"left/image_rect", kImageType},
        {"depth", kImageType},
        {"disparity", kDisparityImageType},
        {"points", kPointCloud2Type},
        {"left/camera_info", kCameraInfoType},
        {"right/camera_info", kCameraInfoType},
        {"nearest", "sensor_msgs/msg/Range"},
        {"reading", "std_msgs/msg/String"},
        {"/tf_static", "tf2_msgs/msg/TFMessage"},
    }};
    return channels;
}

struct Ros2Publisher::Writers {
    explicit Writers(const DdsDiscovery& discovery) : participant(discovery) {}
    DdsParticipant participant;
    std::array<dds_entity_t, kRos2ChannelCount> writer{};
};

Ros2Publisher::Ros2Publisher(Ros2Settings settings, RectifiedGeometry geometry,
                             NearestSettings nearest, CameraPose pose)
    : settings_(std::move(settings)), geometry_(geometry), nearest_(nearest), pose_(pose)
{
}

Ros2Publisher::~Ros2Publisher()
{
    stop();
}

std::string Ros2Publisher::start()
{
    const std::array<const dds_topic_descriptor_t*, kRos2ChannelCount> types = {
        &sensor_msgs_msg_dds__Image__desc,          &sensor_msgs_msg_dds__Image__desc,
        &stereo_msgs_msg_dds__DisparityImage__desc, &sensor_msgs_msg_dds__PointCloud2__desc,
        &sensor_msgs_msg_dds__CameraInfo__desc,     &sensor_msgs_msg_dds__CameraInfo__desc,
        &sensor_msgs_msg_dds__Range__desc,          &std_msgs_msg_dds__String__desc,
        &tf2_msgs_msg_dds__TFMessage__desc};
    try {
        if (const std::string problem = namespaceProblem(settings_.ns); !problem.empty())
            throw std::invalid_argument("ros2.namespace: '" + settings_.ns + "' " + problem);
        auto writers = std::make_unique<Writers>(settings_.discovery);
        for (uint32_t c = 0; c < kRos2ChannelCount; ++c) {
            const char* topic = ros2Channels()[c].topic;
            const std::string name = topic[0] == '/' ? topic : rosTopicName(settings_.ns, topic);
            QosProfile profile = QosProfile::Reliable;
            if (c <= kPointsChannel)
                profile = QosProfile::SensorData;
            else if (c == kTfStaticChannel)
                profile = QosProfile::StaticTf;
            writers->writer[c] =
                writers->participant.makeWriter(ddsTopicName(name), *types[c], profile);
        }
        // `ros2 node list` shows /NAMESPACE/stereod, `ros2 node info` its publishers.
        announceNode(writers->participant,
                     {settings_.ns,
                      kNodeName,
                      {},
                      std::vector<dds_entity_t>(writers->writer.begin(), writers->writer.end())});
        writers_ = std::move(writers);
    } catch (const std::exception& e) {
        std::lock_guard lock(mutex_);
        error_ = e.what();
        return error_;
    }
    CameraPose pose;
    double baseline_m = 0.0;
    {
        std::lock_guard lock(mutex_);
        pose = pose_;
        baseline_m = geometry_.baseline_m;
    }
    publishStaticFrames(pose, baseline_m);
    publishing_.store(true, std::memory_order_release);
    thread_ = std::thread([this] { run(); });
    return {};
}

void Ros2Publisher::stop()
{
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable())
        thread_.join();
    publishing_.store(false, std::memory_order_release);
    writers_.reset();
}

void Ros2Publisher::offerFrame(const DepthResult& r, int64_t stamp_realtime_ns, bool depth_valid,
                               const DisparityRange& range, const CameraPose& pose,
                               std::string_view reading_json)
{
    if (!publishing_.load(std::memory_order_acquire))
        return;
    {
        std::lock_guard lock(mutex_);
        Mailbox& m = mailbox_;
        if (m.frame)
            frames_skipped_.fetch_add(1, std::memory_order_relaxed);
        m.frame = true;
        m.stamp_realtime_ns = stamp_realtime_ns;
        m.left.release();
        m.depth_m.release();
        m.disparity.release();
        if (wanted(kImageChannel))
            m.left_encoding = leftImageForRos(r, m.left);
        if (wanted(kDepthChannel))
            copyTrustedDepth(r, depth_valid, m.depth_m);
        if (wanted(kDisparityChannel))
            r.disparity.copyTo(m.disparity);
        m.min_disparity = static_cast<float>(range.min_disparity);
        m.max_disparity = static_cast<float>(range.min_disparity + range.num_disparities);
        m.cloud.clear();
        m.cloud_colour.clear();
        m.points_taken = wanted(kPointsChannel);
        m.points_in_colour = !r.left_rectified_colour.empty();
        if (m.points_taken && depth_valid)
            subsampleCloud(r, settings_.points_step, m.cloud, m.cloud_colour);
        m.reading = r.reading;
        m.reading_json.assign(reading_json);
        m.pose = pose;
    }
    wake_.notify_one();
}

void Ros2Publisher::offerStatus(std::string_view reading_json, int64_t reading_realtime_ns)
{
    if (!publishing_.load(std::memory_order_acquire))
        return;
    {
        std::lock_guard lock(mutex_);
        mailbox_.status = true;
        mailbox_.status_reading_json.assign(reading_json);
        mailbox_.status_realtime_ns = reading_realtime_ns;
    }
    wake_.notify_one();
}

void Ros2Publisher::setNearest(const NearestSettings& nearest)
{
    std::lock_guard lock(mutex_);
    nearest_ = nearest;
}

void Ros2Publisher::setGeometry(const RectifiedGeometry& geometry)
{
    std::lock_guard lock(mutex_);
    geometry_ = geometry;
}

Ros2Counters Ros2Publisher::counters() const
{
    Ros2Counters c;
    c.publishing = publishing_.load(std::memory_order_acquire);
    {
        std::lock_guard lock(mutex_);
        c.error = error_;
    }
    c.domain_id = settings_.discovery.domain_id;
    c.localhost_only = settings_.discovery.localhost_only;
    c.frames = frames_.load(std::memory_order_relaxed);
    c.frames_skipped = frames_skipped_.load(std::memory_order_relaxed);
    c.messages = messages_.load(std::memory_order_relaxed);
    c.write_errors = write_errors_.load(std::memory_order_relaxed);
    c.readers = readers_.load(std::memory_order_relaxed);
    return c;
}

void Ros2Publisher::refreshMatches()
{
    uint64_t readers = 0;
    for (uint32_t c = 0; c < kRos2ChannelCount; ++c) {
        const uint32_t matched = DdsParticipant::matchedReaders(writers_->writer[c]);
        wanted_[c].store(matched > 0, std::memory_order_relaxed);
        readers += matched;
    }
    readers_.store(readers, std::memory_order_relaxed);
}

void Ros2Publisher::countWrite(int code) noexcept
{
    if (code < 0)
        write_errors_.fetch_add(1, std::memory_order_relaxed);
    else
        messages_.fetch_add(1, std::memory_order_relaxed);
}

void Ros2Publisher::run()
{
    Mailbox work;
    Scratch scratch;
    int64_t last_frame_ns = 0;
    refreshMatches();
    while (true) {
        {
            std::unique_lock lock(mutex_);
            wake_.wait_for(lock, kMatchRefresh,
                           [this] { return stopping_ || mailbox_.frame || mailbox_.status; });
            if (stopping_)
                return;
            std::swap(work, mailbox_);
            mailbox_.frame = false;
            mailbox_.status = false;
            work.nearest = nearest_;
            work.geometry = geometry_;
        }
        refreshMatches();
        const int64_t now_ns = monotonicNowNs();
        if (work.frame) {
            last_frame_ns = now_ns;
            publishFrame(work, scratch, now_ns);
        }
        if (work.status && now_ns - last_frame_ns > kStatusSilenceNs) {
            // No frame for a second: the reading says why (source down, stale); the Range
            // has no reading.
            const int64_t stamp_ns = work.status_realtime_ns != 0
                                         ? work.status_realtime_ns
                                         : saturatingAddNs(now_ns, realtimeOffsetNs());
            Reading none;
            none.reason = NoReadingReason::SourceDown;
            const RangeValues values = rangeFromReading(none, work.nearest, work.geometry);
            writeRange(values, Time::fromNs(stamp_ns));
            publishReadingJson(work.status_reading_json);
        }
    }
}

void Ros2Publisher::writeRange(const RangeValues& values, const Time& stamp)
{
    sensor_msgs_msg_dds__Range_ range{};
    fillHeader(range.header, stamp, kLeftOpticalFrame);
    range.radiation_type = kRadiationInfrared;
    range.field_of_view = values.field_of_view;
    range.min_range = values.min_range;
    range.max_range = values.max_range;
    range.range = values.range;
    countWrite(dds_write(writers_->writer[kRangeChannel], &range));
}

void Ros2Publisher::publishReadingJson(const std::string& json)
{
    std_msgs_msg_dds__String_ text{};
    text.data = borrow(json);
    countWrite(dds_write(writers_->writer[kReadingChannel], &text));
}

void Ros2Publisher::publishFrame(const Mailbox& work, Scratch& scratch, int64_t now_ns)
{
    auto& last_sent_ns = scratch.last_sent_ns;
    const int64_t interval_ns =
        settings_.max_rate_hz > 0 ? static_cast<int64_t>(1e9 / settings_.max_rate_hz) : 0;
    // A frame a little early (capture jitter) still goes, as in the live view.
    const auto due = [&](Ros2Channel channel) {
        if (!wanted(channel) || now_ns - last_sent_ns[channel] < interval_ns - interval_ns / 5)
            return false;
        last_sent_ns[channel] = now_ns;
        return true;
    };
    const dds_entity_t* w = writers_->writer.data();
    const Time stamp = Time::fromNs(work.stamp_realtime_ns);

    if (!work.left.empty() && due(kImageChannel)) {
        sensor_msgs_msg_dds__Image_ image{};
        fillImage(image, stamp, kLeftOpticalFrame, work.left, work.left_encoding,
                  static_cast<uint32_t>(work.left.cols * work.left.elemSize()), work.left.data);
        countWrite(dds_write(w[kImageChannel], &image));
    }
    if (!work.depth_m.empty() && due(kDepthChannel)) {
        std::vector<float>& depth = scratch.depth;
        depthWithNan(work.depth_m, depth);
        sensor_msgs_msg_dds__Image_ image{};
        fillImage(image, stamp, kLeftOpticalFrame, work.depth_m, "32FC1",
                  static_cast<uint32_t>(work.depth_m.cols * 4), depth.data());
        countWrite(dds_write(w[kDepthChannel], &image));
    }
    if (!work.disparity.empty() && due(kDisparityChannel)) {
        std::vector<float>& values = scratch.disparity;
        disparityForRos(work.disparity, work.min_disparity, values);
        stereo_msgs_msg_dds__DisparityImage_ disparity{};
        fillHeader(disparity.header, stamp, kLeftOpticalFrame);
        fillImage(disparity.image, stamp, kLeftOpticalFrame, work.disparity, "32FC1",
                  static_cast<uint32_t>(work.disparity.cols * 4), values.data());
        disparity.f = static_cast<float>(work.geometry.focal_px);
        disparity.t = static_cast<float>(work.geometry.baseline_m);
        disparity.valid_window = {0, 0, disparity.image.height, disparity.image.width, false};
        disparity.min_disparity = work.min_disparity;
        disparity.max_disparity = work.max_disparity;
        disparity.delta_d = 1.0f / 16.0f; // the matchers' sub-pixel step
        countWrite(dds_write(w[kDisparityChannel], &disparity));
    }
    if (work.points_taken && due(kPointsChannel)) {
        static_assert(sizeof(CloudPoint) == 4 * sizeof(float));
        // With colours, a fifth field `rgb` (PCL's packed float); the points interleaved.
        const bool coloured =
            work.points_in_colour && work.cloud_colour.size() == work.cloud.size();
        std::array<sensor_msgs_msg_dds__PointField_, 5> fields = {{
            {borrow("x"), 0, PointField::FLOAT32, 1},
            {borrow("y"), 4, PointField::FLOAT32, 1},
            {borrow("z"), 8, PointField::FLOAT32, 1},
            {borrow("intensity"), 12, PointField::FLOAT32, 1},
            {borrow("rgb"), 16, PointField::FLOAT32, 1},
        }};
        const uint32_t field_count = coloured ? 5 : 4;
        const uint32_t point_step = coloured ? 5 * sizeof(float) : sizeof(CloudPoint);
        const void* data = work.cloud.data();
        if (coloured) {
            xyziRgbCloud(work.cloud, work.cloud_colour, scratch.cloud_rgb);
            data = scratch.cloud_rgb.data();
        }
        sensor_msgs_msg_dds__PointCloud2_ cloud{};
        fillHeader(cloud.header, stamp, kLeftOpticalFrame);
        cloud.height = 1;
        cloud.width = static_cast<uint32_t>(work.cloud.size());
        cloud.fields = {field_count, field_count, fields.data(), false};
        cloud.is_bigendian = false;
        cloud.point_step = point_step;
        cloud.row_step = static_cast<uint32_t>(point_step * work.cloud.size());
        cloud.data = borrowBytes(data, point_step * work.cloud.size());
        cloud.is_dense = true;
        countWrite(dds_write(w[kPointsChannel], &cloud));
    }
    for (const bool right : {false, true}) {
        const Ros2Channel channel = right ? kRightInfoChannel : kLeftInfoChannel;
        if (!due(channel))
            continue;
        const CameraInfo info = rectifiedCameraInfo(work.geometry, right, 0);
        sensor_msgs_msg_dds__CameraInfo_ out{};
        fillHeader(out.header, stamp, right ? kRightOpticalFrame : kLeftOpticalFrame);
        out.height = info.height;
        out.width = info.width;
        out.distortion_model = borrow(info.distortion_model);
        out.d = {static_cast<uint32_t>(info.d.size()), static_cast<uint32_t>(info.d.size()),
                 const_cast<double*>(info.d.data()), false};
        std::copy(info.k.begin(), info.k.end(), out.k);
        std::copy(info.r.begin(), info.r.end(), out.r);
        std::copy(info.p.begin(), info.p.end(), out.p);
        out.binning_x = info.binning_x;
        out.binning_y = info.binning_y;
        out.roi = {info.roi.x_offset, info.roi.y_offset, info.roi.height, info.roi.width,
                   info.roi.do_rectify};
        countWrite(dds_write(w[channel], &out));
    }
    // The reading goes out with every frame: it is small, and it is what a robot acts on.
    const RangeValues values = rangeFromReading(work.reading, work.nearest, work.geometry);
    writeRange(values, stamp);
    publishReadingJson(work.reading_json);

    bool frames_changed = false;
    {
        std::lock_guard lock(mutex_);
        frames_changed = work.pose.translation_m != pose_.translation_m ||
                         work.pose.rpy_deg != pose_.rpy_deg ||
                         work.geometry.baseline_m != tf_baseline_m_;
    }
    if (frames_changed)
        publishStaticFrames(work.pose, work.geometry.baseline_m);
    frames_.fetch_add(1, std::memory_order_relaxed);
}

void Ros2Publisher::publishStaticFrames(const CameraPose& pose, double baseline_m)
{
    {
        std::lock_guard lock(mutex_);
        pose_ = pose;
        tf_baseline_m_ = baseline_m;
    }
    const std::array<FrameTransform, 3> frames = cameraFrames(pose, baseline_m);
    const Time stamp = Time::fromNs(saturatingAddNs(monotonicNowNs(), realtimeOffsetNs()));
    std::array<geometry_msgs_msg_dds__TransformStamped_, 3> transforms{};
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const FrameTransform& f = frames[i];
        geometry_msgs_msg_dds__TransformStamped_& t = transforms[i];
        fillHeader(t.header, stamp, f.parent.c_str());
        t.child_frame_id = borrow(f.child);
        t.transform.translation = {f.translation_m[0], f.translation_m[1], f.translation_m[2]};
        t.transform.rotation = {f.rotation_xyzw[0], f.rotation_xyzw[1], f.rotation_xyzw[2],
                                f.rotation_xyzw[3]};
    }
    tf2_msgs_msg_dds__TFMessage_ message{};
    message.transforms = {3, 3, transforms.data(), false};
    countWrite(dds_write(writers_->writer[kTfStaticChannel], &message));
}

} // namespace stereod::ros2
