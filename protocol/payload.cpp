#include "protocol/payload.hpp"

#include <algorithm>

#include "protocol/json_writer.hpp"

namespace stereod {

namespace {

Payload perPointPayload(std::string_view name, std::string_view format, std::size_t points,
                        std::size_t bytes_per_point)
{
    Payload payload;
    payload.name = name;
    payload.format = format;
    payload.per_point = true;
    payload.points = points;
    payload.bytes = points * bytes_per_point;
    return payload;
}

} // namespace

Payload cloudPayload(std::size_t points)
{
    return perPointPayload("cloud", kFormatCloud, points, sizeof(CloudPoint));
}

Payload cloudColourPayload(std::size_t points)
{
    return perPointPayload("cloud_colour", kFormatRgb, points, sizeof(CloudColour));
}

void appendPayloadJson(std::string& out, const Payload& payload)
{
    JsonObjectWriter object(out);
    object.field("name", payload.name);
    object.field("format", payload.format);
    if (payload.per_point) {
        object.field("points", static_cast<uint64_t>(payload.points));
    } else {
        object.field("width", payload.width);
        object.field("height", payload.height);
    }
    object.field("bytes", static_cast<uint64_t>(payload.bytes));
    if (payload.stamp_ns)
        object.field("stamp_ns", *payload.stamp_ns);
    object.close();
}

Json payloadToJson(const Payload& payload)
{
    std::string text;
    appendPayloadJson(text, payload);
    return Json::parse(text);
}

std::optional<std::size_t> payloadBytesFromJson(const Json& header)
{
    const auto bytes = header.find("bytes");
    if (bytes == header.end())
        return 0;
    // Parsed text holds a count as unsigned; a value built in a program may hold it signed.
    if (!bytes->is_number_integer() || (!bytes->is_number_unsigned() && bytes->get<int64_t>() < 0))
        return std::nullopt;
    return bytes->get<std::size_t>();
}

std::optional<Payload> payloadFromJson(const Json& header)
{
    const std::optional<std::size_t> bytes = payloadBytesFromJson(header);
    if (!bytes)
        return std::nullopt;
    Payload payload;
    payload.name = header.value("name", std::string());
    payload.format = header.value("format", std::string());
    payload.width = header.value("width", 0);
    payload.height = header.value("height", 0);
    payload.per_point = header.contains("points");
    payload.points = header.value("points", std::size_t{0});
    payload.bytes = *bytes;
    if (const auto stamp = header.find("stamp_ns"); stamp != header.end())
        payload.stamp_ns = stamp->get<int64_t>();
    return payload;
}

bool imagePayloadAddsUp(const Payload& payload, std::size_t pixel_bytes)
{
    const std::size_t expected = static_cast<std::size_t>(std::max(payload.width, 0)) *
                                 static_cast<std::size_t>(std::max(payload.height, 0)) *
                                 pixel_bytes;
    return payload.width > 0 && payload.height > 0 && payload.bytes == expected;
}

bool cloudPayloadAddsUp(const Payload& payload)
{
    return payload.bytes == payload.points * sizeof(CloudPoint);
}

bool colourPayloadAddsUp(const Payload& payload)
{
    if (payload.per_point)
        return payload.bytes == payload.points * sizeof(CloudColour);
    if (payload.width == 0 && payload.height == 0)
        return payload.bytes == 0;
    return imagePayloadAddsUp(payload, std::size_t{3}); // u8_rgb: r, g, b
}

} // namespace stereod
