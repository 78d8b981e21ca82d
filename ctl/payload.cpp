#include "ctl/payload.hpp"

#include <algorithm>

#include <fmt/format.h>

namespace stereod {

std::size_t payloadBytes(const nlohmann::ordered_json& header)
{
    const auto bytes = header.find("bytes");
    if (bytes == header.end()) {
        return 0;
    }
    if (!bytes->is_number_unsigned()) {
        throw ClientError(
            "a header from the service has a \"bytes\" that is not a count: " + header.dump(), 0);
    }
    return bytes->get<std::size_t>();
}

Payload parsePayload(const nlohmann::ordered_json& header)
{
    Payload p;
    p.name = header.value("name", std::string());
    p.format = header.value("format", std::string());
    p.width = header.value("width", 0);
    p.height = header.value("height", 0);
    p.points = header.value("points", std::size_t{0});
    p.bytes = payloadBytes(header);
    p.stamp_ns = header.value("stamp_ns", int64_t{0});
    return p;
}

void readImagePayload(ProtocolClient& client, const Payload& payload, int type, cv::Mat& image)
{
    const std::size_t expected = static_cast<std::size_t>(std::max(payload.width, 0)) *
                                 static_cast<std::size_t>(std::max(payload.height, 0)) *
                                 CV_ELEM_SIZE(type);
    if (payload.width <= 0 || payload.height <= 0 || payload.bytes != expected) {
        throw ClientError(fmt::format("the service announced a {} payload of {}x{} {} in {} "
                                      "bytes, which does not add up",
                                      payload.name, payload.width, payload.height, payload.format,
                                      payload.bytes),
                          0);
    }
    image.create(payload.height, payload.width, type);
    client.readPayload(image.data, payload.bytes);
}

} // namespace stereod
