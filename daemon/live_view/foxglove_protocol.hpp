#pragma once
// The Foxglove WebSocket protocol (foxglove.websocket.v1) as pure functions: what the
// server says (serverInfo, advertise, status), what a client may ask (subscribe,
// unsubscribe), and the binary frame of a message. No sockets: the transport carries the
// texts and bytes these make, so the parser can be tested and fuzzed on its own.

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace stereod::live_view {

inline constexpr const char* kSubprotocol = "foxglove.websocket.v1";

// One advertised channel.
struct ChannelSpec {
    uint32_t id = 0;
    std::string topic;           // "/stereo/depth"
    std::string encoding;        // "cdr" or "json"
    std::string schema_name;     // "sensor_msgs/msg/Image"
    std::string schema;          // ros2msg text, or a JSON schema
    std::string schema_encoding; // "ros2msg" or "jsonschema"
};

std::string serverInfoJson(std::string_view name, std::string_view session_id);
std::string advertiseJson(const std::vector<ChannelSpec>& channels);
// A status message shown to the user by Foxglove; level 0 info, 1 warning, 2 error.
std::string statusJson(int level, std::string_view message);

// What one text message of a client asks.
struct ClientRequest {
    enum class Kind { Subscribe, Unsubscribe, Ignored, Invalid };
    Kind kind = Kind::Invalid;
    std::vector<std::pair<uint32_t, uint32_t>> subscriptions; // (subscription id, channel id)
    std::vector<uint32_t> unsubscriptions;                    // subscription ids
    std::string problem; // for Invalid: what is wrong, for the status reply
};

// Parses a client's text message. Operations this server does not offer (publishing,
// parameters, services) are Ignored; anything malformed is Invalid with the reason.
// Never throws.
ClientRequest parseClientMessage(std::string_view text);

// Appends the binary messageData frame: opcode 0x01, subscription id (u32 LE), log time
// (u64 LE, ns), then the payload.
void appendMessageData(uint32_t subscription_id, uint64_t log_time_ns, std::string_view payload,
                       std::string& out);
// Rewrites the subscription id of a frame appendMessageData() made.
void setSubscriptionId(std::string& frame, uint32_t subscription_id);

} // namespace stereod::live_view
