#pragma once
// The event lines the service sends to subscribers (docs/protocol.md, "subscribe"): one
// per frame and stream, written straight into a buffer so that the steady state allocates
// nothing (protocol/json_writer.hpp). Depth and raw events are header lines followed by
// binary payloads (protocol/payload.hpp).
//
// Reentrant: every function here writes only into the caller's buffer.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "model/zone_reading.hpp"
#include "protocol/reading_json.hpp"

namespace stereod {

// Appends `{"event":"zones","frame":N,"stamp_ns":S,"stamp_realtime_ns":R,"age_ms":A,
// "zones":[...]}\n`, with "skipped" when `skipped` > 0. stamp_ns is the pair's capture
// time on CLOCK_MONOTONIC, stamp_realtime_ns the same instant on CLOCK_REALTIME.
void appendZonesEvent(std::string& out, const std::vector<ZoneReading>& zones, uint64_t frame,
                      int64_t stamp_ns, int64_t stamp_realtime_ns, int64_t now_ns,
                      uint64_t skipped);

// Appends `{"event":"reading","reading":{...}}\n`, with "skipped" when `skipped` > 0.
void appendReadingEvent(std::string& out, const ReadingReport& report, int64_t now_ns,
                        uint64_t skipped);

// The header line of a depth event; `bytes` of u16_mm payload follow it.
struct DepthEventHeader {
    uint64_t frame = 0;
    int64_t stamp_ns = 0;          // capture time, CLOCK_MONOTONIC
    int64_t stamp_realtime_ns = 0; // the same instant, CLOCK_REALTIME
    int width = 0;
    int height = 0;
    uint64_t bytes = 0;
    bool depth_valid = false; // the payload is this pair's depth, not cleared
};

// Appends the depth event's header line (with "skipped" when > 0), without the payload.
void appendDepthEventHeader(std::string& out, const DepthEventHeader& header,
                            const ReadingReport& report, int64_t now_ns, uint64_t skipped);

// The header line of a raw event; two u8_gray payloads of width * height bytes follow it,
// raw_left then raw_right. left/right_stamp_ns are each camera's own capture stamp (Frame::
// source_stamp_ns: CLOCK_MONOTONIC for cameras, the recorded stamp on replay);
// left/right_stamp_realtime_ns each frame's capture time in the service's one time base,
// CLOCK_REALTIME (for a replay: when the pair was delivered), which bags carry.
// A subscription `with` depth or cloud adds, after them, `depth` (f32_m, depth_width x
// depth_height float32) and `cloud` (f32_xyzi, cloud_points x 16 bytes), and the pair's
// `depth_valid`. A subscription `with` colour adds, right after raw_right, the frames'
// colour as captured (raw_left_colour, raw_right_colour: u8_rgb, 0 x 0 where that camera
// kept none) and, after the cloud when it is asked for, `cloud_colour` (u8_rgb,
// cloud_colour_points x 3 bytes: the cloud's points in order, or none for a grey source).
struct RawEventHeader {
    uint64_t frame = 0;
    int64_t left_stamp_ns = 0;
    int64_t right_stamp_ns = 0;
    int64_t left_stamp_realtime_ns = 0;
    int64_t right_stamp_realtime_ns = 0;
    int width = 0;
    int height = 0;
    bool depth_valid = false;
    int depth_width = 0;
    int depth_height = 0;
    std::size_t cloud_points = 0;
    int left_colour_width = 0; // 0 x 0: the camera kept no colour
    int left_colour_height = 0;
    int right_colour_width = 0;
    int right_colour_height = 0;
    std::size_t cloud_colour_points = 0;
};

// Appends the raw event's header line (always with "skipped"), without the payloads; with
// the depth, cloud and colour descriptors when asked for. Allocates nothing once `out` has
// the capacity.
void appendRawEventHeader(std::string& out, const RawEventHeader& header, uint64_t skipped,
                          bool with_depth = false, bool with_cloud = false,
                          bool with_colour = false);

} // namespace stereod
