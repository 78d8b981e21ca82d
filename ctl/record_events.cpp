#include "ctl/record_events.hpp"

#include <cstdint>
#include <optional>
#include <string_view>

#include "ctl/commands.hpp"
#include "ctl/payload.hpp"
#include "protocol/request.hpp"

namespace stereod {

using json = nlohmann::ordered_json;

Results parseWith(const std::vector<std::string>& with)
{
    Results results;
    for (const std::string& item : with) {
        if (item == "depth") {
            results.depth = true;
        } else if (item == "points") {
            results.points = true;
        } else {
            throw UsageError("--with: unknown \"" + item + "\"; accepted: depth, points");
        }
    }
    return results;
}

// Reads the payloads of a raw event into `pair` (its results only when `results` asks for
// them); false (payloads read past) when the event does not carry exactly raw_left and
// raw_right.
bool readRawPair(ProtocolClient& client, const json& event, PairBuffer* pair,
                 const Results& results)
{
    const auto payloads = event.find("payloads");
    if (payloads == event.end() || !payloads->is_array()) {
        throw ClientError("a raw event from " + client.socketPath() + " has no payloads list", 0);
    }
    bool complete = true;
    int sides = 0;
    if (pair != nullptr) {
        pair->depth_present = false;
        pair->cloud_present = false;
        pair->cloud_colour.clear();
        pair->left_colour.release();
        pair->right_colour.release();
        const auto stamp = [&event](const char* key) -> std::optional<int64_t> {
            const auto it = event.find(key);
            if (it == event.end() || !it->is_number_integer())
                return std::nullopt;
            return it->get<int64_t>();
        };
        pair->left_realtime_ns = stamp("left_stamp_realtime_ns");
        pair->right_realtime_ns = stamp("right_stamp_realtime_ns");
    }
    for (const json& header : *payloads) {
        const Payload payload = parsePayload(header);
        const std::string_view name = payload.name;
        if (pair != nullptr && results.depth && name == snapshotItemName(SnapshotItem::Depth) &&
            payload.format == kFormatDepthM) {
            // An uncalibrated service has no depth: 0 x 0, read as none.
            pair->depth_present = payload.width > 0 && payload.height > 0;
            if (pair->depth_present)
                readImagePayload(client, payload, CV_32FC1, pair->depth_m);
            continue;
        }
        if (pair != nullptr && results.points && name == snapshotItemName(SnapshotItem::Cloud)) {
            readCloudPayload(client, payload, pair->cloud);
            pair->cloud_present = true;
            continue;
        }
        if (pair != nullptr && results.points &&
            name == snapshotItemName(SnapshotItem::CloudColour) && payload.format == kFormatRgb) {
            readCloudColourPayload(client, payload, pair->cloud_colour);
            continue;
        }
        const bool left_colour = name == snapshotItemName(SnapshotItem::RawLeftColour);
        const bool right_colour = name == snapshotItemName(SnapshotItem::RawRightColour);
        if (pair != nullptr && (left_colour || right_colour) && payload.format == kFormatRgb) {
            readColourPayload(client, payload,
                              left_colour ? pair->left_colour : pair->right_colour);
            continue;
        }
        const bool left = name == snapshotItemName(SnapshotItem::RawLeft);
        const bool right = name == snapshotItemName(SnapshotItem::RawRight);
        if (pair == nullptr || (!left && !right) || payload.format != kFormatGray) {
            client.skipPayload(payload.bytes);
            complete = complete && (left || right || left_colour || right_colour ||
                                    name == snapshotItemName(SnapshotItem::Depth) ||
                                    name == snapshotItemName(SnapshotItem::Cloud) ||
                                    name == snapshotItemName(SnapshotItem::CloudColour));
            continue;
        }
        readImagePayload(client, payload, CV_8UC1, left ? pair->left : pair->right);
        (left ? pair->left_stamp_ns : pair->right_stamp_ns) = payload.stamp_ns.value_or(0);
        ++sides;
    }
    return pair != nullptr && complete && sides == 2;
}

// The service's `with` results are missing from an event: a service older than them.
void checkResultsPresent(const json& event, const Results& results, const std::string& socket)
{
    bool depth = false;
    bool cloud = false;
    for (const json& header : event.value("payloads", json::array())) {
        const std::string name = header.value("name", std::string());
        depth = depth || name == snapshotItemName(SnapshotItem::Depth);
        cloud = cloud || name == snapshotItemName(SnapshotItem::Cloud);
    }
    if ((results.depth && !depth) || (results.points && !cloud)) {
        throw UsageError("the service at " + socket +
                         " sends no depth or points with its raw pairs (a stereod older than "
                         "`subscribe` `with`); record without --with");
    }
}

} // namespace stereod
