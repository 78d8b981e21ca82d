#include "daemon/protocol.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <exception>
#include <new>
#include <utility>
#include <vector>

#include "daemon/json_writer.hpp"

namespace stereod {

namespace {

// Longest piece of client-supplied text quoted back in an error message.
constexpr std::size_t kMaxQuotedBytes = 64;
// Longest message taken from the JSON library (its "last read" part quotes the input).
constexpr std::size_t kMaxLibraryMessageBytes = 200;

std::string quoteText(std::string_view text)
{
    std::string out;
    if (text.size() > kMaxQuotedBytes) {
        out.append("\"").append(text.substr(0, kMaxQuotedBytes)).append("...\"");
    } else {
        out.append("\"").append(text).append("\"");
    }
    return out;
}

std::string joinNames(const std::vector<std::string>& names)
{
    std::string out;
    for (const std::string& name : names) {
        if (!out.empty())
            out.append(", ");
        out.append(name);
    }
    return out;
}

// nlohmann's messages start with "[json.exception.parse_error.101] "; the code means
// nothing to a client, the rest (line, column, what was expected) does.
std::string libraryMessage(const char* what)
{
    std::string_view text(what);
    if (!text.empty() && text.front() == '[') {
        if (const std::size_t end = text.find("] "); end != std::string_view::npos)
            text.remove_prefix(end + 2);
    }
    if (text.size() > kMaxLibraryMessageBytes)
        return std::string(text.substr(0, kMaxLibraryMessageBytes)) + "...";
    return std::string(text);
}

ProtocolError badRequest(std::string message, const std::optional<Json>& id)
{
    return ProtocolError{ErrorCode::BadRequest, std::move(message), id};
}

// Reads an optional number that must be finite and > 0. Returns the problem, if any.
std::optional<std::string> readPositive(const Json& request, const char* key,
                                        std::optional<double>& value)
{
    const auto it = request.find(key);
    if (it == request.end() || it->is_null())
        return std::nullopt;
    if (!it->is_number())
        return std::string("\"") + key + "\" must be a number, not " + it->type_name();
    const double number = it->get<double>();
    if (!std::isfinite(number) || number <= 0.0)
        return std::string("\"") + key + "\" must be a finite number > 0";
    value = number;
    return std::nullopt;
}

std::optional<SnapshotItem> snapshotItemFromName(std::string_view name)
{
    for (const SnapshotItem item :
         {SnapshotItem::Depth, SnapshotItem::Disparity, SnapshotItem::Left, SnapshotItem::Cloud,
          SnapshotItem::RawLeft, SnapshotItem::RawRight, SnapshotItem::Confidence}) {
        if (name == snapshotItemName(item))
            return item;
    }
    return std::nullopt;
}

// Reads `key`, an array of strings each one of `known`, into `names`. Returns the
// problem, if any.
std::optional<std::string> readNames(const Json& request, const char* key,
                                     const std::vector<std::string>& known,
                                     std::vector<std::string>& names)
{
    const Json& list = request.at(key);
    const std::string quoted = std::string("\"") + key + "\"";
    if (!list.is_array())
        return quoted + " must be an array of strings, not " + list.type_name();
    std::size_t index = 0;
    for (const Json& entry : list) {
        const std::string where = quoted + "[" + std::to_string(index++) + "]";
        if (!entry.is_string())
            return where + " must be a string, not " + entry.type_name();
        const std::string& name = entry.get_ref<const std::string&>();
        if (std::find(known.begin(), known.end(), name) == known.end())
            return where + ": unknown item " + quoteText(name) + "; known: " + joinNames(known);
        names.push_back(name);
    }
    return std::nullopt;
}

bool present(const Json& request, const char* key)
{
    const auto it = request.find(key);
    return it != request.end() && !it->is_null();
}

ParseResult parseSnapshot(const Json& request, const std::optional<Json>& id)
{
    SnapshotRequest snapshot;
    if (!present(request, "items")) {
        snapshot.items = {SnapshotItem::Depth, SnapshotItem::Disparity, SnapshotItem::Left,
                          SnapshotItem::Cloud};
        return Request{snapshot, id};
    }
    std::vector<std::string> names;
    if (std::optional<std::string> problem =
            readNames(request, "items", knownSnapshotItems(), names))
        return badRequest(std::move(*problem), id);
    for (const std::string& name : names) {
        const SnapshotItem item = *snapshotItemFromName(name);
        if (std::find(snapshot.items.begin(), snapshot.items.end(), item) == snapshot.items.end())
            snapshot.items.push_back(item);
    }
    return Request{snapshot, id};
}

ParseResult parseSubscribe(const Json& request, const std::optional<Json>& id)
{
    SubscribeRequest subscribe;
    const auto it = request.find("stream");
    if (it == request.end() || it->is_null())
        return badRequest("missing \"stream\" (one of: " + joinNames(knownStreams()) + ")", id);
    if (!it->is_string())
        return badRequest(std::string("\"stream\" must be a string, not ") + it->type_name(), id);
    const std::string& name = it->get_ref<const std::string&>();
    if (name == streamName(StreamKind::Readings)) {
        subscribe.stream = StreamKind::Readings;
    } else if (name == streamName(StreamKind::Depth)) {
        subscribe.stream = StreamKind::Depth;
    } else if (name == streamName(StreamKind::Raw)) {
        subscribe.stream = StreamKind::Raw;
    } else if (name == streamName(StreamKind::Zones)) {
        subscribe.stream = StreamKind::Zones;
    } else {
        return badRequest(
            "unknown stream " + quoteText(name) + "; known: " + joinNames(knownStreams()), id);
    }
    if (std::optional<std::string> problem = readPositive(request, "max_hz", subscribe.max_hz))
        return badRequest(std::move(*problem), id);
    if (!present(request, "with"))
        return Request{subscribe, id};
    if (subscribe.stream != StreamKind::Raw)
        return badRequest("\"with\" applies to the raw stream only", id);
    static const std::vector<std::string> known_with = {"depth", "cloud"};
    std::vector<std::string> with;
    if (std::optional<std::string> problem = readNames(request, "with", known_with, with))
        return badRequest(std::move(*problem), id);
    for (const std::string& item : with) {
        subscribe.with_depth = subscribe.with_depth || item == "depth";
        subscribe.with_cloud = subscribe.with_cloud || item == "cloud";
    }
    return Request{subscribe, id};
}

// Copying and writing a JSON value recurse once per level: an id is echoed, so its
// depth is bounded before it is copied (the parser itself does not recurse). A level is
// an array or an object: `[[]]` has two, `7` none.
constexpr int kMaxIdDepth = 16;

bool nestedDeeperThan(const Json& value, int limit)
{
    std::vector<std::pair<const Json*, int>> pending{{&value, 1}};
    while (!pending.empty()) {
        const auto [node, level] = pending.back();
        pending.pop_back();
        if (!node->is_structured())
            continue;
        if (level > limit)
            return true;
        for (const Json& child : *node)
            pending.emplace_back(&child, level + 1);
    }
    return false;
}

ParseResult parseObject(const Json& request)
{
    std::optional<Json> id;
    if (const auto it = request.find("id"); it != request.end()) {
        if (nestedDeeperThan(*it, kMaxIdDepth))
            return badRequest("\"id\" nests deeper than " + std::to_string(kMaxIdDepth) + " levels",
                              std::nullopt);
        id = *it;
    }

    const auto cmd = request.find("cmd");
    if (cmd == request.end())
        return badRequest("missing \"cmd\" (a string naming the command)", id);
    if (!cmd->is_string())
        return badRequest(std::string("\"cmd\" must be a string, not ") + cmd->type_name(), id);
    const std::string& name = cmd->get_ref<const std::string&>();

    if (name == "hello")
        return Request{HelloRequest{}, id};
    if (name == "distance") {
        DistanceRequest distance;
        if (std::optional<std::string> problem =
                readPositive(request, "max_age_ms", distance.max_age_ms))
            return badRequest(std::move(*problem), id);
        return Request{distance, id};
    }
    if (name == "status")
        return Request{StatusRequest{}, id};
    if (name == "snapshot")
        return parseSnapshot(request, id);
    if (name == "subscribe")
        return parseSubscribe(request, id);
    if (name == "reload")
        return Request{ReloadRequest{}, id};
    if (name == "calibration")
        return Request{CalibrationRequest{}, id};
    if (name == "zones")
        return Request{ZonesRequest{}, id};
    return ProtocolError{
        ErrorCode::UnknownCommand,
        "unknown command " + quoteText(name) + "; known: " + joinNames(knownCommands()), id};
}

// Writes the reason sentence into `buffer` without allocating; returns its length.
std::size_t formatReasonMessage(const Reading& reading, char* buffer, std::size_t size)
{
    int written = 0;
    switch (reading.reason) {
    case NoReadingReason::None:
        written = 0;
        break;
    case NoReadingReason::TooFewValidPixels:
        written = std::snprintf(buffer, size, "%s: %.1f %% valid, %.1f %% needed",
                                reasonText(reading.reason), 100.0 * reading.valid_fraction,
                                100.0 * reading.min_valid_fraction);
        break;
    case NoReadingReason::NothingInRange:
        written = std::snprintf(
            buffer, size, "%s: %.0f pixels in range, %u needed (%.1f %% valid, %.1f %% in range)",
            reasonText(reading.reason), reading.in_range_fraction * reading.region_pixels,
            reading.min_pixels, 100.0 * reading.valid_fraction, 100.0 * reading.in_range_fraction);
        break;
    case NoReadingReason::CalibrationSuspect:
        written = std::snprintf(buffer, size,
                                "%s: rows of matching points %+.2f px apart; recalibrate, or "
                                "`stereoctl check-calibration --fix`",
                                reasonText(reading.reason), reading.calibration_row_offset_px);
        break;
    case NoReadingReason::NearerThanRange:
        written =
            std::snprintf(buffer, size,
                          "%s: nearer than %.3f m (%.1f %% of the region at the range's near "
                          "limit); raise matcher.num_disparities or lower matcher.min_depth_m "
                          "to measure it",
                          reasonText(reading.reason), reading.nearer_than_m,
                          100.0 * reading.range_limit_fraction);
        break;
    default:
        written = std::snprintf(buffer, size, "%s", reasonText(reading.reason));
        break;
    }
    if (written < 0 || size == 0)
        return 0;
    return std::min(static_cast<std::size_t>(written), size - 1);
}

} // namespace

const char* serviceVersion() noexcept
{
    return STEREOD_VERSION;
}

const char* errorCodeName(ErrorCode code) noexcept
{
    switch (code) {
    case ErrorCode::BadJson:
        return "bad_json";
    case ErrorCode::BadRequest:
        return "bad_request";
    case ErrorCode::UnknownCommand:
        return "unknown_command";
    case ErrorCode::RequestTooLarge:
        return "request_too_large";
    case ErrorCode::TooManyClients:
        return "too_many_clients";
    case ErrorCode::NotAvailable:
        return "not_available";
    case ErrorCode::InvalidConfig:
        return "invalid_config";
    case ErrorCode::Internal:
        return "internal";
    case ErrorCode::NotAllowed:
        return "not_allowed";
    case ErrorCode::IdleTimeout:
        return "idle_timeout";
    }
    return "internal";
}

const char* streamName(StreamKind stream) noexcept
{
    switch (stream) {
    case StreamKind::Readings:
        return "readings";
    case StreamKind::Depth:
        return "depth";
    case StreamKind::Raw:
        return "raw";
    case StreamKind::Zones:
        return "zones";
    }
    return "readings";
}

const char* snapshotItemName(SnapshotItem item) noexcept
{
    switch (item) {
    case SnapshotItem::Depth:
        return "depth";
    case SnapshotItem::Disparity:
        return "disparity";
    case SnapshotItem::Left:
        return "left";
    case SnapshotItem::Cloud:
        return "cloud";
    case SnapshotItem::RawLeft:
        return "raw_left";
    case SnapshotItem::RawRight:
        return "raw_right";
    case SnapshotItem::Confidence:
        return "confidence";
    }
    return "depth";
}

const std::vector<std::string>& knownCommands()
{
    static const std::vector<std::string> names = {
        "hello", "distance", "status", "snapshot", "subscribe", "reload", "calibration", "zones"};
    return names;
}

const std::vector<std::string>& knownStreams()
{
    static const std::vector<std::string> names = {"readings", "depth", "raw", "zones"};
    return names;
}

const std::vector<std::string>& knownSnapshotItems()
{
    static const std::vector<std::string> names = {"left",     "disparity", "depth",     "cloud",
                                                   "raw_left", "raw_right", "confidence"};
    return names;
}

ParseResult parseRequest(std::string_view line)
{
    // The parser takes a NUL byte for the end of the input: `{...}` followed by a NUL
    // and anything would pass. No JSON text holds a raw NUL.
    if (line.find('\0') != std::string_view::npos)
        return ProtocolError{ErrorCode::BadJson,
                             "the request is not valid JSON: it holds a NUL byte (at byte " +
                                 std::to_string(line.find('\0')) + ")",
                             std::nullopt};
    try {
        Json request;
        try {
            request = Json::parse(line.begin(), line.end());
        } catch (const Json::exception& e) {
            return ProtocolError{ErrorCode::BadJson,
                                 "the request is not valid JSON: " + libraryMessage(e.what()),
                                 std::nullopt};
        }
        if (!request.is_object())
            return ProtocolError{ErrorCode::BadJson,
                                 std::string("the request must be a JSON object, not ") +
                                     request.type_name(),
                                 std::nullopt};
        return parseObject(request);
    } catch (const std::bad_alloc&) {
        throw;
    } catch (const std::exception& e) {
        return ProtocolError{ErrorCode::Internal,
                             std::string("cannot read the request: ") + e.what(), std::nullopt};
    }
}

Json okReply(const std::optional<Json>& id)
{
    Json reply = Json::object();
    reply["ok"] = true;
    if (id)
        reply["id"] = *id;
    return reply;
}

Json errorReply(ErrorCode code, std::string_view message, const std::optional<Json>& id)
{
    Json reply = Json::object();
    reply["ok"] = false;
    if (id)
        reply["id"] = *id;
    reply["error"] = {{"code", errorCodeName(code)}, {"message", std::string(message)}};
    return reply;
}

Json helloReply(const std::optional<Json>& id)
{
    Json reply = okReply(id);
    reply["service"] = "stereod";
    reply["version"] = serviceVersion();
    reply["protocol"] = kProtocolVersion;
    reply["commands"] = knownCommands();
    reply["streams"] = knownStreams();
    reply["snapshot_items"] = knownSnapshotItems();
    return reply;
}

void appendJsonLine(std::string& out, const Json& json)
{
    out.append(json.dump(-1, ' ', false, Json::error_handler_t::replace));
    out.push_back('\n');
}

std::string reasonMessage(const Reading& reading)
{
    std::array<char, 256> buffer{};
    const std::size_t length = formatReasonMessage(reading, buffer.data(), buffer.size());
    return std::string(buffer.data(), length);
}

void appendReadingJson(std::string& out, const ReadingReport& report, int64_t now_ns)
{
    const Reading& reading = report.reading;
    const bool valid = reading.valid && reading.reason == NoReadingReason::None;
    JsonObjectWriter object(out);
    object.field("valid", valid);
    if (valid)
        object.field("distance_m", roundTo(reading.distance_m, 4));
    else
        object.nullField("distance_m");
    if (report.has_frame && reading.reason != NoReadingReason::NoFrameYet) {
        object.field("stamp_ns", reading.stamp_ns);
        object.field("age_ms", roundTo(static_cast<double>(now_ns - reading.stamp_ns) / 1e6, 3));
    }
    object.field("frame", reading.frame);
    object.field("valid_fraction", roundTo(reading.valid_fraction, 4));
    object.field("in_range_fraction", roundTo(reading.in_range_fraction, 4));
    object.field("region_pixels", reading.region_pixels);
    object.field("range_limit_fraction", roundTo(reading.range_limit_fraction, 4));
    if (reading.calibration_suspect) {
        object.field("calibration_suspect", true);
        object.field("calibration_row_offset_px", roundTo(reading.calibration_row_offset_px, 3));
    }
    if (reading.reason == NoReadingReason::NearerThanRange)
        object.field("nearer_than_m", roundTo(reading.nearer_than_m, 4));
    if (!valid) {
        const NoReadingReason reason =
            reading.reason == NoReadingReason::None ? NoReadingReason::BadFrame : reading.reason;
        std::string& reason_out = object.openField("reason");
        JsonObjectWriter reason_object(reason_out);
        reason_object.field("code", reasonCode(reason));
        if (!report.message.empty()) {
            reason_object.field("message", report.message);
        } else {
            Reading explained = reading;
            explained.reason = reason;
            std::array<char, 256> buffer{};
            const std::size_t length = formatReasonMessage(explained, buffer.data(), buffer.size());
            reason_object.field("message", std::string_view(buffer.data(), length));
        }
        reason_object.close();
    }
    object.close();
}

Json readingToJson(const ReadingReport& report, int64_t now_ns)
{
    std::string text;
    appendReadingJson(text, report, now_ns);
    return Json::parse(text);
}

namespace {

void appendVec3(std::string& out, const cv::Vec3d& v)
{
    out.push_back('[');
    for (int k = 0; k < 3; ++k) {
        if (k > 0)
            out.push_back(',');
        appendJsonNumber(out, roundTo(v[k], 4));
    }
    out.push_back(']');
}

} // namespace

void appendCameraPoseJson(std::string& out, const CameraPose& pose)
{
    JsonObjectWriter object(out);
    appendVec3(object.openField("translation_m"), pose.translation_m);
    appendVec3(object.openField("rpy_deg"), pose.rpy_deg);
    object.close();
}

void appendZonesJson(std::string& out, const std::vector<ZoneReading>& zones)
{
    out.push_back('[');
    for (std::size_t i = 0; i < zones.size(); ++i) {
        const ZoneReading& zone = zones[i];
        if (i > 0)
            out.push_back(',');
        JsonObjectWriter object(out);
        object.field("name", zone.name);
        object.field("state", zoneStateName(zone.state));
        if (!zone.reason.empty())
            object.field("reason", zone.reason);
        object.field("points", zone.points);
        if (zone.points > 0) {
            object.field("nearest_m", roundTo(zone.nearest_m, 4));
            appendVec3(object.openField("nearest_point_m"), zone.nearest_point_m);
        }
        appendVec3(object.openField("min_m"), zone.min_m);
        appendVec3(object.openField("max_m"), zone.max_m);
        object.field("visible_fraction", roundTo(zone.visible_fraction, 3));
        object.close();
    }
    out.push_back(']');
}

void appendZonesEvent(std::string& out, const std::vector<ZoneReading>& zones, uint64_t frame,
                      int64_t stamp_ns, int64_t now_ns, uint64_t skipped)
{
    JsonObjectWriter object(out);
    object.field("event", "zones");
    object.field("frame", frame);
    object.field("stamp_ns", stamp_ns);
    object.field("age_ms", roundTo(static_cast<double>(now_ns - stamp_ns) / 1e6, 3));
    if (skipped > 0)
        object.field("skipped", skipped);
    appendZonesJson(object.openField("zones"), zones);
    object.close();
    out.push_back('\n');
}

void appendReadingEvent(std::string& out, const ReadingReport& report, int64_t now_ns,
                        uint64_t skipped)
{
    JsonObjectWriter object(out);
    object.field("event", "reading");
    if (skipped > 0)
        object.field("skipped", skipped);
    appendReadingJson(object.openField("reading"), report, now_ns);
    object.close();
    out.push_back('\n');
}

void appendDepthEventHeader(std::string& out, const DepthEventHeader& header,
                            const ReadingReport& report, int64_t now_ns, uint64_t skipped)
{
    JsonObjectWriter object(out);
    object.field("event", "depth");
    object.field("frame", header.frame);
    object.field("stamp_ns", header.stamp_ns);
    object.field("format", "u16_mm");
    object.field("width", header.width);
    object.field("height", header.height);
    object.field("bytes", header.bytes);
    object.field("depth_valid", header.depth_valid);
    if (skipped > 0)
        object.field("skipped", skipped);
    appendReadingJson(object.openField("reading"), report, now_ns);
    object.close();
    out.push_back('\n');
}

namespace {

// One image's descriptor in a payloads array; `stamp_ns` only when given.
void appendImageDescriptor(std::string& payloads, const char* name, const char* format, int width,
                           int height, std::size_t element_bytes,
                           std::optional<int64_t> stamp_ns = std::nullopt)
{
    if (payloads.back() != '[')
        payloads.push_back(',');
    JsonObjectWriter payload(payloads);
    payload.field("name", name);
    payload.field("format", format);
    payload.field("width", width);
    payload.field("height", height);
    payload.field("bytes", static_cast<uint64_t>(width) * static_cast<uint64_t>(height) *
                               static_cast<uint64_t>(element_bytes));
    if (stamp_ns)
        payload.field("stamp_ns", *stamp_ns);
    payload.close();
}

} // namespace

void appendRawEventHeader(std::string& out, const RawEventHeader& header, uint64_t skipped,
                          bool with_depth, bool with_cloud)
{
    JsonObjectWriter object(out);
    object.field("event", "raw");
    object.field("frame", header.frame);
    object.field("left_stamp_ns", header.left_stamp_ns);
    object.field("right_stamp_ns", header.right_stamp_ns);
    object.field("skipped", skipped);
    std::string& payloads = object.openField("payloads");
    payloads.push_back('[');
    appendImageDescriptor(payloads, "raw_left", "u8_gray", header.width, header.height, 1,
                          header.left_stamp_ns);
    appendImageDescriptor(payloads, "raw_right", "u8_gray", header.width, header.height, 1,
                          header.right_stamp_ns);
    if (with_depth)
        appendImageDescriptor(payloads, "depth", "f32_m", header.depth_width, header.depth_height,
                              sizeof(float));
    if (with_cloud) {
        payloads.push_back(',');
        JsonObjectWriter payload(payloads);
        payload.field("name", "cloud");
        payload.field("format", "f32_xyzi");
        payload.field("points", header.cloud_points);
        payload.field("bytes", header.cloud_points * 4 * sizeof(float));
        payload.close();
    }
    payloads.push_back(']');
    if (with_depth || with_cloud)
        object.field("depth_valid", header.depth_valid);
    object.close();
    out.push_back('\n');
}

} // namespace stereod
