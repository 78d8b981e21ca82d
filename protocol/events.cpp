#include "protocol/events.hpp"

#include "protocol/json_writer.hpp"
#include "protocol/payload.hpp"
#include "protocol/request.hpp"

namespace stereod {

void appendZonesEvent(std::string& out, const std::vector<ZoneReading>& zones, uint64_t frame,
                      int64_t stamp_ns, int64_t stamp_realtime_ns, int64_t now_ns, uint64_t skipped)
{
    JsonObjectWriter object(out);
    object.field("event", "zones");
    object.field("frame", frame);
    object.field("stamp_ns", stamp_ns);
    object.field("stamp_realtime_ns", stamp_realtime_ns);
    object.field("age_ms", roundTo(static_cast<double>(now_ns - stamp_ns) / 1e6, 3));
    if (skipped > 0)
        object.field("skipped", skipped);
    appendZonesJson(object.openField("zones"), zones);
    object.close();
    out.push_back('\n');
}

void appendReadingEvent(std::string& out, const ReadingReport& report, int64_t now_ns,
                        uint64_t skipped)
{
    JsonObjectWriter object(out);
    object.field("event", "reading");
    if (skipped > 0)
        object.field("skipped", skipped);
    appendReadingJson(object.openField("reading"), report, now_ns);
    object.close();
    out.push_back('\n');
}

void appendDepthEventHeader(std::string& out, const DepthEventHeader& header,
                            const ReadingReport& report, int64_t now_ns, uint64_t skipped)
{
    JsonObjectWriter object(out);
    object.field("event", "depth");
    object.field("frame", header.frame);
    object.field("stamp_ns", header.stamp_ns);
    object.field("stamp_realtime_ns", header.stamp_realtime_ns);
    object.field("format", kFormatDepthMm);
    object.field("width", header.width);
    object.field("height", header.height);
    object.field("bytes", header.bytes);
    object.field("depth_valid", header.depth_valid);
    if (skipped > 0)
        object.field("skipped", skipped);
    appendReadingJson(object.openField("reading"), report, now_ns);
    object.close();
    out.push_back('\n');
}

namespace {

// A raw frame's colour descriptor, as appendPayloadJson() writes it, from the item's name
// in place: "raw_right_colour" is longer than a std::string holds without allocating.
void appendRawColourJson(std::string& out, SnapshotItem item, int width, int height,
                         int64_t stamp_ns)
{
    JsonObjectWriter object(out);
    object.field("name", snapshotItemName(item));
    object.field("format", kFormatRgb);
    object.field("width", width);
    object.field("height", height);
    object.field("bytes", static_cast<uint64_t>(width) * static_cast<uint64_t>(height) * 3);
    object.field("stamp_ns", stamp_ns);
    object.close();
}

} // namespace

void appendRawEventHeader(std::string& out, const RawEventHeader& header, uint64_t skipped,
                          bool with_depth, bool with_cloud, bool with_colour)
{
    JsonObjectWriter object(out);
    object.field("event", "raw");
    object.field("frame", header.frame);
    object.field("left_stamp_ns", header.left_stamp_ns);
    object.field("right_stamp_ns", header.right_stamp_ns);
    object.field("left_stamp_realtime_ns", header.left_stamp_realtime_ns);
    object.field("right_stamp_realtime_ns", header.right_stamp_realtime_ns);
    object.field("skipped", skipped);
    std::string& payloads = object.openField("payloads");
    payloads.push_back('[');
    Payload side;
    side.format = kFormatGray;
    side.width = header.width;
    side.height = header.height;
    side.bytes = static_cast<std::size_t>(header.width) * static_cast<std::size_t>(header.height);
    side.name = snapshotItemName(SnapshotItem::RawLeft);
    side.stamp_ns = header.left_stamp_ns;
    appendPayloadJson(payloads, side);
    payloads.push_back(',');
    side.name = snapshotItemName(SnapshotItem::RawRight);
    side.stamp_ns = header.right_stamp_ns;
    appendPayloadJson(payloads, side);
    if (with_colour) {
        payloads.push_back(',');
        appendRawColourJson(payloads, SnapshotItem::RawLeftColour, header.left_colour_width,
                            header.left_colour_height, header.left_stamp_ns);
        payloads.push_back(',');
        appendRawColourJson(payloads, SnapshotItem::RawRightColour, header.right_colour_width,
                            header.right_colour_height, header.right_stamp_ns);
    }
    if (with_depth) {
        Payload depth;
        depth.name = snapshotItemName(SnapshotItem::Depth);
        depth.format = kFormatDepthM;
        depth.width = header.depth_width;
        depth.height = header.depth_height;
        depth.bytes = static_cast<std::size_t>(header.depth_width) *
                      static_cast<std::size_t>(header.depth_height) * sizeof(float);
        payloads.push_back(',');
        appendPayloadJson(payloads, depth);
    }
    if (with_cloud) {
        payloads.push_back(',');
        appendPayloadJson(payloads, cloudPayload(header.cloud_points));
    }
    if (with_cloud && with_colour) {
        payloads.push_back(',');
        appendPayloadJson(payloads, cloudColourPayload(header.cloud_colour_points));
    }
    payloads.push_back(']');
    if (with_depth || with_cloud)
        object.field("depth_valid", header.depth_valid);
    object.close();
    out.push_back('\n');
}

} // namespace stereod
