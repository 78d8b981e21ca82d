#include "protocol/reply.hpp"

#include "protocol/request.hpp"

namespace stereod {

const char* serviceVersion() noexcept
{
    return STEREOD_VERSION;
}

const char* errorCodeName(ErrorCode code) noexcept
{
    return kErrorCodes.name(code, "internal");
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

std::string jsonText(const Json& json)
{
    return json.dump(-1, ' ', false, Json::error_handler_t::replace);
}

void appendJsonLine(std::string& out, const Json& json)
{
    out.append(jsonText(json));
    out.push_back('\n');
}

} // namespace stereod
