#include "protocol/request.hpp"

#include <algorithm>
#include <cmath>
#include <exception>
#include <new>
#include <utility>
#include <vector>

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
    return kSnapshotItemNames.parse(name);
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
    const std::optional<StreamKind> stream = kStreamNames.parse(name);
    if (!stream)
        return badRequest(
            "unknown stream " + quoteText(name) + "; known: " + joinNames(knownStreams()), id);
    subscribe.stream = *stream;
    if (std::optional<std::string> problem = readPositive(request, "max_hz", subscribe.max_hz))
        return badRequest(std::move(*problem), id);
    if (!present(request, "with"))
        return Request{subscribe, id};
    if (subscribe.stream != StreamKind::Raw)
        return badRequest("\"with\" applies to the raw stream only", id);
    static const std::vector<std::string> known_with = {
        snapshotItemName(SnapshotItem::Depth), snapshotItemName(SnapshotItem::Cloud), "colour"};
    std::vector<std::string> with;
    if (std::optional<std::string> problem = readNames(request, "with", known_with, with))
        return badRequest(std::move(*problem), id);
    for (const std::string& item : with) {
        subscribe.with_depth = subscribe.with_depth || item == known_with[0];
        subscribe.with_cloud = subscribe.with_cloud || item == known_with[1];
        subscribe.with_colour = subscribe.with_colour || item == known_with[2];
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
    if (name == "view")
        return Request{ViewRequest{}, id};
    return ProtocolError{
        ErrorCode::UnknownCommand,
        "unknown command " + quoteText(name) + "; known: " + joinNames(knownCommands()), id};
}

} // namespace

const char* streamName(StreamKind stream) noexcept
{
    return kStreamNames.name(stream, "readings");
}

const char* snapshotItemName(SnapshotItem item) noexcept
{
    return kSnapshotItemNames.name(item, "depth");
}

const std::vector<std::string>& knownCommands()
{
    static const std::vector<std::string> names = {"hello",       "distance",  "status",
                                                   "snapshot",    "subscribe", "reload",
                                                   "calibration", "zones",     "view"};
    return names;
}

const std::vector<std::string>& knownStreams()
{
    static const std::vector<std::string> names = kStreamNames.names();
    return names;
}

const std::vector<std::string>& knownSnapshotItems()
{
    static const std::vector<std::string> names = kSnapshotItemNames.names();
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

} // namespace stereod
