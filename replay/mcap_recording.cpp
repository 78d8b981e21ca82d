#include "replay/mcap_recording.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <map>

#include <fcntl.h>
#include <unistd.h>

#include "base/unique_fd.hpp"
#include "replay/image_message.hpp"
#include "ros2/topic_names.hpp"

namespace stereod {

namespace {

// The QoS rosbag2 records for a sensor stream (reliable, volatile, keep last): the
// `ros2` profile requires the key; `ros2 bag play` uses it to publish.
constexpr const char* kOfferedQos = "- history: 1\n"
                                    "  depth: 10\n"
                                    "  reliability: 1\n"
                                    "  durability: 2\n"
                                    "  deadline:\n"
                                    "    sec: 9223372036\n"
                                    "    nsec: 854775807\n"
                                    "  lifespan:\n"
                                    "    sec: 9223372036\n"
                                    "    nsec: 854775807\n"
                                    "  liveliness: 1\n"
                                    "  liveliness_lease_duration:\n"
                                    "    sec: 9223372036\n"
                                    "    nsec: 854775807\n"
                                    "  avoid_ros_namespace_conventions: false\n";

using ros2::kLeftOpticalFrame;
using ros2::kRightOpticalFrame;

std::string lower(std::string s)
{
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return s;
}

} // namespace

bool isMcapFile(const std::string& path)
{
    const UniqueFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    if (!fd) {
        return false;
    }
    uint8_t start[mcap::kMagicSize] = {};
    const ssize_t n = ::pread(fd.get(), start, sizeof start, 0);
    return n == static_cast<ssize_t>(sizeof start) &&
           std::memcmp(start, mcap::kMagic, sizeof start) == 0;
}

mcap::WriterOptions McapRecordingWriter::defaultOptions()
{
    mcap::WriterOptions o;
    o.profile = "ros2";
    o.library = "stereod";
    return o;
}

McapRecordingWriter::McapRecordingWriter(const std::string& path, mcap::WriterOptions options)
    : writer_(path, std::move(options))
{
    const std::map<std::string, std::string> metadata = {{"offered_qos_profiles", kOfferedQos}};
    image_schema_ = writer_.addSchema(ros2::kImageType, "ros2msg", ros2::imageSchemaText());
    const uint16_t info =
        writer_.addSchema(ros2::kCameraInfoType, "ros2msg", ros2::cameraInfoSchemaText());
    left_channel_ = writer_.addChannel(image_schema_, kMcapLeftImageTopic, "cdr", metadata);
    right_channel_ = writer_.addChannel(image_schema_, kMcapRightImageTopic, "cdr", metadata);
    left_info_channel_ = writer_.addChannel(info, kMcapLeftInfoTopic, "cdr", metadata);
    right_info_channel_ = writer_.addChannel(info, kMcapRightInfoTopic, "cdr", metadata);
}

void McapRecordingWriter::setCameraInfo(const ros2::CameraInfo& left, const ros2::CameraInfo& right)
{
    camera_info_.emplace(left, right);
    camera_info_->first.header.frame_id = kLeftOpticalFrame;
    camera_info_->second.header.frame_id = kRightOpticalFrame;
}

void McapRecordingWriter::writeImage(uint16_t channel, const cv::Mat& image, int64_t stamp_ns,
                                     const char* frame_id)
{
    const auto width = static_cast<uint32_t>(image.cols);
    const auto height = static_cast<uint32_t>(image.rows);
    const ros2::Header header{ros2::Time::fromNs(stamp_ns), frame_id};
    // Grey as mono8, colour as captured: OpenCV's BGR order is ROS's bgr8.
    const char* encoding = image.type() == CV_8UC3 ? "bgr8" : "mono8";
    const auto step = static_cast<uint32_t>(image.cols * image.elemSize());
    const std::size_t bytes = image.total() * image.elemSize();
    if (image.isContinuous()) {
        ros2::serializeImage(header, height, width, encoding, step, image.data, bytes, message_);
    } else {
        const cv::Mat packed = image.clone();
        ros2::serializeImage(header, height, width, encoding, step, packed.data, bytes, message_);
    }
    const auto t = static_cast<uint64_t>(stamp_ns);
    writer_.write(channel, t, t, message_, static_cast<uint32_t>(pairs_));
}

uint64_t McapRecordingWriter::write(const cv::Mat& left, const cv::Mat& right,
                                    int64_t left_stamp_ns, int64_t right_stamp_ns)
{
    const auto eightBit = [](const cv::Mat& image) {
        return image.type() == CV_8UC1 || image.type() == CV_8UC3;
    };
    if (!eightBit(left) || !eightBit(right) || left.size() != right.size() || left.empty()) {
        throw mcap::McapError(writer_.path() + ": a pair must be two 8-bit grey or BGR colour "
                                               "images of one size");
    }
    if (size_.empty()) {
        size_ = left.size();
    } else if (left.size() != size_) {
        throw mcap::McapError(writer_.path() + ": pair of " + std::to_string(left.cols) + "x" +
                              std::to_string(left.rows) + " in a recording of " +
                              std::to_string(size_.width) + "x" + std::to_string(size_.height));
    }
    writeImage(left_channel_, left, left_stamp_ns, kLeftOpticalFrame);
    writeImage(right_channel_, right, right_stamp_ns, kRightOpticalFrame);
    if (camera_info_) {
        camera_info_->first.header.stamp = ros2::Time::fromNs(left_stamp_ns);
        camera_info_->second.header.stamp = ros2::Time::fromNs(right_stamp_ns);
        ros2::serializeCameraInfo(camera_info_->first, message_);
        writer_.write(left_info_channel_, static_cast<uint64_t>(left_stamp_ns),
                      static_cast<uint64_t>(left_stamp_ns), message_,
                      static_cast<uint32_t>(pairs_));
        ros2::serializeCameraInfo(camera_info_->second, message_);
        writer_.write(right_info_channel_, static_cast<uint64_t>(right_stamp_ns),
                      static_cast<uint64_t>(right_stamp_ns), message_,
                      static_cast<uint32_t>(pairs_));
    }
    return pairs_++;
}

void McapRecordingWriter::enableDepth()
{
    if (!depth_channel_) {
        depth_channel_ = writer_.addChannel(image_schema_, kMcapDepthTopic, "cdr",
                                            {{"offered_qos_profiles", kOfferedQos}});
    }
}

void McapRecordingWriter::enablePoints()
{
    if (!points_channel_) {
        const uint16_t schema =
            writer_.addSchema(ros2::kPointCloud2Type, "ros2msg", ros2::pointCloud2SchemaText());
        points_channel_ = writer_.addChannel(schema, kMcapPointsTopic, "cdr",
                                             {{"offered_qos_profiles", kOfferedQos}});
    }
}

void McapRecordingWriter::writeDepth(const cv::Mat& depth_m, int64_t stamp_ns)
{
    if (!depth_channel_) {
        throw mcap::McapError(writer_.path() + ": depth written without enableDepth()", EINVAL);
    }
    if (depth_m.type() != CV_32FC1 || depth_m.empty()) {
        throw mcap::McapError(writer_.path() + ": a depth image must be float32 metres", EINVAL);
    }
    // One pass: a copy with NaN, ROS's "no depth" (REP 118), where the pipeline has 0.
    depth_nan_.create(depth_m.size(), CV_32FC1);
    const float none = std::numeric_limits<float>::quiet_NaN();
    for (int row = 0; row < depth_m.rows; ++row) {
        const float* in = depth_m.ptr<float>(row);
        float* out = depth_nan_.ptr<float>(row);
        for (int col = 0; col < depth_m.cols; ++col) {
            out[col] = in[col] > 0.0f ? in[col] : none;
        }
    }
    const auto width = static_cast<uint32_t>(depth_m.cols);
    const ros2::Header header{ros2::Time::fromNs(stamp_ns), kLeftOpticalFrame};
    ros2::serializeImage(header, static_cast<uint32_t>(depth_m.rows), width, "32FC1",
                         static_cast<uint32_t>(width * sizeof(float)), depth_nan_.data,
                         depth_nan_.total() * sizeof(float), message_);
    const auto t = static_cast<uint64_t>(stamp_ns);
    writer_.write(*depth_channel_, t, t, message_, lastSequence());
}

void McapRecordingWriter::writePoints(const float* xyzi, std::size_t points, int64_t stamp_ns)
{
    writeCloud(xyzi, points, false, stamp_ns);
}

void McapRecordingWriter::writeColouredPoints(const float* xyzirgb, std::size_t points,
                                              int64_t stamp_ns)
{
    writeCloud(xyzirgb, points, true, stamp_ns);
}

void McapRecordingWriter::writeCloud(const float* values, std::size_t points, bool rgb,
                                     int64_t stamp_ns)
{
    if (!points_channel_) {
        throw mcap::McapError(writer_.path() + ": points written without enablePoints()", EINVAL);
    }
    const ros2::Header header{ros2::Time::fromNs(stamp_ns), kLeftOpticalFrame};
    if (rgb)
        ros2::serializeXyziRgbCloud(header, values, points, message_);
    else
        ros2::serializeXyziCloud(header, values, points, message_);
    const auto t = static_cast<uint64_t>(stamp_ns);
    writer_.write(*points_channel_, t, t, message_, lastSequence());
}

McapStereoIndex indexMcapStereo(mcap::Reader& reader, const std::string& left_topic,
                                const std::string& right_topic)
{
    McapStereoIndex index;
    // Image channels by topic; every topic of the bag, for the messages that refuse it.
    std::map<std::string, uint16_t> image_topics;
    std::map<std::string, uint16_t> info_topics;
    std::map<std::string, std::string> all_topics; // topic -> "encoding, schema"
    for (const auto& [id, channel] : reader.channels()) {
        const auto schema = reader.schemas().find(channel.schema_id);
        const std::string schema_name =
            schema == reader.schemas().end() ? "no schema" : schema->second.name;
        all_topics[channel.topic] = channel.message_encoding + ", " + schema_name;
        if (schema == reader.schemas().end() || channel.message_encoding != "cdr") {
            continue;
        }
        if (schema_name == ros2::kImageType || schema_name == "sensor_msgs/Image") {
            image_topics[channel.topic] = id;
        } else if (schema_name == ros2::kCameraInfoType ||
                   schema_name == "sensor_msgs/CameraInfo") {
            info_topics[channel.topic] = id;
        }
    }
    std::string listed;
    for (const auto& [topic, id] : image_topics) {
        listed += (listed.empty() ? "" : ", ") + topic;
    }
    if (listed.empty()) {
        listed = "none";
    }
    auto refuse = [&](const std::string& why) {
        throw mcap::McapError(reader.path() + ": " + why +
                              " (its sensor_msgs/msg/Image topics in CDR: " + listed + ")");
    };
    if (image_topics.empty()) {
        // Nothing to choose from: say what the bag does hold instead.
        std::string topics;
        for (const auto& [topic, what] : all_topics) {
            topics += (topics.empty() ? "" : ", ") + topic + " (" + what + ")";
        }
        throw mcap::McapError(
            reader.path() + ": no topic carries sensor_msgs/msg/Image in CDR; " +
            (topics.empty() ? std::string("the bag has no channel") : "its topics: " + topics));
    }

    if (!left_topic.empty() || !right_topic.empty()) {
        index.left_topic = left_topic.empty() ? kMcapLeftImageTopic : left_topic;
        index.right_topic = right_topic.empty() ? kMcapRightImageTopic : right_topic;
        for (const std::string* t : {&index.left_topic, &index.right_topic}) {
            if (image_topics.count(*t) == 0) {
                const auto other = all_topics.find(*t);
                refuse(other == all_topics.end()
                           ? "no sensor_msgs/msg/Image topic '" + *t + "'"
                           : "topic '" + *t + "' is not sensor_msgs/msg/Image in CDR (it is " +
                                 other->second + ")");
            }
        }
        if (index.left_topic == index.right_topic) {
            refuse("the left and right images are both set to the topic '" + index.left_topic +
                   "'; a stereo pair needs two topics");
        }
    } else if (image_topics.count(kMcapLeftImageTopic) &&
               image_topics.count(kMcapRightImageTopic)) {
        index.left_topic = kMcapLeftImageTopic;
        index.right_topic = kMcapRightImageTopic;
    } else {
        std::vector<std::string> lefts, rights;
        for (const auto& [topic, id] : image_topics) {
            const std::string name = lower(topic);
            const bool l = name.find("left") != std::string::npos;
            const bool r = name.find("right") != std::string::npos;
            if (l && !r) {
                lefts.push_back(topic);
            } else if (r && !l) {
                rights.push_back(topic);
            }
        }
        if (lefts.size() != 1 || rights.size() != 1) {
            refuse("cannot tell which image topics are the left and right cameras; set "
                   "source.replay.topics.left and .right");
        }
        index.left_topic = lefts.front();
        index.right_topic = rights.front();
        index.notes.push_back("image topics chosen by name: left " + index.left_topic + ", right " +
                              index.right_topic);
    }
    const uint16_t left_id = image_topics.at(index.left_topic);
    const uint16_t right_id = image_topics.at(index.right_topic);
    const std::string left_info = ros2::cameraInfoTopicBeside(index.left_topic);
    const std::string right_info = ros2::cameraInfoTopicBeside(index.right_topic);
    const int left_info_id = info_topics.count(left_info) ? info_topics.at(left_info) : -1;
    const int right_info_id = info_topics.count(right_info) ? info_topics.at(right_info) : -1;

    struct Stamped {
        int64_t stamp_ns;
        mcap::MessageRef ref;
        std::size_t order; // position in the file among its topic's messages
    };
    std::vector<Stamped> lefts, rights;
    std::optional<ros2::CameraInfo> info[2];
    // Per side: images whose message does not decode, and the first one's reason.
    uint64_t undecodable[2] = {0, 0};
    std::string first_problem[2];
    uint64_t bad = 0;
    reader.forEachMessage([&](const mcap::MessageView& m, const mcap::MessageRef& ref) {
        try {
            if (m.channel_id == left_id || m.channel_id == right_id) {
                const int side = m.channel_id == left_id ? 0 : 1;
                try {
                    const ros2::ImageView image = ros2::parseImage(m.data);
                    auto& list = side == 0 ? lefts : rights;
                    list.push_back({image.header.stamp.toNs(), ref, list.size()});
                } catch (const ros2::CdrError& e) {
                    if (undecodable[side]++ == 0) {
                        first_problem[side] = e.what();
                    }
                }
            } else if (m.channel_id == left_info_id && !info[0]) {
                info[0] = ros2::parseCameraInfo(m.data);
            } else if (m.channel_id == right_info_id && !info[1]) {
                info[1] = ros2::parseCameraInfo(m.data);
            }
        } catch (const ros2::CdrError&) {
            ++bad;
        }
    });
    for (const std::string& skipped : reader.skippedChunks()) {
        index.problems.push_back(skipped);
    }
    const std::string* topic_of[2] = {&index.left_topic, &index.right_topic};
    for (int side = 0; side < 2; ++side) {
        if (undecodable[side] > 0) {
            index.problems.push_back(
                std::to_string(undecodable[side]) + " images on " + *topic_of[side] +
                " do not decode and were skipped (first: " + first_problem[side] + ")");
        }
    }
    if (bad > 0) {
        index.problems.push_back(std::to_string(bad) +
                                 " camera_info messages that do not decode were skipped");
    }
    if (info[0] && info[1]) {
        index.camera_info.emplace(*info[0], *info[1]);
    }
    auto by_stamp = [](const Stamped& a, const Stamped& b) { return a.stamp_ns < b.stamp_ns; };
    std::stable_sort(lefts.begin(), lefts.end(), by_stamp);
    std::stable_sort(rights.begin(), rights.end(), by_stamp);

    // Tolerance: half the median spacing of the left stream (20 ms when it cannot tell).
    int64_t tolerance_ns = 20'000'000;
    if (lefts.size() >= 2) {
        std::vector<int64_t> gaps;
        for (std::size_t i = 1; i < lefts.size(); ++i) {
            gaps.push_back(lefts[i].stamp_ns - lefts[i - 1].stamp_ns);
        }
        std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2),
                         gaps.end());
        if (gaps[gaps.size() / 2] > 0) {
            tolerance_ns = gaps[gaps.size() / 2] / 2;
        }
    }
    std::size_t j = 0;
    std::vector<bool> used(rights.size(), false);
    std::vector<std::size_t> pair_order;
    for (const Stamped& l : lefts) {
        // The nearest right image; among equally near ones (a recording of a looping
        // replay repeats its stamps) the first not yet used.
        while (j + 1 < rights.size()) {
            const int64_t here = std::llabs(rights[j].stamp_ns - l.stamp_ns);
            const int64_t next = std::llabs(rights[j + 1].stamp_ns - l.stamp_ns);
            if (next < here || (next == here && used[j])) {
                ++j;
            } else {
                break;
            }
        }
        if (j < rights.size() && !used[j] &&
            std::llabs(rights[j].stamp_ns - l.stamp_ns) <= tolerance_ns) {
            used[j] = true;
            index.pairs.push_back({l.ref, rights[j].ref, l.stamp_ns, rights[j].stamp_ns});
            pair_order.push_back(l.order);
        } else {
            ++index.unpaired_left;
        }
    }
    index.unpaired_right = rights.size() - index.pairs.size();
    // Replayed in the order the left images were recorded (a recording of a looping replay
    // repeats its stamps; a camera's only grow).
    std::vector<std::size_t> by_file(index.pairs.size());
    for (std::size_t i = 0; i < by_file.size(); ++i) {
        by_file[i] = i;
    }
    std::sort(by_file.begin(), by_file.end(),
              [&](std::size_t a, std::size_t b) { return pair_order[a] < pair_order[b]; });
    std::vector<McapPair> ordered;
    ordered.reserve(index.pairs.size());
    for (std::size_t i : by_file) {
        ordered.push_back(index.pairs[i]);
    }
    index.pairs = std::move(ordered);
    if (index.pairs.empty()) {
        const auto side_text = [&](int side) {
            const std::size_t readable = side == 0 ? lefts.size() : rights.size();
            std::string text = std::to_string(readable) + " images on " + *topic_of[side];
            if (undecodable[side] > 0) {
                text += " (and " + std::to_string(undecodable[side]) +
                        " that do not decode: " + first_problem[side] + ")";
            }
            return text;
        };
        if (lefts.empty() || rights.empty()) {
            refuse("no stereo pair: " + side_text(0) + " and " + side_text(1));
        }
        refuse("no stereo pair: " + side_text(0) + " and " + side_text(1) +
               " have no stamps within " + std::to_string(tolerance_ns / 1000) +
               " us of each other");
    }
    return index;
}

bool decodeMcapImage(mcap::Reader& reader, const mcap::MessageRef& ref, cv::Mat& out,
                     std::string& reason, cv::Size expected)
{
    return decodeImageMessage(reader.message(ref).data, expected, out, reason);
}

bool decodeMcapImage(mcap::Reader& reader, const mcap::MessageRef& ref, cv::Mat& out,
                     cv::Mat& colour, std::string& reason, cv::Size expected)
{
    return decodeImageMessage(reader.message(ref).data, expected, out, colour, reason);
}

} // namespace stereod
