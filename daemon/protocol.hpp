#pragma once
// The socket protocol of docs/protocol.md, without sockets: the request parser (a pure
// function, unit-tested and fuzzable on its own), and the builders of the replies and
// event lines the server sends.
//
// Reentrant: every function here is pure or writes only into the caller's buffer.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "pipeline/reading.hpp"
#include "pipeline/zones.hpp"

namespace stereod {

// Replies keep their fields in the order written ("ok" first), which people reading a
// socket by hand appreciate; clients must not depend on the order.
using Json = nlohmann::ordered_json;

inline constexpr int kProtocolVersion = 1;

// The service's version ("0.1.0"), as `hello` and `stereod --version` give it.
const char* serviceVersion() noexcept;

// The stable error codes of the protocol.
enum class ErrorCode {
    BadJson,         // the line is not a JSON object
    BadRequest,      // a field is missing, of the wrong type, or out of range
    UnknownCommand,  // `cmd` names no command
    RequestTooLarge, // the line exceeded socket.max_request_bytes
    TooManyClients,  // socket.max_clients connections are open
    NotAvailable,    // nothing to give yet
    InvalidConfig,   // `reload` found the configuration invalid
    Internal,        // the service failed to do something it should have
    NotAllowed,      // the peer is not in socket.allow_uids / socket.allow_gids
    IdleTimeout,     // nothing received for socket.idle_timeout_s
};

// "bad_json", "bad_request", ...
const char* errorCodeName(ErrorCode code) noexcept;

// Raw: the pairs as captured, before rectification (two u8_gray payloads per event).
// Zones: the keep-out zones of every frame (`{"event":"zones",...}` lines).
enum class StreamKind { Readings, Depth, Raw, Zones };
const char* streamName(StreamKind stream) noexcept;

// RawLeft, RawRight: the pair's frames as captured, before rectification.
// Confidence: the matcher's per-pixel confidence (u8, 0 = no disparity, 1..255).
enum class SnapshotItem { Depth, Disparity, Left, Cloud, RawLeft, RawRight, Confidence };
const char* snapshotItemName(SnapshotItem item) noexcept;

struct HelloRequest {};

struct DistanceRequest {
    std::optional<double> max_age_ms; // > 0 and finite when present
};

struct StatusRequest {};

struct SnapshotRequest {
    // In the order the payloads are to be sent, without repeats. Default (no `items`):
    // depth, disparity, left, cloud.
    std::vector<SnapshotItem> items;
};

struct SubscribeRequest {
    StreamKind stream = StreamKind::Readings;
    std::optional<double> max_hz; // > 0 and finite when present
    // The raw stream only (`"with": ["depth", "cloud"]`): each raw event also carries the
    // pair's depth (f32_m) and point cloud (f32_xyzi), so a recorder gets a pair and its
    // results in one event, under one frame number.
    bool with_depth = false;
    bool with_cloud = false;
};

struct ReloadRequest {};

// The calibration in force, as the text of its file.
struct CalibrationRequest {};

// The keep-out zones of the latest frame.
struct ZonesRequest {};

using Command = std::variant<HelloRequest, DistanceRequest, StatusRequest, SnapshotRequest,
                             SubscribeRequest, ReloadRequest, CalibrationRequest, ZonesRequest>;

struct Request {
    Command command;
    std::optional<Json> id; // echoed in the reply when the request had one
};

// Why a line is not a request: the error reply to send.
struct ProtocolError {
    ErrorCode code = ErrorCode::BadRequest;
    std::string message;    // names the field and the problem
    std::optional<Json> id; // the request's id when the line had one
};

using ParseResult = std::variant<Request, ProtocolError>;

// Parses one request line (without its newline). Any byte sequence gives a Request or a
// ProtocolError; no exception escapes (bar std::bad_alloc). Unknown fields are ignored so
// that newer clients can talk to this service; a JSON null counts as an absent optional
// field.
ParseResult parseRequest(std::string_view line);

// The commands, streams and snapshot items this service knows, as `hello` lists them.
const std::vector<std::string>& knownCommands();
const std::vector<std::string>& knownStreams();
const std::vector<std::string>& knownSnapshotItems();

// `{"ok":true}` with the request's id when it had one; handlers add their fields.
Json okReply(const std::optional<Json>& id);

// `{"ok":false, "id":..., "error":{"code":..., "message":...}}`.
Json errorReply(ErrorCode code, std::string_view message, const std::optional<Json>& id);

// The `hello` reply.
Json helloReply(const std::optional<Json>& id);

// Appends `json` as one line ending in '\n'. Bytes that are not valid UTF-8 (say, from an
// echoed exception text) are replaced, so the line is always valid JSON.
void appendJsonLine(std::string& out, const Json& json);

// What a reading object is written from.
struct ReadingReport {
    Reading reading;
    // False when no pair lies behind the reading (no frame yet, or a source that failed
    // before its first pair): stamp_ns and age_ms are left out.
    bool has_frame = true;
    // The reason as one sentence with its numbers; empty: reasonMessage(reading).
    std::string_view message;
};

// The reason of a reading as one sentence with the numbers the reading holds, e.g. "too
// few valid pixels in the region: 2.0 % valid, 10.0 % needed". Empty for a valid reading.
std::string reasonMessage(const Reading& reading);

// Appends the reading object of docs/protocol.md; age_ms is `now_ns` minus the stamp.
// Allocates nothing once `out` has the capacity.
void appendReadingJson(std::string& out, const ReadingReport& report, int64_t now_ns);

// The same object, for composing replies.
Json readingToJson(const ReadingReport& report, int64_t now_ns);

// The zones of a frame as a JSON array of objects (name, state, reason, points,
// nearest_m, nearest_point_m, visible_fraction). Allocates nothing once `out` has the
// capacity.
void appendZonesJson(std::string& out, const std::vector<ZoneReading>& zones);

// The camera's pose on the robot: {"translation_m":[x,y,z],"rpy_deg":[r,p,y]}.
void appendCameraPoseJson(std::string& out, const CameraPose& pose);

// Appends `{"event":"zones","frame":N,"stamp_ns":S,"age_ms":A,"zones":[...]}\n`, with
// "skipped" when `skipped` > 0.
void appendZonesEvent(std::string& out, const std::vector<ZoneReading>& zones, uint64_t frame,
                      int64_t stamp_ns, int64_t now_ns, uint64_t skipped);

// Appends `{"event":"reading","reading":{...}}\n`, with "skipped" when `skipped` > 0.
void appendReadingEvent(std::string& out, const ReadingReport& report, int64_t now_ns,
                        uint64_t skipped);

// The header line of a depth event; `bytes` of u16_mm payload follow it.
struct DepthEventHeader {
    uint64_t frame = 0;
    int64_t stamp_ns = 0;
    int width = 0;
    int height = 0;
    uint64_t bytes = 0;
    bool depth_valid = false; // the payload is this pair's depth, not cleared
};

// Appends the depth event's header line (with "skipped" when > 0), without the payload.
void appendDepthEventHeader(std::string& out, const DepthEventHeader& header,
                            const ReadingReport& report, int64_t now_ns, uint64_t skipped);

// The header line of a raw event; two u8_gray payloads of width * height bytes follow it,
// raw_left then raw_right. Stamps are each camera's own capture stamp (Frame::
// source_stamp_ns: CLOCK_MONOTONIC for cameras, the recorded stamp on replay).
// A subscription `with` depth or cloud adds, after them, `depth` (f32_m, depth_width x
// depth_height float32) and `cloud` (f32_xyzi, cloud_points x 16 bytes), and the pair's
// `depth_valid`.
struct RawEventHeader {
    uint64_t frame = 0;
    int64_t left_stamp_ns = 0;
    int64_t right_stamp_ns = 0;
    int width = 0;
    int height = 0;
    bool depth_valid = false;
    int depth_width = 0;
    int depth_height = 0;
    uint64_t cloud_points = 0;
};

// Appends the raw event's header line (always with "skipped"), without the payloads; with
// the depth and cloud descriptors when asked for. Allocates nothing once `out` has the
// capacity.
void appendRawEventHeader(std::string& out, const RawEventHeader& header, uint64_t skipped,
                          bool with_depth = false, bool with_cloud = false);

} // namespace stereod
