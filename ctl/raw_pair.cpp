#include "ctl/raw_pair.hpp"

#include <optional>
#include <string>
#include <string_view>

#include "ctl/payload.hpp"
#include "protocol/request.hpp"

namespace stereod {

using json = nlohmann::ordered_json;

namespace {

// The event's payloads list. Throws ClientError naming the socket when there is none.
const json& payloadsOf(const ProtocolClient& client, const json& event)
{
    const auto payloads = event.find("payloads");
    if (payloads == event.end() || !payloads->is_array()) {
        throw ClientError("a raw event from " + client.socketPath() +
                              " has no payloads list: " + event.dump(),
                          0);
    }
    return *payloads;
}

bool isItem(std::string_view name, SnapshotItem item)
{
    return name == snapshotItemName(item);
}

std::optional<int64_t> stampOf(const json& event, const char* key)
{
    const auto it = event.find(key);
    if (it == event.end() || !it->is_number_integer())
        return std::nullopt;
    return it->get<int64_t>();
}

} // namespace

RawPairContents readRawPair(ProtocolClient& client, const json& event, RawPair& pair,
                            const Results& results)
{
    const json& payloads = payloadsOf(client, event);
    pair.depth_present = false;
    pair.cloud_present = false;
    pair.cloud_colour.clear();
    pair.left_colour.release();
    pair.right_colour.release();
    pair.left_realtime_ns = stampOf(event, "left_stamp_realtime_ns");
    pair.right_realtime_ns = stampOf(event, "right_stamp_realtime_ns");
    RawPairContents contents;
    for (const json& header : payloads) {
        const Payload payload = parsePayload(header);
        const std::string_view name = payload.name;
        if (results.depth && isItem(name, SnapshotItem::Depth) && payload.format == kFormatDepthM) {
            // An uncalibrated service has no depth: 0 x 0, read as none.
            pair.depth_present = payload.width > 0 && payload.height > 0;
            if (pair.depth_present)
                readImagePayload(client, payload, CV_32FC1, pair.depth_m);
            continue;
        }
        if (results.points && isItem(name, SnapshotItem::Cloud)) {
            readCloudPayload(client, payload, pair.cloud);
            pair.cloud_present = true;
            continue;
        }
        if (results.points && isItem(name, SnapshotItem::CloudColour) &&
            payload.format == kFormatRgb) {
            readCloudColourPayload(client, payload, pair.cloud_colour);
            continue;
        }
        const bool left_colour = isItem(name, SnapshotItem::RawLeftColour);
        const bool right_colour = isItem(name, SnapshotItem::RawRightColour);
        if ((left_colour || right_colour) && payload.format == kFormatRgb) {
            readColourPayload(client, payload, left_colour ? pair.left_colour : pair.right_colour);
            continue;
        }
        const bool left = isItem(name, SnapshotItem::RawLeft);
        const bool right = isItem(name, SnapshotItem::RawRight);
        if ((left || right) && payload.format == kFormatGray) {
            readImagePayload(client, payload, CV_8UC1, left ? pair.left : pair.right);
            (left ? pair.left_stamp_ns : pair.right_stamp_ns) = payload.stamp_ns.value_or(0);
            (left ? contents.left : contents.right) = true;
            continue;
        }
        client.skipPayload(payload.bytes);
        const bool known = left || right || left_colour || right_colour ||
                           isItem(name, SnapshotItem::Depth) || isItem(name, SnapshotItem::Cloud) ||
                           isItem(name, SnapshotItem::CloudColour);
        if (!known && !contents.unknown)
            contents.unknown = std::string(name);
    }
    return contents;
}

void skipRawPair(ProtocolClient& client, const json& event)
{
    for (const json& header : payloadsOf(client, event))
        client.skipPayload(parsePayload(header).bytes);
}

} // namespace stereod
