#include <algorithm>
#include <limits>

#include <spdlog/spdlog.h>

#include "capture/frame.hpp"
#include "daemon/image_payload.hpp"
#include "daemon/socket_server.hpp"
#include "protocol/events.hpp"

namespace stereod {

namespace {

// A raw snapshot waits at most this long for a pair with raw frames.
constexpr int64_t kRawSnapshotWaitNs = 5'000'000'000;

} // namespace

void SocketServer::handle(Client& client, const SubscribeRequest& request,
                          const std::optional<Json>& id)
{
    Subscription& subscription = request.stream == StreamKind::Raw     ? client.raw
                                 : request.stream == StreamKind::Depth ? client.depth
                                 : request.stream == StreamKind::Zones ? client.zones
                                                                       : client.readings;
    if (request.stream == StreamKind::Raw)
        publisher_.wantRawUntil(monotonicNowNs() + kRawInterestNs);
    subscription = Subscription{};
    subscription.active = true;
    subscription.max_hz = request.max_hz;
    subscription.last_sequence = last_dispatched_sequence_;
    subscription.with_depth = request.with_depth;
    subscription.with_cloud = request.with_cloud;
    subscription.with_colour = request.with_colour;
    Json answer = okReply(id);
    answer["stream"] = streamName(request.stream);
    reply(client, answer);
}

bool SocketServer::due(Subscription& subscription, double max_hz_config, int64_t now_ns) const
{
    double hz = max_hz_config;
    if (subscription.max_hz)
        hz = hz > 0.0 ? std::min(hz, *subscription.max_hz) : *subscription.max_hz;
    if (hz <= 0.0)
        return true;
    const auto interval_ns = static_cast<int64_t>(1e9 / hz);
    // A frame up to a tenth of the interval early still counts, so that a source at the
    // very rate of the limit is not halved by jitter; the schedule advances by whole
    // intervals, so the mean rate stays at the limit.
    if (now_ns < subscription.next_due_ns - interval_ns / 10)
        return false;
    subscription.next_due_ns += interval_ns;
    if (subscription.next_due_ns <= now_ns)
        subscription.next_due_ns = now_ns + interval_ns;
    return true;
}

void SocketServer::onPublished()
{
    publisher_.clearEvent();
    const PublishedFrame* frame = publisher_.latest();
    if (frame == nullptr || frame->sequence == last_dispatched_sequence_)
        return;
    const int64_t now_ns = monotonicNowNs();
    dispatchFrame(*frame, now_ns);
    last_dispatched_sequence_ = frame->sequence;
    if (observer_ != nullptr) {
        ReadingReport report;
        report.reading = frame->result.reading;
        report.detail = frame->reason_message.view();
        report.realtime_offset_ns = frame->realtime_offset_ns;
        observer_reading_.clear();
        appendReadingJson(observer_reading_, report, now_ns);
        observer_->onFrame(*frame, observer_reading_);
    }
}

void SocketServer::dispatchFrame(const PublishedFrame& frame, int64_t now_ns)
{
    ReadingReport report;
    report.reading = frame.result.reading;
    report.detail = frame.reason_message.view();
    report.realtime_offset_ns = frame.realtime_offset_ns;
    reading_event_.clear();
    depth_header_.clear();
    zones_event_.clear();

    const cv::Mat& depth = frame.depth_mm;
    DepthEventHeader header;
    header.frame = frame.result.frame;
    header.stamp_ns = frame.result.stamp_ns;
    header.stamp_realtime_ns = frame.realtimeNs(frame.result.stamp_ns);
    header.width = depth.empty() ? 0 : depth.cols;
    header.height = depth.empty() ? 0 : depth.rows;
    header.bytes = matBytes(depth);
    header.depth_valid = frame.depth_valid;

    const RawPair& raw = frame.raw;
    raw_header_.clear();
    RawEventHeader raw_header;
    raw_header.frame = frame.result.frame;
    raw_header.left_stamp_ns = raw.left_stamp_ns;
    raw_header.right_stamp_ns = raw.right_stamp_ns;
    raw_header.left_stamp_realtime_ns = frame.realtimeNs(frame.result.stamp_ns);
    raw_header.right_stamp_realtime_ns =
        frame.realtimeNs(saturatingAddNs(frame.result.stamp_ns, frame.skew_ns));
    raw_header.width = raw.left.cols;
    raw_header.height = raw.left.rows;
    const cv::Mat& depth_m = frame.result.depth_m;
    raw_header.depth_valid = frame.depth_valid;
    raw_header.depth_width = depth_m.empty() ? 0 : depth_m.cols;
    raw_header.depth_height = depth_m.empty() ? 0 : depth_m.rows;
    raw_header.cloud_points = frame.result.cloud.size();
    raw_header.left_colour_width = raw.left_colour.cols;
    raw_header.left_colour_height = raw.left_colour.rows;
    raw_header.right_colour_width = raw.right_colour.cols;
    raw_header.right_colour_height = raw.right_colour.rows;
    raw_header.cloud_colour_points = frame.result.cloud_colour.size();

    serveWaitingSnapshots(&frame, nullptr, now_ns);

    for (auto& [id, client] : clients_) {
        if (client.dead || !client.subscribed() || dropIfBacklogged(client))
            continue;
        const bool pending = client.unsent() > 0;
        bool appended = false;
        for (const StreamKind stream :
             {StreamKind::Readings, StreamKind::Depth, StreamKind::Raw, StreamKind::Zones}) {
            const bool is_depth = stream == StreamKind::Depth;
            const bool is_raw = stream == StreamKind::Raw;
            const bool is_zones = stream == StreamKind::Zones;
            Subscription& subscription =
                is_zones ? client.zones
                         : (is_raw ? client.raw : (is_depth ? client.depth : client.readings));
            if (!subscription.active)
                continue;
            // A pair taken before the subscriber's interest reached the worker has no raw
            // frames: it was never available to this stream, so it is not counted lost.
            if (is_raw && !raw.present)
                continue;
            // The raw stream is limited only by the subscriber's own max_hz: a recorder
            // wants every pair.
            const double config_hz = is_raw ? 0.0
                                     : is_depth
                                         ? options_.publish.depth_max_hz
                                         : options_.publish.readings_max_hz; // readings, zones
            // Frames this thread never saw (it was busy) are lost to a stream that wants
            // every frame.
            const bool every_frame = config_hz <= 0.0 && !subscription.max_hz;
            if (every_frame && subscription.last_sequence != 0 &&
                frame.sequence > subscription.last_sequence + 1) {
                const uint64_t lost = frame.sequence - subscription.last_sequence - 1;
                subscription.skipped += lost;
                counters_.frames_dropped += lost;
            }
            subscription.last_sequence = frame.sequence;
            if (!due(subscription, config_hz, now_ns))
                continue;
            if (pending) {
                ++subscription.skipped;
                ++counters_.frames_dropped;
                continue;
            }
            compactOut(client);
            if (is_zones) {
                if (subscription.skipped > 0) {
                    appendZonesEvent(client.out, frame.zones, frame.result.frame,
                                     frame.result.stamp_ns, header.stamp_realtime_ns, now_ns,
                                     subscription.skipped);
                } else {
                    if (zones_event_.empty())
                        appendZonesEvent(zones_event_, frame.zones, frame.result.frame,
                                         frame.result.stamp_ns, header.stamp_realtime_ns, now_ns,
                                         0);
                    client.out.append(zones_event_);
                }
            } else if (is_raw) {
                const bool with =
                    subscription.with_depth || subscription.with_cloud || subscription.with_colour;
                if (subscription.skipped > 0 || with) {
                    appendRawEventHeader(client.out, raw_header, subscription.skipped,
                                         subscription.with_depth, subscription.with_cloud,
                                         subscription.with_colour);
                } else {
                    if (raw_header_.empty())
                        appendRawEventHeader(raw_header_, raw_header, 0);
                    client.out.append(raw_header_);
                }
                appendMatBytes(client.out, raw.left);
                appendMatBytes(client.out, raw.right);
                if (subscription.with_colour) {
                    appendBgrAsRgb(client.out, raw.left_colour);
                    appendBgrAsRgb(client.out, raw.right_colour);
                }
                if (subscription.with_depth)
                    appendMatBytes(client.out, depth_m);
                if (subscription.with_cloud)
                    client.out.append(reinterpret_cast<const char*>(frame.result.cloud.data()),
                                      frame.result.cloud.size() * sizeof(CloudPoint));
                if (subscription.with_cloud && subscription.with_colour)
                    client.out.append(
                        reinterpret_cast<const char*>(frame.result.cloud_colour.data()),
                        frame.result.cloud_colour.size() * sizeof(CloudColour));
            } else if (!is_depth) {
                if (subscription.skipped > 0) {
                    appendReadingEvent(client.out, report, now_ns, subscription.skipped);
                } else {
                    if (reading_event_.empty())
                        appendReadingEvent(reading_event_, report, now_ns, 0);
                    client.out.append(reading_event_);
                }
            } else {
                if (subscription.skipped > 0) {
                    appendDepthEventHeader(client.out, header, report, now_ns,
                                           subscription.skipped);
                } else {
                    if (depth_header_.empty())
                        appendDepthEventHeader(depth_header_, header, report, now_ns, 0);
                    client.out.append(depth_header_);
                }
                appendMatBytes(client.out, depth);
            }
            subscription.skipped = 0;
            appended = true;
        }
        if (appended)
            writeClient(client);
    }
}

void SocketServer::broadcastSourceDown(const SourceHealth& health, int64_t now_ns)
{
    const ReadingReport report = currentReading(
        publisher_.latest(), std::numeric_limits<double>::infinity(), health, now_ns);
    for (auto& [id, client] : clients_) {
        if (client.dead || !client.readings.active || dropIfBacklogged(client))
            continue;
        if (client.unsent() > 0) {
            ++client.readings.skipped;
            ++counters_.frames_dropped;
            continue;
        }
        compactOut(client);
        appendReadingEvent(client.out, report, now_ns, client.readings.skipped);
        client.readings.skipped = 0;
        writeClient(client);
    }
}

void SocketServer::refreshRawInterest(int64_t now_ns)
{
    for (const auto& [id, client] : clients_) {
        if (!client.dead && client.raw.active) {
            publisher_.wantRawUntil(now_ns + kRawInterestNs);
            return;
        }
    }
}

void SocketServer::serveWaitingSnapshots(const PublishedFrame* frame, const SourceHealth* health,
                                         int64_t now_ns)
{
    for (auto& [id, client] : clients_) {
        if (client.dead || !client.waiting)
            continue;
        if (frame != nullptr && frame->raw.present) {
            finishWaiting(client, frame, {});
        } else if (health != nullptr && health->down) {
            finishWaiting(client, nullptr,
                          "no raw frames: " + std::string(reasonText(NoReadingReason::SourceDown)) +
                              ": " + health->message);
        } else if (now_ns - client.waiting->since_ns > kRawSnapshotWaitNs) {
            finishWaiting(client, nullptr,
                          "no raw frames: no pair arrived within " +
                              std::to_string(kRawSnapshotWaitNs / 1'000'000'000) + " s");
        }
    }
}

void SocketServer::finishWaiting(Client& client, const PublishedFrame* frame,
                                 std::string_view error)
{
    const WaitingSnapshot waiting = std::move(*client.waiting);
    client.waiting.reset();
    try {
        if (frame != nullptr)
            sendSnapshot(client, waiting.request, waiting.id, *frame);
        else
            reply(client, errorReply(ErrorCode::NotAvailable, error, waiting.id));
    } catch (const std::exception& e) {
        replyFailed(client, e, waiting.id);
    }
    if (client.dead)
        return;
    if (client.input_closed) {
        // The peer closed its side while its snapshot waited: serve what it sent last.
        while (!client.dead && !client.waiting && !client.in.empty()) {
            const std::size_t newline = client.in.find('\n');
            const std::string line = client.in.substr(0, newline);
            client.in.erase(0, newline == std::string::npos ? client.in.size() : newline + 1);
            if (line.size() < options_.socket.max_request_bytes)
                handleRequest(client, line);
        }
        if (!client.dead && !client.subscribed() && !client.waiting)
            client.close_when_flushed = true;
    } else {
        handleLines(client);
    }
    if (!client.dead)
        writeClient(client);
}

} // namespace stereod
