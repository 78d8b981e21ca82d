#include "ctl/payload.hpp"

#include <optional>
#include <utility>

#include <fmt/format.h>

namespace stereod {

namespace {

ClientError bytesNotACount(const nlohmann::ordered_json& header)
{
    return ClientError(
        "a header from the service has a \"bytes\" that is not a count: " + header.dump(), 0);
}

} // namespace

std::size_t payloadBytes(const nlohmann::ordered_json& header)
{
    const std::optional<std::size_t> bytes = payloadBytesFromJson(header);
    if (!bytes) {
        throw bytesNotACount(header);
    }
    return *bytes;
}

Payload parsePayload(const nlohmann::ordered_json& header)
{
    std::optional<Payload> payload = payloadFromJson(header);
    if (!payload) {
        throw bytesNotACount(header);
    }
    return std::move(*payload);
}

void readImagePayload(ProtocolClient& client, const Payload& payload, int type, cv::Mat& image)
{
    if (!imagePayloadAddsUp(payload, type)) {
        throw ClientError(fmt::format("the service announced a {} payload of {}x{} {} in {} "
                                      "bytes, which does not add up",
                                      payload.name, payload.width, payload.height, payload.format,
                                      payload.bytes),
                          0);
    }
    image.create(payload.height, payload.width, type);
    client.readPayload(image.data, payload.bytes);
}

void readCloudPayload(ProtocolClient& client, const Payload& payload,
                      std::vector<CloudPoint>& cloud)
{
    if (!cloudPayloadAddsUp(payload)) {
        throw ClientError(fmt::format("the service announced {} cloud points in {} bytes, "
                                      "which does not add up",
                                      payload.points, payload.bytes),
                          0);
    }
    cloud.resize(payload.points);
    client.readPayload(cloud.data(), payload.bytes);
}

} // namespace stereod
