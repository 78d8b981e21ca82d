#include <algorithm>
#include <array>
#include <cstdio>
#include <stdexcept>

#include <spdlog/spdlog.h>

#include "capture/frame.hpp"
#include "daemon/image_payload.hpp"
#include "daemon/socket_server.hpp"

namespace stereod {

namespace {

struct SnapshotImage {
    const cv::Mat& mat;
    std::string_view format; // u8_rgb: `mat` is BGR, sent as RGB
};

// The image a snapshot item sends, and its payload format. Not for the cloud.
SnapshotImage snapshotImage(const PublishedFrame& frame, SnapshotItem item)
{
    switch (item) {
    case SnapshotItem::LeftColour:
        return {frame.result.left_rectified_colour, kFormatRgb};
    case SnapshotItem::RawLeftColour:
        return {frame.raw.left_colour, kFormatRgb};
    case SnapshotItem::RawRightColour:
        return {frame.raw.right_colour, kFormatRgb};
    case SnapshotItem::Depth:
        return {frame.depth_mm, kFormatDepthMm};
    case SnapshotItem::Disparity:
        return {frame.result.disparity, kFormatDisparityPx};
    case SnapshotItem::Left:
        return {frame.result.left_rectified, kFormatGray};
    case SnapshotItem::RawLeft:
        return {frame.raw.left, kFormatGray};
    case SnapshotItem::RawRight:
        return {frame.raw.right, kFormatGray};
    case SnapshotItem::Confidence:
        return {frame.result.confidence, kFormatConfidence};
    case SnapshotItem::Cloud:
    case SnapshotItem::CloudColour:
        break;
    }
    throw std::logic_error("a snapshot's cloud is not an image");
}

// The descriptor of a snapshot item's payload; raw frames carry their capture stamps.
Payload snapshotPayload(const PublishedFrame& frame, SnapshotItem item)
{
    if (item == SnapshotItem::Cloud)
        return cloudPayload(frame.result.cloud.size());
    if (item == SnapshotItem::CloudColour)
        return cloudColourPayload(frame.result.cloud_colour.size());
    const SnapshotImage image = snapshotImage(frame, item);
    Payload payload = imagePayload(snapshotItemName(item), image.format, image.mat);
    if (item == SnapshotItem::RawLeft || item == SnapshotItem::RawLeftColour)
        payload.stamp_ns = frame.raw.left_stamp_ns;
    else if (item == SnapshotItem::RawRight || item == SnapshotItem::RawRightColour)
        payload.stamp_ns = frame.raw.right_stamp_ns;
    return payload;
}

} // namespace

void SocketServer::handleRequest(Client& client, std::string_view line)
{
    ParseResult parsed = parseRequest(line);
    if (ProtocolError* error = std::get_if<ProtocolError>(&parsed)) {
        reply(client, errorReply(error->code, error->message, error->id));
        return;
    }
    Request& request = std::get<Request>(parsed);
    try {
        std::visit([&](const auto& command) { handle(client, command, request.id); },
                   request.command);
    } catch (const std::exception& e) {
        replyFailed(client, e, request.id);
    }
}

void SocketServer::replyFailed(Client& client, const std::exception& error,
                               const std::optional<Json>& id)
{
    log_limiter_.log(spdlog::level::err, "client.request_failed", monotonicNowNs(),
                     "client {}: request failed: {}", client.id - kFirstClientTag, error.what());
    reply(client, errorReply(ErrorCode::Internal, error.what(), id));
}

ReadingReport SocketServer::currentReading(const PublishedFrame* latest, double max_age_ms,
                                           const SourceHealth& health, int64_t now_ns) const
{
    ReadingFacts facts = latest != nullptr ? latest->result.facts : ReadingFacts{};
    facts.calibrated = options_.calibrated;
    facts.source_down = health.down;
    if (latest != nullptr) {
        facts.age_ms = static_cast<double>(now_ns - facts.stamp_ns) / 1e6;
        facts.max_age_ms = max_age_ms;
    }
    ReadingReport report;
    report.reading = judgeReading(facts);
    report.has_frame = latest != nullptr;
    if (latest != nullptr)
        report.realtime_offset_ns = latest->realtime_offset_ns;
    if (report.reading.reason == NoReadingReason::SourceDown)
        report.detail = health.message;
    else if (report.reading.reason == NoReadingReason::BadFrame && latest != nullptr)
        report.detail = latest->reason_message.view();
    return report;
}

void SocketServer::handle(Client& client, const HelloRequest&, const std::optional<Json>& id)
{
    Json answer = helloReply(id);
    answer["calibrated"] = options_.calibrated;
    reply(client, answer);
}

void SocketServer::handle(Client& client, const DistanceRequest& request,
                          const std::optional<Json>& id)
{
    const int64_t now_ns = monotonicNowNs();
    const SourceHealth health = backend_.sourceHealth(now_ns);
    const ReadingReport report = currentReading(
        publisher_.latest(), request.max_age_ms.value_or(options_.publish.max_reading_age_ms),
        health, now_ns);
    if (client.dead || dropIfBacklogged(client))
        return;
    // Written directly: `distance` may be polled at a high rate.
    JsonObjectWriter object = openDirectReply(client, id);
    appendReadingJson(object.openField("reading"), report, now_ns);
    object.close();
    client.out.push_back('\n');
}

Json SocketServer::statusNow(int64_t now_ns)
{
    const PublishedFrame* latest = publisher_.latest();
    const SourceHealth health = backend_.sourceHealth(now_ns);
    ServiceStatus status = backend_.serviceStatus(latest, health, now_ns);
    status.clients = counters();
    status.reading = currentReading(latest, options_.publish.max_reading_age_ms, health, now_ns);
    status.now_ns = now_ns;
    status.max_reading_age_ms = options_.publish.max_reading_age_ms;
    return statusToJson(status);
}

void SocketServer::handle(Client& client, const StatusRequest&, const std::optional<Json>& id)
{
    Json answer = okReply(id);
    answer["status"] = statusNow(monotonicNowNs());
    reply(client, answer);
}

void SocketServer::notifyObserverOfStatus(int64_t now_ns)
{
    if (observer_ == nullptr || now_ns - observer_status_ns_ < 1'000'000'000)
        return;
    observer_status_ns_ = now_ns;
    const PublishedFrame* latest = publisher_.latest();
    const SourceHealth health = backend_.sourceHealth(now_ns);
    const ReadingReport report =
        currentReading(latest, options_.publish.max_reading_age_ms, health, now_ns);
    observer_reading_.clear();
    appendReadingJson(observer_reading_, report, now_ns);
    observer_->onStatus(
        statusNow(now_ns).dump(), observer_reading_,
        report.has_frame && latest != nullptr ? latest->realtimeNs(report.reading.stamp_ns) : 0);
}

void SocketServer::handle(Client& client, const SnapshotRequest& request,
                          const std::optional<Json>& id)
{
    const bool wants_raw =
        std::any_of(request.items.begin(), request.items.end(), [](SnapshotItem item) {
            return item == SnapshotItem::RawLeft || item == SnapshotItem::RawRight ||
                   item == SnapshotItem::RawLeftColour || item == SnapshotItem::RawRightColour;
        });
    const int64_t now_ns = monotonicNowNs();
    const PublishedFrame* latest = publisher_.latest();
    if (wants_raw) {
        publisher_.wantRawUntil(now_ns + kRawInterestNs);
        // The newest pair has raw frames only if someone asked for them recently; else
        // the next pair will (answered by serveWaitingSnapshots()).
        if (latest == nullptr || !latest->raw.present) {
            client.waiting = WaitingSnapshot{request, id, now_ns};
            return;
        }
    }
    if (latest == nullptr) {
        reply(client, errorReply(ErrorCode::NotAvailable, "no frame processed yet", id));
        return;
    }
    sendSnapshot(client, request, id, *latest);
}

void SocketServer::sendSnapshot(Client& client, const SnapshotRequest& request,
                                const std::optional<Json>& id, const PublishedFrame& frame)
{
    const PublishedFrame* latest = &frame;
    const int64_t now_ns = monotonicNowNs();
    const DepthResult& result = latest->result;
    const struct {
        const cv::Mat& mat;
        int type;
        const char* name;
    } images[] = {{latest->depth_mm, CV_16UC1, "depth"},
                  {result.disparity, CV_32FC1, "disparity"},
                  {result.left_rectified, CV_8UC1, "left"},
                  {result.left_rectified_colour, CV_8UC3, "left colour"},
                  {latest->raw.left_colour, CV_8UC3, "raw left colour"},
                  {latest->raw.right_colour, CV_8UC3, "raw right colour"}};
    for (const auto& image : images) {
        if (!image.mat.empty() && image.mat.type() != image.type)
            throw std::logic_error(std::string("the ") + image.name +
                                   " image of the result has an unexpected pixel type");
    }

    const SourceHealth health = backend_.sourceHealth(now_ns); // the report borrows its message
    const ReadingReport report =
        currentReading(latest, options_.publish.max_reading_age_ms, health, now_ns);
    const RectifiedGeometry& geometry = options_.geometry;
    Json answer = okReply(id);
    answer["frame"] = result.frame;
    answer["stamp_ns"] = result.stamp_ns;
    answer["stamp_realtime_ns"] = latest->realtimeNs(result.stamp_ns);
    answer["depth_valid"] = latest->depth_valid;
    answer["reading"] = readingToJson(report, now_ns);
    answer["calibration"] = {{"focal_px", geometry.focal_px},
                             {"baseline_m", geometry.baseline_m},
                             {"cx_px", geometry.cx_px},
                             {"cy_px", geometry.cy_px},
                             {"doffs_px", geometry.doffs_px}};
    Json payloads = Json::array();
    for (const SnapshotItem item : request.items)
        payloads.push_back(payloadToJson(snapshotPayload(frame, item)));
    answer["payloads"] = std::move(payloads);
    reply(client, answer);
    if (client.dead)
        return;
    for (const SnapshotItem item : request.items) {
        if (item == SnapshotItem::Cloud) {
            client.out.append(reinterpret_cast<const char*>(result.cloud.data()),
                              result.cloud.size() * sizeof(CloudPoint));
        } else if (item == SnapshotItem::CloudColour) {
            client.out.append(reinterpret_cast<const char*>(result.cloud_colour.data()),
                              result.cloud_colour.size() * sizeof(CloudColour));
        } else {
            const SnapshotImage image = snapshotImage(frame, item);
            if (image.format == kFormatRgb)
                appendBgrAsRgb(client.out, image.mat);
            else
                appendMatBytes(client.out, image.mat);
        }
    }
}

void SocketServer::handle(Client& client, const ReloadRequest&, const std::optional<Json>& id)
{
    const ReloadOutcome outcome = backend_.reload();
    if (!outcome.ok) {
        reply(client, errorReply(outcome.error, outcome.message, id));
        return;
    }
    Json answer = okReply(id);
    answer["changed"] = outcome.changed;
    answer["restart_needed"] = outcome.restart_needed;
    reply(client, answer);
}

void SocketServer::handle(Client& client, const ZonesRequest&, const std::optional<Json>& id)
{
    const int64_t now_ns = monotonicNowNs();
    const PublishedFrame* latest = publisher_.latest();
    if (client.dead || dropIfBacklogged(client))
        return;
    JsonObjectWriter object = openDirectReply(client, id);
    if (latest == nullptr) {
        object.nullField("frame");
        object.openField("zones").append("[]");
    } else {
        object.field("frame", latest->result.frame);
        object.field("stamp_ns", latest->result.stamp_ns);
        object.field("stamp_realtime_ns", latest->realtimeNs(latest->result.stamp_ns));
        object.field("age_ms",
                     roundTo(static_cast<double>(now_ns - latest->result.stamp_ns) / 1e6, 3));
        appendZonesJson(object.openField("zones"), latest->zones);
        appendCameraPoseJson(object.openField("camera_pose"), latest->camera_pose);
        if (options_.calibrated) {
            // What a client needs to draw the zones on the rectified left image.
            JsonObjectWriter camera(object.openField("camera"));
            camera.field("focal_px", options_.geometry.focal_px);
            camera.field("cx_px", options_.geometry.cx_px);
            camera.field("cy_px", options_.geometry.cy_px);
            camera.field("width", options_.geometry.image_size.width);
            camera.field("height", options_.geometry.image_size.height);
            camera.close();
        }
    }
    object.close();
    client.out.push_back('\n');
}

void SocketServer::handle(Client& client, const CalibrationRequest&, const std::optional<Json>& id)
{
    Json answer = okReply(id);
    answer["calibrated"] = options_.calibrated;
    if (options_.calibrated) {
        if (options_.calibration_text.empty()) {
            reply(client, errorReply(ErrorCode::NotAvailable,
                                     "the calibration in force was not read from a file", id));
            return;
        }
        answer["path"] = options_.calibration_path;
        answer["text"] = options_.calibration_text;
    }
    reply(client, answer);
}

void SocketServer::handle(Client& client, const ViewRequest&, const std::optional<Json>& id)
{
    const LiveViewLinks links = backend_.liveViewLinks();
    Json answer = okReply(id);
    answer["listening"] = links.listening;
    answer["listen"] = links.listen;
    if (links.listening) {
        answer["page"] = links.page;
        answer["websocket"] = links.websocket;
    } else {
        answer["error"] = links.error;
    }
    reply(client, answer);
}

} // namespace stereod
