// A ROS 2 stereo camera driver as far as DDS can tell, built from eProsima Fast DDS with
// fastddsgen's types (nothing of stereod's DDS code): it publishes one image pair again and
// again on two sensor_msgs/msg/Image topics, both images of a pair with one header stamp
// (the wall clock, as ROS 2 drivers stamp), on the loopback interface. The ROS 2 source's
// tests (tests/ros2/ros2_source_test.cpp) feed stereod from it.
//
//   fastdds_image_publisher DOMAIN SECONDS LEFT_IMAGE RIGHT_IMAGE [options]
//     --encoding E                how the pixels go out: mono8 (the files read as grey),
//                                 bgr8, rgb8, or yuv422 / yuv422_yuy2 (UYVY / YUYV of the
//                                 grey: the files' grey as luma, no chroma)
//     --rate HZ                   pairs a second (10)
//     --right-offset-ms MS        the right image's stamp this much after the left's (0)
//     --bad-every N               every N-th left image declares a step shorter than its
//                                 row (a malformed message); 0: none
//     --reliable                  a reliable writer instead of sensor data's best effort
//     --width PX                  the images cut to their PX left columns (an odd width)
//     --topics LEFT RIGHT         ROS 2 topics (/stereo/left/image_raw /stereo/right/image_raw)
//     --camera-info LEFT RIGHT    also sensor_msgs/msg/CameraInfo beside each image topic
//                                 (.../camera_info), with each image's stamp, from ROS
//                                 camera_info YAML files (as camera_info_manager loads them)
//
// Prints one JSON line when it ends: the pairs published and the readers matched.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <yaml-cpp/yaml.h>

#include "ros2_dds_types.h"
#include "ros2_dds_typesPubSubTypes.h"
#include "tests/ros2/fastdds_loopback.hpp"

namespace {

using namespace eprosima::fastdds::dds;
using sensor_msgs::msg::dds_::CameraInfo_;
using sensor_msgs::msg::dds_::Image_;

struct Options {
    int domain = 0;
    double seconds = 0;
    std::string left_path, right_path;
    std::string encoding = "mono8";
    double rate_hz = 10;
    double right_offset_ms = 0;
    int bad_every = 0;
    int width = 0; // 0: the files' own
    bool reliable = false;
    std::string left_topic = "/stereo/left/image_raw";
    std::string right_topic = "/stereo/right/image_raw";
    std::string left_info_path, right_info_path; // empty: no camera_info
};

bool parse(int argc, char** argv, Options& o)
{
    if (argc < 5)
        return false;
    o.domain = std::atoi(argv[1]);
    o.seconds = std::atof(argv[2]);
    o.left_path = argv[3];
    o.right_path = argv[4];
    for (int i = 5; i < argc; ++i) {
        const std::string arg = argv[i];
        const bool has_value = i + 1 < argc;
        if (arg == "--encoding" && has_value)
            o.encoding = argv[++i];
        else if (arg == "--rate" && has_value)
            o.rate_hz = std::atof(argv[++i]);
        else if (arg == "--right-offset-ms" && has_value)
            o.right_offset_ms = std::atof(argv[++i]);
        else if (arg == "--bad-every" && has_value)
            o.bad_every = std::atoi(argv[++i]);
        else if (arg == "--width" && has_value)
            o.width = std::atoi(argv[++i]);
        else if (arg == "--reliable")
            o.reliable = true;
        else if (arg == "--topics" && i + 2 < argc) {
            o.left_topic = argv[++i];
            o.right_topic = argv[++i];
        } else if (arg == "--camera-info" && i + 2 < argc) {
            o.left_info_path = argv[++i];
            o.right_info_path = argv[++i];
        } else
            return false;
    }
    return o.encoding == "mono8" || o.encoding == "bgr8" || o.encoding == "rgb8" ||
           o.encoding == "yuv422" || o.encoding == "yuv422_yuy2";
}

bool isYuv(const std::string& encoding)
{
    return encoding == "yuv422" || encoding == "yuv422_yuy2";
}

// The image as the message carries it, with its encoding's channels.
cv::Mat loadImage(const std::string& path, const std::string& encoding)
{
    if (encoding == "mono8")
        return cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (isYuv(encoding)) {
        // Two bytes a pixel: the grey as luma beside a neutral chroma (128), UYVY for
        // yuv422, YUYV for yuv422_yuy2.
        const cv::Mat grey = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (grey.empty())
            return grey;
        cv::Mat chroma(grey.size(), CV_8UC1, cv::Scalar(128));
        cv::Mat yuv;
        if (encoding == "yuv422")
            cv::merge(std::vector<cv::Mat>{chroma, grey}, yuv);
        else
            cv::merge(std::vector<cv::Mat>{grey, chroma}, yuv);
        return yuv;
    }
    cv::Mat bgr = cv::imread(path, cv::IMREAD_COLOR);
    if (encoding == "rgb8" && !bgr.empty())
        cv::cvtColor(bgr, bgr, cv::COLOR_BGR2RGB);
    return bgr;
}

Image_ imageMessage(const cv::Mat& pixels, const std::string& encoding)
{
    Image_ message;
    message.header().frame_id("stereo_camera_optical_frame");
    message.height(static_cast<uint32_t>(pixels.rows));
    message.width(static_cast<uint32_t>(pixels.cols));
    message.encoding(encoding);
    message.is_bigendian(0);
    const auto row = static_cast<uint32_t>(pixels.cols * pixels.channels());
    message.step(row);
    std::vector<uint8_t> data(static_cast<std::size_t>(row) *
                              static_cast<std::size_t>(pixels.rows));
    for (int y = 0; y < pixels.rows; ++y)
        std::copy_n(pixels.ptr<uint8_t>(y), row,
                    data.begin() + static_cast<std::ptrdiff_t>(y) * row);
    message.data(std::move(data));
    return message;
}

template <class Message> void stamp(Message& message, int64_t ns)
{
    message.header().stamp().sec(static_cast<int32_t>(ns / 1'000'000'000));
    message.header().stamp().nanosec(static_cast<uint32_t>(ns % 1'000'000'000));
}

// A ROS camera_info YAML file (image_width, camera_matrix.data, ...) as the message;
// throws YAML::Exception when a key is missing.
CameraInfo_ cameraInfoMessage(const std::string& path)
{
    const YAML::Node root = YAML::LoadFile(path);
    CameraInfo_ message;
    message.header().frame_id("stereo_camera_optical_frame");
    message.width(root["image_width"].as<uint32_t>());
    message.height(root["image_height"].as<uint32_t>());
    message.distortion_model(root["distortion_model"].as<std::string>());
    message.d(root["distortion_coefficients"]["data"].as<std::vector<double>>());
    const auto fill = [&root](const char* key, double* out, std::size_t count) {
        const auto values = root[key]["data"].as<std::vector<double>>();
        for (std::size_t i = 0; i < count && i < values.size(); ++i)
            out[i] = values[i];
    };
    fill("camera_matrix", message.k().data(), 9);
    fill("rectification_matrix", message.r().data(), 9);
    fill("projection_matrix", message.p().data(), 12);
    return message;
}

// `/a/b/image_raw` -> `/a/b/camera_info`, as drivers place them.
std::string infoTopicBeside(const std::string& image_topic)
{
    return image_topic.substr(0, image_topic.rfind('/') + 1) + "camera_info";
}

} // namespace

// Debian's Fast DDS 2.9 deletes an endpoint through a base of another size at teardown
// (tests/ros2/fastdds_subscriber.cpp says more): not ours to fix.
extern "C" const char* __asan_default_options();
extern "C" const char* __asan_default_options()
{
    return "new_delete_type_mismatch=0";
}

int main(int argc, char** argv)
{
    Options o;
    if (!parse(argc, argv, o)) {
        std::fprintf(stderr, "usage: fastdds_image_publisher DOMAIN SECONDS LEFT_IMAGE RIGHT_IMAGE "
                             "[--encoding mono8|bgr8|rgb8|yuv422|yuv422_yuy2] [--rate HZ] "
                             "[--right-offset-ms MS] [--bad-every N] [--width PX] [--reliable] "
                             "[--topics LEFT RIGHT] [--camera-info LEFT.yaml RIGHT.yaml]\n");
        return 2;
    }
    cv::Mat left = loadImage(o.left_path, o.encoding);
    cv::Mat right = loadImage(o.right_path, o.encoding);
    if (o.width > 0 && o.width < left.cols && o.width < right.cols) {
        left = left.colRange(0, o.width);
        right = right.colRange(0, o.width);
    }
    if (left.empty() || right.empty()) {
        std::fprintf(stderr, "fastdds_image_publisher: cannot read %s or %s\n", o.left_path.c_str(),
                     o.right_path.c_str());
        return 1;
    }

    const DomainParticipantQos participant_qos =
        stereod::test::loopbackParticipantQos("fastdds_image_publisher");
    DomainParticipant* participant =
        DomainParticipantFactory::get_instance()->create_participant(o.domain, participant_qos);
    if (participant == nullptr) {
        std::fprintf(stderr, "fastdds_image_publisher: no participant in domain %d\n", o.domain);
        return 1;
    }
    TypeSupport type(new sensor_msgs::msg::dds_::Image_PubSubType());
    type.register_type(participant);
    Publisher* publisher = participant->create_publisher(PUBLISHER_QOS_DEFAULT);
    DataWriterQos qos = DATAWRITER_QOS_DEFAULT;
    // A camera driver's sensor data: best effort, keep last 5, volatile (or reliable).
    qos.reliability().kind = o.reliable ? RELIABLE_RELIABILITY_QOS : BEST_EFFORT_RELIABILITY_QOS;
    qos.durability().kind = VOLATILE_DURABILITY_QOS;
    qos.history().kind = KEEP_LAST_HISTORY_QOS;
    qos.history().depth = 5;
    qos.endpoint().history_memory_policy =
        eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    // Images are larger than a datagram: fragments go out from Fast DDS's own thread.
    qos.publish_mode().kind = ASYNCHRONOUS_PUBLISH_MODE;
    DataWriter* writers[2] = {};
    const std::string topics[2] = {o.left_topic, o.right_topic};
    for (int side = 0; side < 2; ++side) {
        Topic* topic =
            participant->create_topic("rt" + topics[side], type.get_type_name(), TOPIC_QOS_DEFAULT);
        writers[side] = topic == nullptr ? nullptr : publisher->create_datawriter(topic, qos);
        if (writers[side] == nullptr) {
            std::fprintf(stderr, "fastdds_image_publisher: no writer for %s\n",
                         topics[side].c_str());
            return 1;
        }
    }

    // The drivers' camera_info, on the same QoS as their images.
    DataWriter* info_writers[2] = {};
    CameraInfo_ infos[2];
    if (!o.left_info_path.empty()) {
        try {
            infos[0] = cameraInfoMessage(o.left_info_path);
            infos[1] = cameraInfoMessage(o.right_info_path);
        } catch (const YAML::Exception& e) {
            std::fprintf(stderr, "fastdds_image_publisher: camera_info: %s\n", e.what());
            return 1;
        }
        TypeSupport info_type(new sensor_msgs::msg::dds_::CameraInfo_PubSubType());
        info_type.register_type(participant);
        for (int side = 0; side < 2; ++side) {
            Topic* topic = participant->create_topic("rt" + infoTopicBeside(topics[side]),
                                                     info_type.get_type_name(), TOPIC_QOS_DEFAULT);
            info_writers[side] =
                topic == nullptr ? nullptr : publisher->create_datawriter(topic, qos);
            if (info_writers[side] == nullptr) {
                std::fprintf(stderr, "fastdds_image_publisher: no camera_info writer\n");
                return 1;
            }
        }
    }

    Image_ messages[2] = {imageMessage(left, o.encoding), imageMessage(right, o.encoding)};
    Image_ bad = messages[0];
    bad.step(bad.width() / 2); // shorter than a row of the image
    const auto period = std::chrono::nanoseconds(static_cast<int64_t>(1e9 / o.rate_hz));
    const auto start = std::chrono::steady_clock::now();
    const auto end = start + std::chrono::milliseconds(static_cast<int64_t>(o.seconds * 1000));
    int64_t pairs = 0;
    int matched = 0;
    for (auto next = start; next < end; next += period) {
        std::this_thread::sleep_until(next);
        const int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                   std::chrono::system_clock::now().time_since_epoch())
                                   .count();
        const bool malformed = o.bad_every > 0 && pairs % o.bad_every == o.bad_every - 1;
        Image_& left_message = malformed ? bad : messages[0];
        stamp(left_message, now_ns);
        stamp(messages[1], now_ns + static_cast<int64_t>(o.right_offset_ms * 1e6));
        writers[0]->write(&left_message);
        writers[1]->write(&messages[1]);
        for (int side = 0; side < 2 && info_writers[0] != nullptr; ++side) {
            stamp(infos[side],
                  side == 0 ? now_ns : now_ns + static_cast<int64_t>(o.right_offset_ms * 1e6));
            info_writers[side]->write(&infos[side]);
        }
        ++pairs;
        PublicationMatchedStatus status;
        writers[0]->get_publication_matched_status(status);
        matched = std::max(matched, status.current_count);
    }
    std::cout << "{\"pairs\": " << pairs << ", \"matched\": " << matched << "}" << std::endl;
    participant->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(participant);
    return 0;
}
