#pragma once
// source.type ros2: the frame source that reads a stereo pair from a ROS 2 camera driver's
// two sensor_msgs/msg/Image topics over DDS (Cyclone DDS), as a ROS 2 node subscribing
// to them would (docs/ros2.md, "A ROS 2 camera driver as the source").
//
// Frame path: Cyclone's receive threads -> each topic's reader (keep last kReaderDepth,
// best effort: it matches a driver's sensor-data writers and reliable ones too) -> our
// reading thread, which takes the samples as CDR, checks every size the message declares
// against its bytes and the configured frame size before anything is decoded
// (decodeImageMessage(), the check and decoder a bag's images get), converts rgb8, bgr8,
// rgba8, bgra8 to grey and takes the luma of yuv422 / yuv422_yuy2 into a frame of a pool
// allocated at start, and offers it to a StereoSyncThread that pairs the
// two topics by header stamp within max_skew (capture/stereo_sync.hpp) and pushes the
// pairs into the PairRing (drop-oldest). Every queue on the way is bounded.
//
// A bad message (a size that does not fit, an encoding not taken, another frame size) is
// skipped and counted in its side's bad_frames, with its reason in last_bad_frame; the
// source runs on. A side with no image for stall_timeout is Stalled, and so is the source,
// with the topic and the writers it matches in last_error: the service reports source down
// and readings resume when images do.
//
// The calibration from the drivers' camera_info: with camera_info topics in the options (no
// calibration given), a reader of each (best effort: reliable writers match too) beside the
// image topics. Once both have given a message, the pair is checked and turned into a
// calibration by calibrationFromCameraInfoMessages() (pipeline/calibration_formats.hpp,
// the conversion a bag's camera_info gets) and held to the frame size; the first pair that
// passes is the calibration (cameraInfoCalibration()) for as long as the source lives. A
// pair refused is logged and shown in status().warnings with the topic and the field, and
// the next messages are tried; a camera_info that differs from the one taken, later, is
// ignored with a warning (a new calibration needs a restart, docs/ros2.md).
//
// In the ROS 2 graph: the participant is announced on ros_discovery_info as the node
// `stereod_source` in the node's namespace, with the GIDs of its readers (the image topics'
// and camera_info's), so that `ros2 node info` lists its subscriptions
// (ros2/node_announcement.hpp).
//
// Stamps: a message's header stamp (the wall clock, as ROS 2 stamps) is kept in
// Frame::source_stamp_ns and converted to CLOCK_MONOTONIC for Frame::stamp_ns with the
// clocks' offset, sampled once a second (so that the two images of one stamp get one). The driver
// must stamp on this machine's clock (or one synchronized with it) for the readings' age to mean
// anything; pairing needs only that both topics use one clock.
//
// Thread contract: as FrameSource: start()/stop() from one controlling thread; status()
// and frameSize() from any thread. Our reading thread is the only producer into both
// inboxes of the sync.
//
// Ownership: owns its DDS participant (sharing the process's localhost domain with the
// ROS 2 publisher's), its threads and the frame pool. Lifetime: as every source, each pair
// delivered must be released before the source is destroyed (stop(), drain or destroy the
// ring, destroy).
//
// Units: sizes in pixels, times in ns unless the name says otherwise.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <opencv2/core/types.hpp>

#include "base/rate_estimate.hpp"
#include "capture/frame_pool.hpp"
#include "capture/frame_source.hpp"
#include "capture/stereo_sync.hpp"
#include "pipeline/calibration.hpp"
#include "ros2/dds_participant.hpp"
#include "ros2/messages.hpp"

namespace stereod::ros2 {

struct Ros2SourceOptions {
    std::string left_topic = "/stereo/left/image_raw"; // ROS 2 topic names
    std::string right_topic = "/stereo/right/image_raw";
    // The drivers' sensor_msgs/msg/CameraInfo topics; empty: none subscribed to (the
    // calibration comes from elsewhere).
    std::string left_info_topic;
    std::string right_info_topic;
    cv::Size frame_size{640, 480};          // images of another size are refused, not decoded
    std::string node_namespace = "/stereo"; // the announced node's (ros2.namespace)
    DdsDiscovery discovery;
    SyncSettings sync;
    int64_t stall_timeout_ns = 2'000'000'000; // no image on a topic this long: Stalled
    std::size_t ring_capacity = 4;            // the PairRing's, to size the frame pool
};

// A calibration made from the drivers' camera_info, and the topics it came from.
struct CameraInfoCalibration {
    StereoCalibration calibration;
    std::string origin; // "/stereo/left/camera_info + /stereo/right/camera_info"
};

class Ros2ImageSource final : public FrameSource {
  public:
    // The node the source's participant is announced as, in options.node_namespace.
    static constexpr const char* kNodeName = "stereod_source";
    // Samples each reader keeps until our thread takes them ("keep last few").
    static constexpr int kReaderDepth = 4;
    // Frames queued per side between our reading thread and the sync thread.
    static constexpr std::size_t kInboxCapacity = 4;

    // Nothing is joined yet; the pool is allocated. Throws std::invalid_argument for bad
    // sync settings or an empty frame size.
    explicit Ros2ImageSource(Ros2SourceOptions options);
    ~Ros2ImageSource() override;

    Ros2ImageSource(const Ros2ImageSource&) = delete;
    Ros2ImageSource& operator=(const Ros2ImageSource&) = delete;

    // Joins the DDS domain, subscribes to both topics and starts the threads. Returns 0,
    // -EBUSY when running, or -EIO when DDS refuses (the reason in status().last_error).
    int start(PairRing& ring) override;
    void stop() noexcept override;
    SourceStatus status() const override;
    cv::Size frameSize() const override { return options_.frame_size; }

    // The calibration from the camera_info topics once a pair of their messages has passed
    // every check; none before, and none without camera_info topics. Any thread.
    std::optional<CameraInfoCalibration> cameraInfoCalibration() const;

    // The frames one side may hold at once: our hand, the inbox, the sync's queue, the
    // ring and the worker's pair.
    static std::size_t framesPerSide(std::size_t ring_capacity, const SyncSettings& sync) noexcept;

  private:
    struct Side {
        std::string topic;
        std::atomic<dds_entity_t> reader{0}; // 0 while stopped; status() reads it
        uint64_t sequence = 0;               // reading thread only
        // Written by the reading thread, read by status().
        std::atomic<uint64_t> frames{0};
        std::atomic<uint64_t> dropped{0}; // no free frame in the pool
        std::atomic<uint64_t> bad{0};
        std::atomic<int64_t> last_arrival_ns{0}; // CLOCK_MONOTONIC; 0: none yet
        RateEstimate<16> fps;                    // arrivals; add() on the reading thread only
    };

    // One camera's camera_info topic.
    struct InfoSide {
        std::string topic;
        std::atomic<dds_entity_t> reader{0}; // 0 while stopped or not subscribed
        std::optional<CameraInfo> latest;    // reading thread only: the newest that parsed
        std::optional<CameraInfo> taken;     // reading thread only: the one calibrated from
        std::atomic<bool> changed{false};    // a message differed from `taken`
    };

    void run() noexcept;
    // Takes what the camera_info reader of `side` holds; true when it took anything.
    bool takeCameraInfo(int side);
    // With a message of each side and no calibration yet: the pair checked, and taken or
    // refused; with a calibration: a message that differs is warned about, once.
    void considerCameraInfo();
    void noteCameraInfoProblem(std::string problem);
    // Takes what the reader of `side` holds; true when it took anything.
    bool takeSamples(int side);
    void handleMessage(int side, std::string_view message);
    void noteBad(int side, std::string reason);
    void noteArrival(Side& side, int64_t now_ns) noexcept;

    const Ros2SourceOptions options_;
    FramePool pool_;
    StereoSyncThread sync_;
    std::array<Side, 2> sides_;
    std::array<InfoSide, 2> infos_;
    // Reading thread only: the pair last refused, not checked again until one changes.
    std::optional<CameraInfo> refused_[2];

    // Made by start(), deleted by stop(); the reading thread uses them between.
    std::unique_ptr<DdsParticipant> participant_;
    dds_entity_t waitset_ = 0;
    dds_entity_t wake_ = 0; // guard condition stop() triggers
    std::thread thread_;
    std::atomic<bool> stop_requested_{false};
    std::atomic<int64_t> started_ns_{0}; // CLOCK_MONOTONIC of start(); 0 while stopped
    std::string message_;                // reading thread only: the sample's CDR, capacity kept
    // Reading thread only: CLOCK_REALTIME - CLOCK_MONOTONIC, and when it was sampled.
    int64_t offset_ns_ = 0;
    int64_t offset_sampled_ns_ = 0;
    bool running_ = false; // controlling thread only

    mutable std::mutex status_mutex_;
    std::string start_error_;                          // guarded by status_mutex_
    std::array<std::string, 2> bad_reasons_;           // guarded by status_mutex_
    std::optional<CameraInfoCalibration> calibration_; // guarded by status_mutex_
    std::string camera_info_problem_; // guarded by status_mutex_: the last pair refused
};

} // namespace stereod::ros2
