#include "ctl/payload.hpp"

#include <optional>
#include <utility>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

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
    if (!imagePayloadAddsUp(payload, static_cast<std::size_t>(CV_ELEM_SIZE(type)))) {
        throw ClientError(fmt::format("the service announced a {} payload of {}x{} {} in {} "
                                      "bytes, which does not add up",
                                      payload.name, payload.width, payload.height, payload.format,
                                      payload.bytes),
                          0);
    }
    image.create(payload.height, payload.width, type);
    client.readPayload(image.data, payload.bytes);
}

namespace {

// One value per point into `values`, after `adds_up` says the bytes fit the points.
template <typename Value>
void readPerPoint(ProtocolClient& client, const Payload& payload, bool adds_up, const char* what,
                  std::vector<Value>& values)
{
    if (!adds_up) {
        throw ClientError(fmt::format("the service announced {} {} in {} bytes, which does not "
                                      "add up",
                                      payload.points, what, payload.bytes),
                          0);
    }
    values.resize(payload.points);
    client.readPayload(values.data(), payload.bytes);
}

} // namespace

void readCloudPayload(ProtocolClient& client, const Payload& payload,
                      std::vector<CloudPoint>& cloud)
{
    readPerPoint(client, payload, cloudPayloadAddsUp(payload), "cloud points", cloud);
}

void readColourPayload(ProtocolClient& client, const Payload& payload, cv::Mat& bgr)
{
    if (payload.per_point || !colourPayloadAddsUp(payload)) {
        throw ClientError(fmt::format("the service announced a {} payload of {}x{} {} in {} "
                                      "bytes, which does not add up",
                                      payload.name, payload.width, payload.height, payload.format,
                                      payload.bytes),
                          0);
    }
    if (payload.bytes == 0) {
        bgr.release();
        return;
    }
    bgr.create(payload.height, payload.width, CV_8UC3);
    client.readPayload(bgr.data, payload.bytes);
    cv::cvtColor(bgr, bgr, cv::COLOR_RGB2BGR);
}

void readCloudColourPayload(ProtocolClient& client, const Payload& payload,
                            std::vector<CloudColour>& colours)
{
    readPerPoint(client, payload, payload.per_point && colourPayloadAddsUp(payload),
                 "cloud colours", colours);
}

} // namespace stereod
