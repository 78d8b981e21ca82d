#pragma once
// stereod as a ROS 2 node on DDS (Cyclone DDS), without ROS installed: the service's
// results as ROS 2 topics under a namespace (default /stereo), and /tf_static. Topics and
// types are in docs/ros2.md.
//
// Two threads meet here, and the worker is none of them:
//  - the socket server's I/O thread offers each new result (offerFrame) and, once a
//    second, the current reading (offerStatus): a copy into a one-result mailbox under a
//    short lock, only of the channels some DDS reader matches. A result not taken yet is
//    replaced by the next one (counted as skipped): the mailbox never grows;
//  - the publishing thread (ours) takes the newest mailbox content, fills the messages and
//    writes them (Cyclone serializes each once, whatever the number of readers), image
//    channels at most at max_rate_hz. A reliable reader that does not acknowledge holds a
//    write at most 100 ms (QoS), and only this thread waits for it.
//
// Stamps: a pair's capture time on the wall clock (CLOCK_REALTIME, the service's one
// conversion of its monotonic stamps, PublishedFrame::realtimeNs()), the clock ROS 2 nodes
// compare stamps on; every message of a pair has the same stamp.
//
// Thread contract: start()/stop() and setNearest() from the controlling thread (the
// service's); offerFrame()/offerStatus() from one thread; counters() from any thread.

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "pipeline/calibration.hpp"
#include "pipeline/nearest_settings.hpp"
#include "pipeline/stereo_processor.hpp"
#include "pipeline/zones.hpp"
#include "ros2/dds_participant.hpp"
#include "ros2/messages.hpp"
#include "ros2/range_reading.hpp"

namespace stereod::ros2 {

// The ROS 2 node's name, in the topics' namespace (ros_discovery_info).
inline constexpr const char* kNodeName = "stereod";

struct Ros2Settings {
    std::string ns = "/stereo"; // the topics' namespace; namespaceProblem() must accept it
    DdsDiscovery discovery;
    int points_step = 4;       // every n-th point of the cloud goes out
    double max_rate_hz = 30.0; // image and cloud topics at most this often
};

// What `status` shows of the node.
struct Ros2Counters {
    bool publishing = false;
    std::string error; // why it is not publishing, when it should be
    uint32_t domain_id = 0;
    bool localhost_only = true;
    uint64_t frames = 0;         // results published
    uint64_t frames_skipped = 0; // results replaced in the mailbox before they went out
    uint64_t messages = 0;       // DDS samples written
    uint64_t write_errors = 0;   // writes Cyclone refused
    uint64_t readers = 0;        // DDS readers matched over all topics
};

// The ROS 2 topics, by index.
enum Ros2Channel : uint32_t {
    kImageChannel,
    kDepthChannel,
    kDisparityChannel,
    kPointsChannel,
    kLeftInfoChannel,
    kRightInfoChannel,
    kRangeChannel,
    kReadingChannel,
    kTfStaticChannel,
    kRos2ChannelCount
};

// Each channel's ROS 2 topic name relative to the namespace ("left/image_rect"; /tf_static
// is absolute) and its ROS 2 type ("sensor_msgs/msg/Image").
struct Ros2ChannelSpec {
    const char* topic;
    const char* type;
};
const std::array<Ros2ChannelSpec, kRos2ChannelCount>& ros2Channels();

class Ros2Publisher {
  public:
    Ros2Publisher(Ros2Settings settings, RectifiedGeometry geometry, NearestSettings nearest,
                  CameraPose pose);
    ~Ros2Publisher();
    Ros2Publisher(const Ros2Publisher&) = delete;
    Ros2Publisher& operator=(const Ros2Publisher&) = delete;

    // Joins the DDS domain, makes the writers, publishes /tf_static and starts the
    // thread; "" when publishing, else the reason (the service then runs without it).
    std::string start();
    void stop();

    // A new result, captured at `stamp_realtime_ns` (CLOCK_REALTIME): its depth is trusted
    // when `depth_valid`; `reading_json` is the protocol's reading object for it.
    void offerFrame(const DepthResult& result, int64_t stamp_realtime_ns, bool depth_valid,
                    const DisparityRange& range, const CameraPose& pose,
                    std::string_view reading_json);
    // Once a second: the current reading (which says why when no frame comes any more),
    // the protocol's object, and the wall-clock stamp of the pair behind it (0: none).
    // Published when no frame went out for a second.
    void offerStatus(std::string_view reading_json, int64_t reading_realtime_ns);

    // New nearest-object settings (a reload): the Range's limits and field of view.
    void setNearest(const NearestSettings& nearest);
    // The rectified geometry of a calibration that came after start (the service ran
    // uncalibrated): camera_info, the disparity's f and t, the Range's field of view and
    // /tf_static's right optical frame follow it from the next frame. Any thread.
    void setGeometry(const RectifiedGeometry& geometry);

    Ros2Counters counters() const;

  private:
    struct Mailbox {
        bool frame = false;
        int64_t stamp_realtime_ns = 0; // the pair's capture time, CLOCK_REALTIME
        cv::Mat left, depth_m, disparity;
        const char* left_encoding = "mono8"; // "rgb8" where the left camera has colour
        // Whether the frame's cloud was taken (the points topic had readers then): a reader
        // matched since gets the next frame's, not an empty one.
        bool points_taken = false;
        std::vector<CloudPoint> cloud;
        std::vector<CloudColour> cloud_colour; // one per cloud point, or none (grey)
        // The left camera is in colour: the cloud carries it, empty or not, so that the
        // topic's layout does not change with a frame that has no depth.
        bool points_in_colour = false;
        float min_disparity = 0.0f;
        float max_disparity = 0.0f;
        Reading reading;
        std::string reading_json;
        CameraPose pose;
        NearestSettings nearest;
        RectifiedGeometry geometry;
        bool status = false;
        std::string status_reading_json;
        int64_t status_realtime_ns = 0;
    };
    // The publishing thread's buffers, kept from frame to frame.
    struct Scratch {
        std::array<int64_t, kRos2ChannelCount> last_sent_ns{}; // per channel, CLOCK_MONOTONIC
        std::vector<float> depth, disparity;
        std::vector<float> cloud_rgb; // x, y, z, intensity, rgb per point
    };
    struct Writers;

    bool wanted(Ros2Channel channel) const noexcept
    {
        return wanted_[channel].load(std::memory_order_relaxed);
    }
    void run();
    void refreshMatches();
    void publishFrame(const Mailbox& work, Scratch& scratch, int64_t now_ns);
    void publishStaticFrames(const CameraPose& pose, double baseline_m);
    void writeRange(const RangeValues& values, const Time& stamp);
    void publishReadingJson(const std::string& json);
    void countWrite(int code) noexcept;

    Ros2Settings settings_;
    RectifiedGeometry geometry_;       // guarded by mutex_
    std::unique_ptr<Writers> writers_; // the publishing thread's after start()
    std::array<std::atomic<bool>, kRos2ChannelCount> wanted_{};

    mutable std::mutex mutex_;
    std::condition_variable wake_;
    bool stopping_ = false;
    Mailbox mailbox_;            // guarded by mutex_
    NearestSettings nearest_;    // guarded by mutex_
    CameraPose pose_;            // guarded by mutex_: the pose of the last /tf_static
    double tf_baseline_m_ = 0.0; // guarded by mutex_: the baseline of the last /tf_static
    std::string error_;          // guarded by mutex_
    std::thread thread_;

    std::atomic<bool> publishing_{false};
    std::atomic<uint64_t> frames_{0}, frames_skipped_{0}, messages_{0}, write_errors_{0},
        readers_{0};
};

} // namespace stereod::ros2
