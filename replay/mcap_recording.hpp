#pragma once
// Stereo recordings as ROS 2 bags in MCAP (replay/mcap_writer.hpp, ros2/messages.hpp):
// what `stereoctl record --out FILE.mcap` writes and `stereod --replay FILE.mcap` reads.
//
// Written (profile `ros2`, message encoding `cdr`, schema encoding `ros2msg`):
//   /stereo/left/image_raw     sensor_msgs/msg/Image, as captured: mono8, or bgr8 for a
//                              camera that kept its colour
//   /stereo/right/image_raw    sensor_msgs/msg/Image
//   /stereo/left/camera_info   sensor_msgs/msg/CameraInfo, with every pair when the
//   /stereo/right/camera_info  calibration is known (the right one's p[3] = -fx' * B)
//   /stereo/depth              sensor_msgs/msg/Image, 32FC1 metres, NaN = no depth
//                              (optional: enableDepth())
//   /stereo/points             sensor_msgs/msg/PointCloud2, x y z intensity float32,
//                              and rgb (PCL's packed float) when the pair has colour
//                              (optional: enablePoints())
// log_time, publish_time and header.stamp are the stamps the writer is given: `stereoctl
// record` gives each frame's capture time in the service's one time base, CLOCK_REALTIME
// (docs/architecture.md, "Time"); a pair's depth and points carry its left image's stamp. Frame ids
// stereo_{left,right}_optical_frame (REP 103 optical frames: x right, y down, z forward);
// depth and points are in the rectified left camera's, stereo_left_optical_frame, as
// stereo_image_proc gives its disparity and points the left camera's frame id.
//
// Read: any MCAP whose channels carry two sensor_msgs/msg/Image streams (ours, or a ROS 2
// bag from a robot), paired by header stamp; the camera_info channels beside the image
// topics give the calibration when present.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "replay/mcap_reader.hpp"
#include "replay/mcap_writer.hpp"
#include "ros2/messages.hpp"

namespace stereod {

inline constexpr const char* kMcapLeftImageTopic = "/stereo/left/image_raw";
inline constexpr const char* kMcapRightImageTopic = "/stereo/right/image_raw";
inline constexpr const char* kMcapLeftInfoTopic = "/stereo/left/camera_info";
inline constexpr const char* kMcapRightInfoTopic = "/stereo/right/camera_info";
inline constexpr const char* kMcapDepthTopic = "/stereo/depth";
inline constexpr const char* kMcapPointsTopic = "/stereo/points";

// True when `path` names an MCAP file (by its first bytes; a directory is not).
bool isMcapFile(const std::string& path);

// Writes pairs as a ROS 2 bag. Chunks (zstd by default) are flushed as they fill, so a
// writer killed mid-way leaves every complete chunk readable (replay/mcap_writer.hpp).
// Errors throw mcap::McapError (the errno in code()).
//
// Thread-bound: one thread writes.
class McapRecordingWriter {
  public:
    // Creates `path` (never overwrites an existing file).
    explicit McapRecordingWriter(const std::string& path,
                                 mcap::WriterOptions options = defaultOptions());

    static mcap::WriterOptions defaultOptions();

    // The calibration in force, written as camera_info beside every later pair (stamped
    // like the pair). The header stamps and frame ids are set here.
    void setCameraInfo(const ros2::CameraInfo& left, const ros2::CameraInfo& right);

    // Appends one pair: two images of the same size, each CV_8UC1 (mono8) or CV_8UC3 BGR
    // (bgr8, a colour camera's), with their capture times.
    // Returns its index (0, 1, ...). Throws mcap::McapError (EINVAL for a wrong image).
    uint64_t write(const cv::Mat& left, const cv::Mat& right, int64_t left_stamp_ns,
                   int64_t right_stamp_ns);

    // Adds the /stereo/depth and /stereo/points channels (before the first pair, so that
    // readers see them even when no message follows).
    void enableDepth();
    void enablePoints();

    // The depth of the pair last written: CV_32FC1 metres, 0 = no depth (the pipeline's
    // convention), written as 32FC1 with NaN where there is none. Throws mcap::McapError
    // (EINVAL for a wrong image, or without enableDepth()).
    void writeDepth(const cv::Mat& depth_m, int64_t stamp_ns);
    // The point cloud of the pair last written: `points` points of 4 float32 each (x, y, z
    // in metres, intensity 0..255), written as an unorganised (height 1), dense cloud.
    // Throws mcap::McapError (EINVAL without enablePoints()).
    void writePoints(const float* xyzi, std::size_t points, int64_t stamp_ns);
    // The same for a coloured cloud: 5 float32 a point, the fifth its colour packed as
    // ROS packs a PointCloud2's `rgb` (ros2::xyziRgbCloud() makes them), written with the
    // fields x y z intensity rgb.
    void writeColouredPoints(const float* xyzirgb, std::size_t points, int64_t stamp_ns);

    // Writes the summary and closes the file. Throws mcap::McapError.
    void close() { writer_.close(); }

    uint64_t pairsWritten() const noexcept { return pairs_; }
    // Pairs whose two images are in chunks on disk: what a replay finds should the open
    // chunk never be written (a full disk). Pairs are written in order, the right image
    // after the left, so this is the right images on disk.
    uint64_t pairsOnDisk() const noexcept { return writer_.messagesOnDisk(right_channel_); }
    const mcap::Writer& file() const noexcept { return writer_; }

  private:
    void writeImage(uint16_t channel, const cv::Mat& image, int64_t stamp_ns, const char* frame_id);
    // `points` points of 4 float32 (x y z intensity), or 5 with `rgb`.
    void writeCloud(const float* values, std::size_t points, bool rgb, int64_t stamp_ns);
    // The MCAP sequence of the pair last written, which its depth and points share.
    uint32_t lastSequence() const noexcept
    {
        return static_cast<uint32_t>(pairs_ == 0 ? 0 : pairs_ - 1);
    }

    mcap::Writer writer_;
    uint16_t left_channel_ = 0;
    uint16_t right_channel_ = 0;
    uint16_t left_info_channel_ = 0;
    uint16_t right_info_channel_ = 0;
    std::optional<uint16_t> depth_channel_;
    std::optional<uint16_t> points_channel_;
    uint16_t image_schema_ = 0;
    std::optional<std::pair<ros2::CameraInfo, ros2::CameraInfo>> camera_info_;
    cv::Size size_;
    uint64_t pairs_ = 0;
    std::string message_; // scratch: one serialized message, reused
    cv::Mat depth_nan_;   // scratch: the depth with NaN for 0, reused
};

// One pair of a bag: where its two Image messages are, and their header stamps.
struct McapPair {
    mcap::MessageRef left;
    mcap::MessageRef right;
    int64_t left_stamp_ns = 0;
    int64_t right_stamp_ns = 0;
};

struct McapStereoIndex {
    std::string left_topic;
    std::string right_topic;
    std::vector<McapPair> pairs; // in the order of the left images in the file
    uint64_t unpaired_left = 0;  // images with no partner within the tolerance
    uint64_t unpaired_right = 0;
    // The first camera_info of each side's sibling topic (`.../camera_info` beside the
    // image topic), when both exist.
    std::optional<std::pair<ros2::CameraInfo, ros2::CameraInfo>> camera_info;
    std::vector<std::string> notes;    // what was chosen and why, for the log
    std::vector<std::string> problems; // what was skipped and why (damaged chunks, messages)
};

// Indexes the stereo pairs of a bag. Topics: the given ones; when both are empty, the
// defaults (/stereo/{left,right}/image_raw) when the bag has them, else the one pair of
// sensor_msgs/msg/Image topics whose names say "left" and "right". A left image is paired
// with the right image nearest in header stamp, within half the left stream's median
// period (each right image used once); others are counted as unpaired. Pairs keep the
// order in which their left images appear in the file.
// Throws mcap::McapError (EINVAL) naming the bag's image topics when no pair of topics
// fits, or when no pair is found.
McapStereoIndex indexMcapStereo(mcap::Reader& reader, const std::string& left_topic,
                                const std::string& right_topic);

// Decodes one Image message of the bag into `out` as 8-bit grayscale (mono8 as is,
// rgb8/bgr8/rgba8/bgra8 converted, yuv422/yuv422_yuy2 their luma), of `expected` size
// when that is not empty (replay/image_message.hpp says what is checked). False, with the
// reason, for other encodings or bad messages; throws mcap::McapError when the message
// cannot be read (a chunk that does not decompress).
bool decodeMcapImage(mcap::Reader& reader, const mcap::MessageRef& ref, cv::Mat& out,
                     std::string& reason, cv::Size expected = {});
// The same, and the image's colour into `colour` (BGR) where its encoding has colour
// (released for mono8).
bool decodeMcapImage(mcap::Reader& reader, const mcap::MessageRef& ref, cv::Mat& out,
                     cv::Mat& colour, std::string& reason, cv::Size expected = {});

} // namespace stereod
