// A ROS 2 subscriber built from eProsima Fast DDS (ROS 2's default middleware), with types
// that fastddsgen compiled from ros2/idl/ros2_dds_types.idl: nothing of stereod's DDS code.
// It joins the domain on the loopback interface, subscribes to every topic stereod
// publishes with ROS 2's names, types and QoS, and prints what it received as one JSON
// object on stdout: per topic the matches, the writers' GUIDs, the count and the age of
// the samples when taken (median, p99, max: wall time minus the header's stamp), and
// the decoded content of the last message of each (depth values in full); the ROS 2
// graph's ros_discovery_info (every sample: one per announcing participant); and the GUIDs
// of the readers discovery found in the domain, by topic, to hold the announced reader
// GIDs to.
//
//   fastdds_subscriber DOMAIN NAMESPACE SECONDS MIN_EACH
//
// Ends when every topic has MIN_EACH messages (tf_static: one) or after SECONDS.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <nlohmann/json.hpp>

#include "ros2_dds_types.h"
#include "ros2_dds_typesPubSubTypes.h"
#include "tests/ros2/fastdds_loopback.hpp"

namespace {

using namespace eprosima::fastdds::dds;
using Json = nlohmann::ordered_json;

Json headerJson(const std_msgs::msg::dds_::Header_& header)
{
    return {{"stamp_ns", int64_t{header.stamp().sec()} * 1'000'000'000 + header.stamp().nanosec()},
            {"frame_id", header.frame_id()}};
}

// A float for JSON: NaN and the infinities by name.
Json number(float value)
{
    if (std::isnan(value))
        return "nan";
    if (std::isinf(value))
        return value > 0 ? "inf" : "-inf";
    return value;
}

Json imageJson(const sensor_msgs::msg::dds_::Image_& image, bool with_floats)
{
    Json out = {{"header", headerJson(image.header())},
                {"height", image.height()},
                {"width", image.width()},
                {"encoding", image.encoding()},
                {"step", image.step()},
                {"bytes", image.data().size()}};
    if (with_floats && image.data().size() % 4 == 0) {
        Json values = Json::array();
        const auto* f = reinterpret_cast<const float*>(image.data().data());
        for (std::size_t i = 0; i < image.data().size() / 4; ++i)
            values.push_back(std::isnan(f[i]) ? Json(nullptr) : Json(f[i]));
        out["data"] = std::move(values);
    }
    return out;
}

Json cameraInfoJson(const sensor_msgs::msg::dds_::CameraInfo_& info)
{
    return {{"header", headerJson(info.header())},
            {"height", info.height()},
            {"width", info.width()},
            {"distortion_model", info.distortion_model()},
            {"d", info.d()},
            {"k", info.k()},
            {"r", info.r()},
            {"p", info.p()}};
}

// A GID or GUID as 32 hex digits.
std::string hex(const uint8_t* bytes, std::size_t size)
{
    std::string out;
    char digits[3];
    for (std::size_t i = 0; i < size; ++i) {
        std::snprintf(digits, sizeof digits, "%02x", bytes[i]);
        out += digits;
    }
    return out;
}

Json gidsJson(const std::vector<rmw_dds_common::msg::dds_::Gid_>& gids)
{
    Json out = Json::array();
    for (const auto& gid : gids)
        out.push_back(hex(gid.data().data(), gid.data().size()));
    return out;
}

struct Subscription;
// One sample into the subscription (`last`, `writers`, `ages_ms`); false: none.
using Take = std::function<bool(DataReader*, Subscription&)>;

struct Subscription {
    std::string name; // DDS topic
    std::string type;
    int min_count = 1;
    DataReader* reader = nullptr;
    int count = 0;
    Json last;
    // The GUIDs of the writers samples came from (Fast DDS's handle of a remote writer is
    // its GUID), to hold the node's announced GIDs to.
    std::set<std::string> writers;
    // Wall time at take minus the header's stamp of each sample, ms: the age on delivery.
    std::vector<double> ages_ms;
    Take take;
};

int64_t wallNowNs()
{
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
}

template <typename Message>
Take taker(std::function<Json(const Message&)> decode, bool keep_all = false)
{
    return [decode, keep_all](DataReader* reader, Subscription& s) {
        Message message;
        SampleInfo info;
        if (reader->take_next_sample(&message, &info) != ReturnCode_t::RETCODE_OK)
            return false;
        if (!info.valid_data)
            return true;
        const int64_t now_ns = wallNowNs();
        s.writers.insert(hex(info.publication_handle.value, 16));
        Json decoded = decode(message);
        if (decoded.is_object() && decoded.contains("header"))
            s.ages_ms.push_back(
                static_cast<double>(now_ns - decoded["header"]["stamp_ns"].get<int64_t>()) / 1e6);
        if (keep_all) {
            if (!s.last.is_array())
                s.last = Json::array();
            s.last.push_back(std::move(decoded));
        } else {
            s.last = std::move(decoded);
        }
        return true;
    };
}

// Median, 99th percentile and maximum of `values`.
Json summary(std::vector<double> values)
{
    if (values.empty())
        return nullptr;
    std::sort(values.begin(), values.end());
    const auto at = [&values](double q) {
        return values[static_cast<std::size_t>(q * static_cast<double>(values.size() - 1))];
    };
    return {{"count", values.size()}, {"p50", at(0.5)}, {"p99", at(0.99)}, {"max", values.back()}};
}

// The readers discovery finds, by DDS topic: their GUIDs (Fast DDS's discovery thread).
class DiscoveredReaders final : public DomainParticipantListener {
  public:
    void on_subscriber_discovery(DomainParticipant* /*participant*/,
                                 eprosima::fastrtps::rtps::ReaderDiscoveryInfo&& info) override
    {
        if (info.status != eprosima::fastrtps::rtps::ReaderDiscoveryInfo::DISCOVERED_READER)
            return;
        const auto& guid = info.info.guid();
        std::string text = hex(guid.guidPrefix.value, 12) + hex(guid.entityId.value, 4);
        const std::lock_guard lock(mutex_);
        readers_[info.info.topicName().to_string()].insert(std::move(text));
    }

    Json json() const
    {
        const std::lock_guard lock(mutex_);
        Json out = Json::object();
        for (const auto& [topic, guids] : readers_)
            out[topic] = guids;
        return out;
    }

  private:
    mutable std::mutex mutex_;
    std::map<std::string, std::set<std::string>> readers_;
};

} // namespace

// Debian's Fast DDS 2.9 deletes a reader through a base of another size when the
// participant is torn down (AddressSanitizer: new-delete-type-mismatch inside
// libfastrtps's RTPSReader destructor). The peer's library is not ours to fix; the
// check stays on for everything of ours, in stereod and in this test's own code.
extern "C" const char* __asan_default_options();
extern "C" const char* __asan_default_options()
{
    return "new_delete_type_mismatch=0";
}

int main(int argc, char** argv)
{
    if (argc != 5) {
        std::fprintf(stderr, "usage: fastdds_subscriber DOMAIN NAMESPACE SECONDS MIN_EACH\n");
        return 2;
    }
    const int domain = std::atoi(argv[1]);
    const std::string ns = argv[2];
    const double seconds = std::atof(argv[3]);
    const int min_each = std::atoi(argv[4]);

    const DomainParticipantQos participant_qos =
        stereod::test::loopbackParticipantQos("fastdds_interop_subscriber");
    DiscoveredReaders discovered;
    DomainParticipant* participant = DomainParticipantFactory::get_instance()->create_participant(
        domain, participant_qos, &discovered, StatusMask::none());
    if (participant == nullptr) {
        std::fprintf(stderr, "fastdds_subscriber: cannot create a participant in domain %d\n",
                     domain);
        return 1;
    }
    Subscriber* subscriber = participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);

    using namespace sensor_msgs::msg::dds_;
    const std::string rt = "rt" + ns + "/";
    std::vector<Subscription> topics;
    const auto add = [&topics](std::string name, std::string type, int min_count, Take take) {
        Subscription s;
        s.name = std::move(name);
        s.type = std::move(type);
        s.min_count = min_count;
        s.take = std::move(take);
        topics.push_back(std::move(s));
    };
    add(rt + "left/image_rect", "sensor_msgs::msg::dds_::Image_", min_each,
        taker<Image_>([](const Image_& m) { return imageJson(m, false); }));
    add(rt + "depth", "sensor_msgs::msg::dds_::Image_", min_each,
        taker<Image_>([](const Image_& m) { return imageJson(m, true); }));
    add(rt + "disparity", "stereo_msgs::msg::dds_::DisparityImage_", min_each,
        taker<stereo_msgs::msg::dds_::DisparityImage_>(
            [](const stereo_msgs::msg::dds_::DisparityImage_& m) {
                return Json{{"header", headerJson(m.header())},
                            {"image", imageJson(m.image(), false)},
                            {"f", m.f()},
                            {"t", m.t()},
                            {"min_disparity", m.min_disparity()},
                            {"max_disparity", m.max_disparity()},
                            {"delta_d", m.delta_d()}};
            }));
    add(rt + "points", "sensor_msgs::msg::dds_::PointCloud2_", min_each,
        taker<PointCloud2_>([](const PointCloud2_& m) {
            Json fields = Json::array();
            for (const auto& f : m.fields())
                fields.push_back({{"name", f.name()},
                                  {"offset", f.offset()},
                                  {"datatype", f.datatype()},
                                  {"count", f.count()}});
            return Json{{"header", headerJson(m.header())},
                        {"height", m.height()},
                        {"width", m.width()},
                        {"fields", fields},
                        {"point_step", m.point_step()},
                        {"row_step", m.row_step()},
                        {"bytes", m.data().size()},
                        {"is_dense", m.is_dense()}};
        }));
    add(rt + "left/camera_info", "sensor_msgs::msg::dds_::CameraInfo_", min_each,
        taker<CameraInfo_>(cameraInfoJson));
    add(rt + "right/camera_info", "sensor_msgs::msg::dds_::CameraInfo_", min_each,
        taker<CameraInfo_>(cameraInfoJson));
    add(rt + "nearest", "sensor_msgs::msg::dds_::Range_", min_each,
        taker<Range_>(
            [](const Range_& m) {
                return Json{{"header", headerJson(m.header())},
                            {"radiation_type", m.radiation_type()},
                            {"field_of_view", number(m.field_of_view())},
                            {"min_range", number(m.min_range())},
                            {"max_range", number(m.max_range())},
                            {"range", number(m.range())}};
            },
            true));
    add(rt + "reading", "std_msgs::msg::dds_::String_", min_each,
        taker<std_msgs::msg::dds_::String_>(
            [](const std_msgs::msg::dds_::String_& m) { return Json(m.data()); }, true));
    add("rt/tf_static", "tf2_msgs::msg::dds_::TFMessage_", 1,
        taker<tf2_msgs::msg::dds_::TFMessage_>([](const tf2_msgs::msg::dds_::TFMessage_& m) {
            Json transforms = Json::array();
            for (const auto& t : m.transforms()) {
                const auto& tr = t.transform().translation();
                const auto& q = t.transform().rotation();
                transforms.push_back({{"parent", t.header().frame_id()},
                                      {"child", t.child_frame_id()},
                                      {"translation", {tr.x(), tr.y(), tr.z()}},
                                      {"rotation", {q.x(), q.y(), q.z(), q.w()}}});
            }
            return transforms;
        }));
    // The ROS 2 graph: the nodes a participant holds (rmw's QoS: reliable, transient local).
    add("ros_discovery_info", "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_", 1,
        taker<rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_>(
            [](const rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_& m) {
                Json nodes = Json::array();
                for (const auto& node : m.node_entities_info_seq())
                    nodes.push_back({{"namespace", node.node_namespace()},
                                     {"name", node.node_name()},
                                     {"readers", gidsJson(node.reader_gid_seq())},
                                     {"writers", gidsJson(node.writer_gid_seq())}});
                return Json{{"gid", hex(m.gid().data().data(), m.gid().data().size())},
                            {"nodes", nodes}};
            },
            true));
    std::vector<TypeSupport> types = {
        TypeSupport(new rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_PubSubType()),
        TypeSupport(new Image_PubSubType()),
        TypeSupport(new stereo_msgs::msg::dds_::DisparityImage_PubSubType()),
        TypeSupport(new PointCloud2_PubSubType()),
        TypeSupport(new CameraInfo_PubSubType()),
        TypeSupport(new Range_PubSubType()),
        TypeSupport(new std_msgs::msg::dds_::String_PubSubType()),
        TypeSupport(new tf2_msgs::msg::dds_::TFMessage_PubSubType()),
    };
    for (TypeSupport& type : types)
        type.register_type(participant);

    for (std::size_t i = 0; i < topics.size(); ++i) {
        Subscription& t = topics[i];
        eprosima::fastdds::dds::Topic* topic =
            participant->create_topic(t.name, t.type, TOPIC_QOS_DEFAULT);
        DataReaderQos qos = DATAREADER_QOS_DEFAULT;
        // ROS 2's profiles: sensor data for the images and the cloud, reliable for the
        // rest, transient local for /tf_static (tf2's static listener).
        const bool sensor = i < 4;
        qos.reliability().kind = sensor ? BEST_EFFORT_RELIABILITY_QOS : RELIABLE_RELIABILITY_QOS;
        const bool latched = t.name == "rt/tf_static" || t.name == "ros_discovery_info";
        qos.durability().kind = latched ? TRANSIENT_LOCAL_DURABILITY_QOS : VOLATILE_DURABILITY_QOS;
        qos.history().kind = KEEP_LAST_HISTORY_QOS;
        qos.history().depth = sensor ? 5 : 10;
        qos.endpoint().history_memory_policy =
            eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
        t.reader = subscriber->create_datareader(topic, qos);
        if (t.reader == nullptr) {
            std::fprintf(stderr, "fastdds_subscriber: no reader for %s\n", t.name.c_str());
            return 1;
        }
    }

    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
    Json result = {{"topics", Json::object()}};
    std::vector<int> matched(topics.size(), 0);
    while (std::chrono::steady_clock::now() < deadline) {
        bool all = true;
        for (std::size_t i = 0; i < topics.size(); ++i) {
            Subscription& t = topics[i];
            SubscriptionMatchedStatus status;
            t.reader->get_subscription_matched_status(status);
            matched[i] = std::max(matched[i], status.current_count);
            while (t.take(t.reader, t))
                ++t.count;
            all = all && t.count >= t.min_count;
        }
        if (all)
            break;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    for (std::size_t i = 0; i < topics.size(); ++i) {
        const Subscription& t = topics[i];
        result["topics"][t.name] = {{"type", t.type},       {"matched", matched[i]},
                                    {"count", t.count},     {"last", t.last},
                                    {"writers", t.writers}, {"age_ms", summary(t.ages_ms)}};
    }
    result["discovered_readers"] = discovered.json();
    std::cout << result.dump() << "\n";
    participant->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(participant);
    return 0;
}
