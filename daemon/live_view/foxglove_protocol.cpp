#include "daemon/live_view/foxglove_protocol.hpp"

#include <limits>

#include <nlohmann/json.hpp>

namespace stereod::live_view {

namespace {

using nlohmann::json;

// A channel or subscription id: a JSON integer that fits in 32 bits.
bool readId(const json& value, uint32_t& out)
{
    if (!value.is_number_integer())
        return false;
    const auto wide = value.get<int64_t>();
    if (wide < 0 || wide > std::numeric_limits<uint32_t>::max())
        return false;
    out = static_cast<uint32_t>(wide);
    return true;
}

ClientRequest invalid(std::string problem)
{
    ClientRequest request;
    request.kind = ClientRequest::Kind::Invalid;
    request.problem = std::move(problem);
    return request;
}

void putLe(std::string& out, uint64_t value, int bytes)
{
    for (int i = 0; i < bytes; ++i)
        out.push_back(static_cast<char>((value >> (8 * i)) & 0xff));
}

constexpr std::size_t kSubscriptionIdOffset = 1; // after the opcode

} // namespace

std::string serverInfoJson(std::string_view name, std::string_view session_id)
{
    return json{{"op", "serverInfo"},
                {"name", name},
                {"capabilities", json::array()},
                {"supportedEncodings", json::array()},
                {"metadata", json::object()},
                {"sessionId", session_id}}
        .dump();
}

std::string advertiseJson(const std::vector<ChannelSpec>& channels)
{
    json list = json::array();
    for (const ChannelSpec& c : channels) {
        list.push_back({{"id", c.id},
                        {"topic", c.topic},
                        {"encoding", c.encoding},
                        {"schemaName", c.schema_name},
                        {"schema", c.schema},
                        {"schemaEncoding", c.schema_encoding}});
    }
    return json{{"op", "advertise"}, {"channels", std::move(list)}}.dump();
}

std::string statusJson(int level, std::string_view message)
{
    return json{{"op", "status"}, {"level", level}, {"message", message}}.dump(
        -1, ' ', false, json::error_handler_t::replace);
}

ClientRequest parseClientMessage(std::string_view text)
{
    const json message = json::parse(text, nullptr, false);
    if (message.is_discarded() || !message.is_object())
        return invalid("not a JSON object");
    const auto op = message.find("op");
    if (op == message.end() || !op->is_string())
        return invalid("no \"op\"");
    const std::string& name = op->get_ref<const std::string&>();
    if (name == "subscribe") {
        const auto list = message.find("subscriptions");
        if (list == message.end() || !list->is_array())
            return invalid("subscribe: \"subscriptions\" is not a list");
        ClientRequest request;
        request.kind = ClientRequest::Kind::Subscribe;
        for (const json& entry : *list) {
            uint32_t id = 0;
            uint32_t channel = 0;
            if (!entry.is_object() || !entry.contains("id") || !entry.contains("channelId") ||
                !readId(entry["id"], id) || !readId(entry["channelId"], channel))
                return invalid("subscribe: each subscription needs integer \"id\" and "
                               "\"channelId\"");
            request.subscriptions.emplace_back(id, channel);
        }
        return request;
    }
    if (name == "unsubscribe") {
        const auto list = message.find("subscriptionIds");
        if (list == message.end() || !list->is_array())
            return invalid("unsubscribe: \"subscriptionIds\" is not a list");
        ClientRequest request;
        request.kind = ClientRequest::Kind::Unsubscribe;
        for (const json& entry : *list) {
            uint32_t id = 0;
            if (!readId(entry, id))
                return invalid("unsubscribe: subscription ids are integers");
            request.unsubscriptions.push_back(id);
        }
        return request;
    }
    ClientRequest request;
    request.kind = ClientRequest::Kind::Ignored;
    request.problem = "operation \"" + name + "\" is not offered by this server";
    return request;
}

void appendMessageData(uint32_t subscription_id, uint64_t log_time_ns, std::string_view payload,
                       std::string& out)
{
    out.reserve(out.size() + 13 + payload.size());
    out.push_back(static_cast<char>(0x01));
    putLe(out, subscription_id, 4);
    putLe(out, log_time_ns, 8);
    out.append(payload);
}

void setSubscriptionId(std::string& frame, uint32_t subscription_id)
{
    for (std::size_t i = 0; i < 4; ++i)
        frame[kSubscriptionIdOffset + i] = static_cast<char>((subscription_id >> (8 * i)) & 0xff);
}

} // namespace stereod::live_view
