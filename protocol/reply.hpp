#pragma once
// What every reply of the socket protocol (docs/protocol.md) has in common: one line of
// JSON with `ok`, the request's `id` when it had one, and on failure an `error` with a
// stable code and a human message.
//
// Reentrant: every function here is pure or writes only into the caller's buffer.

#include <optional>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "base/name_table.hpp"

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

// The codes as the protocol writes them, one table for naming and parsing them.
inline constexpr NameTable<ErrorCode, 10> kErrorCodes{{{
    {ErrorCode::BadJson, "bad_json"},
    {ErrorCode::BadRequest, "bad_request"},
    {ErrorCode::UnknownCommand, "unknown_command"},
    {ErrorCode::RequestTooLarge, "request_too_large"},
    {ErrorCode::TooManyClients, "too_many_clients"},
    {ErrorCode::NotAvailable, "not_available"},
    {ErrorCode::InvalidConfig, "invalid_config"},
    {ErrorCode::Internal, "internal"},
    {ErrorCode::NotAllowed, "not_allowed"},
    {ErrorCode::IdleTimeout, "idle_timeout"},
}}};
static_assert(kErrorCodes.wellFormed());

// "bad_json", "bad_request", ...
const char* errorCodeName(ErrorCode code) noexcept;

// `{"ok":true}` with the request's id when it had one; handlers add their fields.
Json okReply(const std::optional<Json>& id);

// `{"ok":false, "id":..., "error":{"code":..., "message":...}}`.
Json errorReply(ErrorCode code, std::string_view message, const std::optional<Json>& id);

// The `hello` reply: service, version, protocol, and the commands, streams and snapshot
// items known (protocol/request.hpp).
Json helloReply(const std::optional<Json>& id);

// Appends `json` as one line ending in '\n'. Bytes that are not valid UTF-8 (say, from an
// echoed exception text) are replaced, so the line is always valid JSON.
void appendJsonLine(std::string& out, const Json& json);

// `json` as JSON text without a newline, invalid UTF-8 replaced as by appendJsonLine().
std::string jsonText(const Json& json);

} // namespace stereod
