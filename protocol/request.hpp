#pragma once
// The requests of the socket protocol (docs/protocol.md) and their parser: a pure
// function from one line of bytes to a request or the error reply to send, unit-tested and
// fuzzed on its own, without sockets.
//
// Reentrant: every function here is pure.

#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "base/name_table.hpp"
#include "protocol/reply.hpp"

namespace stereod {

// Raw: the pairs as captured, before rectification (two u8_gray payloads per event).
// Zones: the keep-out zones of every frame (`{"event":"zones",...}` lines).
enum class StreamKind { Readings, Depth, Raw, Zones };
inline constexpr NameTable<StreamKind, 4> kStreamNames{{{{StreamKind::Readings, "readings"},
                                                         {StreamKind::Depth, "depth"},
                                                         {StreamKind::Raw, "raw"},
                                                         {StreamKind::Zones, "zones"}}}};
static_assert(kStreamNames.wellFormed());
const char* streamName(StreamKind stream) noexcept;

// RawLeft, RawRight: the pair's frames as captured, before rectification.
// Confidence: the matcher's per-pixel confidence (u8, 0 = no disparity, 1..255).
// LeftColour, CloudColour, RawLeftColour, RawRightColour: the colour beside the grey
// (u8_rgb): the rectified left image, one colour per cloud point, the frames as captured;
// empty (0 x 0, no point) where the camera kept no colour.
enum class SnapshotItem {
    Depth,
    Disparity,
    Left,
    Cloud,
    RawLeft,
    RawRight,
    Confidence,
    LeftColour,
    CloudColour,
    RawLeftColour,
    RawRightColour,
};
// In the order `hello` lists them.
inline constexpr NameTable<SnapshotItem, 11> kSnapshotItemNames{{{
    {SnapshotItem::Left, "left"},
    {SnapshotItem::Disparity, "disparity"},
    {SnapshotItem::Depth, "depth"},
    {SnapshotItem::Cloud, "cloud"},
    {SnapshotItem::RawLeft, "raw_left"},
    {SnapshotItem::RawRight, "raw_right"},
    {SnapshotItem::Confidence, "confidence"},
    {SnapshotItem::LeftColour, "left_colour"},
    {SnapshotItem::CloudColour, "cloud_colour"},
    {SnapshotItem::RawLeftColour, "raw_left_colour"},
    {SnapshotItem::RawRightColour, "raw_right_colour"},
}}};
static_assert(kSnapshotItemNames.wellFormed());
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
    // The raw stream only (`"with": ["depth", "cloud", "colour"]`): each raw event also
    // carries the pair's depth (f32_m) and point cloud (f32_xyzi), so a recorder gets a pair
    // and its results in one event, under one frame number; with colour, the frames' colour
    // as captured (raw_left_colour, raw_right_colour) and the cloud's (cloud_colour).
    bool with_depth = false;
    bool with_cloud = false;
    bool with_colour = false;
};

struct ReloadRequest {};

// The calibration in force, as the text of its file.
struct CalibrationRequest {};

// The keep-out zones of the latest frame.
struct ZonesRequest {};

// The live view's addresses with its token (docs/live-view.md): what `stereoctl view`
// prints. Given only here, so that only those who may use the socket can watch.
struct ViewRequest {};

using Command =
    std::variant<HelloRequest, DistanceRequest, StatusRequest, SnapshotRequest, SubscribeRequest,
                 ReloadRequest, CalibrationRequest, ZonesRequest, ViewRequest>;

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

} // namespace stereod
