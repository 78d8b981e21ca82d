#pragma once
// Bags (ROS 2 in MCAP) written by the tests message by message, for the tests of what the
// replay does with bags that lie: Image messages whose every field is the test's choice
// (a width that overflows, a step of 0, an encoding nobody replays), channels of any
// schema, and a chunk whose zstd frame states any size. Written with the project's own
// MCAP writer and records (replay/mcap_writer.hpp, replay/mcap_records.hpp), so that the
// lie is in the message or the chunk and nowhere else.
//
// Reentrant: every function writes only what it is given.

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "replay/mcap_writer.hpp"

namespace stereod::test {

// The fields of one sensor_msgs/msg/Image, written as they are (nothing is checked).
struct ImageMessage {
    int64_t stamp_ns = 0;
    uint32_t height = 0;
    uint32_t width = 0;
    std::string encoding = "mono8";
    uint32_t step = 0; // bytes per row
    std::string data;
};

// A truthful mono8 message of `image` (CV_8UC1).
ImageMessage monoMessage(const cv::Mat& image, int64_t stamp_ns);

// One channel of a bag and the messages it carries, in file order.
struct BagTopic {
    std::string topic;
    std::string schema_name = "sensor_msgs/msg/Image";
    std::string message_encoding = "cdr";
    std::vector<ImageMessage> images; // serialized as CDR Image messages
};

// Writes the topics' messages interleaved (the first of each, then the second of each,
// ...) with `options` (default: ros2 profile, zstd chunks of 4 MiB, so a large message
// has a chunk of its own), and closes the bag.
void writeBag(const std::string& path, const std::vector<BagTopic>& topics,
              mcap::WriterOptions options = {});

// Left and right messages on /stereo/left/image_raw and /stereo/right/image_raw.
void writeStereoBag(const std::string& path,
                    const std::vector<std::pair<ImageMessage, ImageMessage>>& pairs,
                    mcap::WriterOptions options = {});

// The bytes of a bag without summary whose one Chunk (after an Image schema and a
// channel) says `compression` and `uncompressed_size` and holds `records` as they are:
// for a chunk whose zstd frame header states a size its blocks cannot hold.
std::string chunkBag(std::string_view records, uint64_t uncompressed_size,
                     const std::string& compression = "zstd");

// A zstd frame that states `content_size` bytes in its header (8-byte field, single
// segment) and holds one empty raw block: what the frame says and what it holds differ.
std::string lyingZstdFrame(uint64_t content_size);

} // namespace stereod::test
