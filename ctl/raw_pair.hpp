#pragma once
// Reading one event of the service's `raw` stream (docs/protocol.md) off the connection: the
// grey pair and, when asked for, its results and colour, into a RawPair. What
// `stereoctl record` (ctl/record_command.cpp) and `stereoctl calibrate --live`
// (ctl/live_calibration.cpp) both read; each decides at its call what an incomplete pair
// means (the recorder drops it, the calibration stops with an error).
//
// Reentrant: no state; the client passed in is used by the calling thread only. A RawPair
// belongs to whoever holds it. Units: stamps in ns.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "ctl/client.hpp"
#include "model/cloud_point.hpp"

namespace stereod {

// One raw pair of the service, with its results; reused from pair to pair.
struct RawPair {
    cv::Mat left; // CV_8UC1, as captured (before rectification)
    cv::Mat right;
    // The cameras' colour as captured (CV_8UC3, BGR), empty where a camera kept none: what
    // is recorded in its place (a colour PNG, a bgr8 image in a bag).
    cv::Mat left_colour;
    cv::Mat right_colour;
    // Each camera's own capture stamps (the source's: CLOCK_MONOTONIC for cameras, the
    // recorded ones on replay): what a CSV+PNG recording keeps, to be replayed as it was.
    int64_t left_stamp_ns = 0;
    int64_t right_stamp_ns = 0;
    // The same frames in the service's one time base, CLOCK_REALTIME: what a bag carries
    // (header.stamp and log time), as ROS does. A service older than these fields gives
    // none: the bag then keeps the source's stamps.
    std::optional<int64_t> left_realtime_ns;
    std::optional<int64_t> right_realtime_ns;
    // The pair's results (--with), when the event carried them. The buffers keep their
    // size from pair to pair.
    cv::Mat depth_m; // CV_32FC1 metres, 0 = none
    bool depth_present = false;
    std::vector<CloudPoint> cloud;
    bool cloud_present = false; // (a cloud may have no point)
    // One colour per cloud point when the left camera kept its colour, else none.
    std::vector<CloudColour> cloud_colour;
};

// The results to read with the pair (`stereoctl record --with`); the rest are read past.
struct Results {
    bool depth = false;
    bool points = false;
    bool any() const noexcept { return depth || points; }
};

// What readRawPair found in an event.
struct RawPairContents {
    bool left = false;  // a raw_left u8_gray image was read
    bool right = false; // a raw_right u8_gray image was read
    // The name of the first payload that is none of the raw stream's (read past): a
    // service newer than this stereoctl.
    std::optional<std::string> unknown;

    // Both images and nothing unknown: the pair as this stereoctl understands it whole.
    bool complete() const noexcept { return left && right && !unknown; }
};

// Reads the payloads of a raw event into `pair` (its results only when `results` asks for
// them); a payload not wanted is read past, so the connection stays in step either way.
// Throws ClientError when the event has no payloads list, or a payload announces a size
// that does not add up or is cut short (ctl/payload.hpp): the connection is then out of
// step.
RawPairContents readRawPair(ProtocolClient& client, const nlohmann::ordered_json& event,
                            RawPair& pair, const Results& results);

// Reads the payloads of a raw event past, for a pair with no room to go to. Throws as
// readRawPair does.
void skipRawPair(ProtocolClient& client, const nlohmann::ordered_json& event);

} // namespace stereod
