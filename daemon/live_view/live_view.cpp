#include "daemon/live_view/live_view.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

#include <spdlog/spdlog.h>
#include <unistd.h>

#include "base/clock.hpp"
#include "config/service_config.hpp"
#include "daemon/live_view/admission.hpp"
#include "protocol/json_writer.hpp"
#include "protocol/reading_json.hpp"
#include "ros2/conventions.hpp"
#include "ros2/messages.hpp"

namespace stereod::live_view {

namespace {

using ros2::kLeftOpticalFrame;
using ros2::kRightOpticalFrame;

// The JSON schema of /stereo/nearest: the reading object of docs/protocol.md.
const char* kReadingSchema =
    R"({"type":"object","title":"stereod reading",)"
    R"("description":"The reading object of stereod's protocol (docs/protocol.md): valid with )"
    R"(distance_m, or not valid with reason.",)"
    R"("properties":{)"
    R"("valid":{"type":"boolean"},)"
    R"("distance_m":{"type":["number","null"],"description":"metres; null without a reading"},)"
    R"("stamp_ns":{"type":"integer","description":"capture time, CLOCK_MONOTONIC ns"},)"
    R"("stamp_realtime_ns":{"type":"integer","description":"capture time, CLOCK_REALTIME ns"},)"
    R"("age_ms":{"type":"number"},)"
    R"("frame":{"type":"integer"},)"
    R"("valid_fraction":{"type":"number"},)"
    R"("in_range_fraction":{"type":"number"},)"
    R"("region_pixels":{"type":"integer"},)"
    R"("range_limit_fraction":{"type":"number","description":"share of the region with )"
    R"(evidence of a surface nearer than the range"},)"
    R"("inferred_fraction":{"type":"number","description":"share of the region without a )"
    R"(measured depth, counted at the nearest other evidence says it may be"},)"
    R"("out_of_view_fraction":{"type":"number","description":"share of the region whose )"
    R"(columns cannot see as near as the distance: the image's left edge cuts their view"},)"
    R"("closest_m":{"type":"number","description":"the closest depth the matcher measures"},)"
    R"("near_field_guard":{"type":"boolean","description":"whether the matcher looks for )"
    R"(surfaces nearer than its range"},)"
    R"("calibration_suspect":{"type":"boolean","description":"the calibration health check )"
    R"(fails: the distance may be wrong"},)"
    R"("calibration_row_offset_px":{"type":"number"},)"
    R"("nearer_than_m":{"type":"number"},)"
    R"("reason":{"type":"object","properties":{"code":{"type":"string"},)"
    R"("message":{"type":"string"}},"required":["code","message"]}},)"
    R"("required":["valid","distance_m","frame"]})";
const char* kStatusSchema = R"({"type":"object","title":"stereod status",)"
                            R"("description":"What stereoctl status --json prints."})";
// The JSON schema of /stereo/zones: the zones of a pair, as the `zones` request answers.
const char* kZonesSchema =
    R"({"type":"object","title":"stereod zones",)"
    R"("description":"The keep-out zones of one pair (docs/protocol.md, zones).",)"
    R"("properties":{"frame":{"type":"integer"},"stamp_ns":{"type":"integer"},)"
    R"("stamp_realtime_ns":{"type":"integer"},)"
    R"("zones":{"type":"array","items":{"type":"object","properties":{)"
    R"("name":{"type":"string"},"state":{"type":"string"},"reason":{"type":"string"},)"
    R"("points":{"type":"integer"},"nearest_m":{"type":"number"},)"
    R"("visible_fraction":{"type":"number"}}}}},"required":["frame","zones"]})";

std::string contentType(const std::string& path)
{
    const auto ends = [&path](const char* suffix) {
        const std::string s(suffix);
        return path.size() >= s.size() && path.compare(path.size() - s.size(), s.size(), s) == 0;
    };
    if (ends(".html"))
        return "text/html; charset=utf-8";
    if (ends(".js") || ends(".mjs"))
        return "text/javascript; charset=utf-8";
    if (ends(".css"))
        return "text/css; charset=utf-8";
    if (ends(".png"))
        return "image/png";
    if (ends(".svg"))
        return "image/svg+xml";
    return "application/octet-stream";
}

// A request path we serve: letters, digits, '.', '-', '_' and '/', no "..".
bool safePath(const std::string& path)
{
    if (path.find("..") != std::string::npos)
        return false;
    for (const char c : path) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                        (c >= '0' && c <= '9') || c == '.' || c == '-' || c == '_' || c == '/';
        if (!ok)
            return false;
    }
    return true;
}

HttpResponse notFound(const std::string& path)
{
    return HttpResponse{404, "text/plain; charset=utf-8", "not found: " + path + "\n"};
}

} // namespace

const std::vector<ChannelSpec>& channelSpecs()
{
    static const std::vector<ChannelSpec> specs = {
        {kLeftImage, "/stereo/left/image_rect", "cdr", ros2::kImageType, ros2::imageSchemaText(),
         "ros2msg"},
        {kDepth, "/stereo/depth", "cdr", ros2::kImageType, ros2::imageSchemaText(), "ros2msg"},
        {kDisparity, "/stereo/disparity", "cdr", ros2::kDisparityImageType,
         ros2::disparityImageSchemaText(), "ros2msg"},
        {kConfidence, "/stereo/confidence", "cdr", ros2::kImageType, ros2::imageSchemaText(),
         "ros2msg"},
        {kPoints, "/stereo/points", "cdr", ros2::kPointCloud2Type, ros2::pointCloud2SchemaText(),
         "ros2msg"},
        {kLeftInfo, "/stereo/left/camera_info", "cdr", ros2::kCameraInfoType,
         ros2::cameraInfoSchemaText(), "ros2msg"},
        {kRightInfo, "/stereo/right/camera_info", "cdr", ros2::kCameraInfoType,
         ros2::cameraInfoSchemaText(), "ros2msg"},
        {kNearest, "/stereo/nearest", "json", "stereod.Reading", kReadingSchema, "jsonschema"},
        {kStatus, "/stereo/status", "json", "stereod.Status", kStatusSchema, "jsonschema"},
        {kZones, "/stereo/zones", "json", "stereod.Zones", kZonesSchema, "jsonschema"},
    };
    return specs;
}

// One WebSocket client: its subscriptions, the frames waiting for its socket, and whether
// it reads.
struct LiveView::Client {
    std::map<uint32_t, Channel> subscriptions; // subscription id -> channel
    // Per frame channel, the newest message not handed to the socket yet (subscription id
    // 0: patched per subscription on the way out), and when it came (to keep their order).
    std::array<std::shared_ptr<std::string>, kChannelEnd> waiting{};
    std::array<uint64_t, kChannelEnd> waiting_since{};
    // What the socket held unsent after our last send: it read something when it holds less.
    std::size_t buffered_after_send = 0;
    int64_t stalled_since_ns = 0; // 0: reading
    bool closing = false;         // closed for being stuck; gone soon
};

// The clients, on the transport's thread only.
struct LiveView::Sessions {
    std::map<WebSocketTransport::ConnectionId, Client> clients;
};

LiveView::LiveView(LiveViewSettings settings, RectifiedGeometry geometry)
    : settings_(std::move(settings)), sessions_(std::make_unique<Sessions>()), geometry_(geometry)
{
    address_ = formatListenAddress(settings_.host, settings_.port);
    WebSocketTransport::Handlers handlers;
    handlers.opened = [this](WebSocketTransport::ConnectionId id) {
        sessions_->clients[id] = Client{};
        clients_.store(sessions_->clients.size(), std::memory_order_relaxed);
        transport_->sendText(id, serverInfoJson("stereod", std::to_string(::getpid())));
        transport_->sendText(id, advertiseJson(channelSpecs()));
    };
    handlers.closed = [this](WebSocketTransport::ConnectionId id) {
        const auto it = sessions_->clients.find(id);
        if (it == sessions_->clients.end())
            return;
        for (const auto& [sub, channel] : it->second.subscriptions)
            subscribers_[channel].fetch_sub(1, std::memory_order_relaxed);
        sessions_->clients.erase(it);
        clients_.store(sessions_->clients.size(), std::memory_order_relaxed);
    };
    handlers.text = [this](WebSocketTransport::ConnectionId id, const std::string& text) {
        Client& client = sessions_->clients[id];
        const ClientRequest request = parseClientMessage(text);
        switch (request.kind) {
        case ClientRequest::Kind::Subscribe: {
            // One subscription per channel and client: a client cannot make the service
            // hold ids without end, nor send it one frame many times over.
            std::string refused;
            std::size_t refusals = 0;
            for (const auto& [sub, channel] : request.subscriptions) {
                std::string why;
                const uint32_t wanted = channel; // a structured binding no lambda may capture
                if (channel < kLeftImage || channel >= kChannelEnd) {
                    why = "no channel " + std::to_string(channel);
                } else if (client.subscriptions.count(sub) != 0) {
                    continue; // the same id twice: already subscribed
                } else if (const auto taken = std::find_if(
                               client.subscriptions.begin(), client.subscriptions.end(),
                               [wanted](const auto& s) { return s.second == wanted; });
                           taken != client.subscriptions.end()) {
                    why = "channel " + std::to_string(channel) + " is subscribed already, as " +
                          std::to_string(taken->first);
                } else {
                    client.subscriptions[sub] = static_cast<Channel>(channel);
                    subscribers_[channel].fetch_add(1, std::memory_order_relaxed);
                    continue;
                }
                if (refusals++ == 0)
                    refused = why;
            }
            if (refusals > 0)
                transport_->sendReply(
                    id,
                    statusJson(2, "subscribe: " + refused +
                                      (refusals > 1 ? " (and " + std::to_string(refusals - 1) +
                                                          " more refused)"
                                                    : std::string())),
                    replyBacklogAllowed(client));
            break;
        }
        case ClientRequest::Kind::Unsubscribe:
            for (const uint32_t sub : request.unsubscriptions) {
                const auto it = client.subscriptions.find(sub);
                if (it == client.subscriptions.end())
                    continue;
                subscribers_[it->second].fetch_sub(1, std::memory_order_relaxed);
                client.subscriptions.erase(it);
            }
            break;
        case ClientRequest::Kind::Ignored:
        case ClientRequest::Kind::Invalid:
            transport_->sendReply(
                id,
                statusJson(request.kind == ClientRequest::Kind::Invalid ? 2 : 1, request.problem),
                replyBacklogAllowed(client));
            break;
        }
    };
    handlers.http = [this](const std::string& path) { return serveFile(path); };
    transport_ = std::make_unique<WebSocketTransport>(std::move(handlers));
}

LiveView::~LiveView()
{
    stop();
}

std::string LiveView::start()
{
    if (settings_.token.empty())
        settings_.token = newToken();
    TransportLimits limits;
    limits.token = settings_.token;
    limits.allowed_origins = settings_.allowed_origins;
    limits.max_clients = settings_.max_clients;
    limits.max_connections = settings_.max_connections;
    error_ = transport_->start(settings_.host, settings_.port, kSubprotocol, std::move(limits));
    if (!error_.empty())
        return error_;
    address_ = formatListenAddress(settings_.host, transport_->port());
    listening_.store(true, std::memory_order_release);
    feed_thread_ = std::thread([this] { feed(); });
    return {};
}

void LiveView::stop()
{
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    if (feed_thread_.joinable())
        feed_thread_.join();
    transport_->stop();
    listening_.store(false, std::memory_order_release);
}

uint16_t LiveView::port() const noexcept
{
    return transport_->port();
}

void LiveView::sendJson(Channel channel, int64_t log_time_ns, std::string_view text, int64_t now_ns)
{
    if (!subscribed(channel))
        return;
    // kZones follows kNearest's rate: the zones come with the reading.
    const double hz = settings_.rate_hz[channel];
    if (hz > 0 && channel != kStatus) {
        const auto interval_ns = static_cast<int64_t>(1e9 / hz);
        // A reading a little early (capture jitter) still goes, as in feed().
        if (now_ns - json_sent_ns_[channel] < interval_ns - interval_ns / 5)
            return;
        json_sent_ns_[channel] = now_ns;
    }
    send(channel, log_time_ns, text);
}

void LiveView::onFrame(const PublishedFrame& frame, std::string_view reading_json)
{
    last_frame_ns_ = monotonicNowNs();
    if (!listening_.load(std::memory_order_acquire) ||
        clients_.load(std::memory_order_relaxed) == 0)
        return;
    const DepthResult& r = frame.result;
    const int64_t stamp_ns = frame.realtimeNs(r.stamp_ns);
    // Readings first: on their way before the images are even copied.
    sendJson(kNearest, stamp_ns, reading_json, last_frame_ns_);
    if (subscribed(kZones)) {
        zones_json_.clear();
        JsonObjectWriter object(zones_json_);
        object.field("frame", r.frame);
        object.field("stamp_ns", r.stamp_ns);
        object.field("stamp_realtime_ns", stamp_ns);
        appendZonesJson(object.openField("zones"), frame.zones);
        object.close();
        sendJson(kZones, stamp_ns, zones_json_, last_frame_ns_);
    }
    {
        std::lock_guard lock(mutex_);
        Mailbox& m = mailbox_;
        m.frame = true;
        m.stamp_ns = stamp_ns;
        for (const Channel channel : {kLeftImage, kDepth, kConfidence, kDisparity, kPoints})
            m.taken[channel] = subscribed(channel);
        if (m.taken[kLeftImage])
            m.left_encoding = ros2::leftImageForRos(r, m.left);
        if (m.taken[kDepth])
            ros2::copyTrustedDepth(r, frame.depth_valid, m.depth_m);
        if (m.taken[kConfidence])
            r.confidence.copyTo(m.confidence);
        if (m.taken[kDisparity])
            r.disparity.copyTo(m.disparity);
        m.min_disparity = static_cast<float>(frame.stats.range.min_disparity);
        m.max_disparity =
            static_cast<float>(frame.stats.range.min_disparity + frame.stats.range.num_disparities);
        m.cloud.clear();
        m.cloud_colour.clear();
        m.points_in_colour = !r.left_rectified_colour.empty();
        if (m.taken[kPoints] && frame.depth_valid)
            ros2::subsampleCloud(r, settings_.points_step, m.cloud, m.cloud_colour);
    }
    wake_.notify_one();
}

void LiveView::onStatus(std::string_view status_json, std::string_view reading_json,
                        int64_t reading_realtime_ns)
{
    if (!listening_.load(std::memory_order_acquire) ||
        clients_.load(std::memory_order_relaxed) == 0)
        return;
    const int64_t now_ns = monotonicNowNs();
    // The status is of now: logged at the wall clock's now.
    sendJson(kStatus, saturatingAddNs(now_ns, realtimeOffsetNs()), status_json, now_ns);
    // No frame for a second: the reading says why (source down, stale).
    if (now_ns - last_frame_ns_ > 1'000'000'000)
        sendJson(kNearest, reading_realtime_ns, reading_json, now_ns);
}

void LiveView::feed()
{
    Mailbox work;
    std::string message;
    std::vector<float> depth_nan;
    std::vector<float> disparity_ros;
    std::vector<float> cloud_rgb;
    // Per channel: the least time between two messages, and when the last one went.
    std::array<int64_t, kChannelEnd> interval_ns{};
    std::array<int64_t, kChannelEnd> last_sent_ns{};
    for (uint32_t c = kLeftImage; c < kChannelEnd; ++c) {
        const double hz = settings_.rate_hz[c] > 0 ? settings_.rate_hz[c] : settings_.max_rate_hz;
        interval_ns[c] = hz > 0 ? static_cast<int64_t>(1e9 / hz) : 0;
    }
    int64_t now_ns = 0;
    // A frame a little early (capture jitter) still goes: otherwise a camera at exactly
    // a channel's rate would lose every other frame it sends a hair early.
    const auto due = [&](Channel channel) {
        if (!subscribed(channel) ||
            now_ns - last_sent_ns[channel] < interval_ns[channel] - interval_ns[channel] / 5)
            return false;
        last_sent_ns[channel] = now_ns;
        return true;
    };
    // A frame channel whose part of this frame was taken, when it is due.
    const auto fresh = [&](Channel channel) { return work.taken[channel] && due(channel); };
    int64_t last_pump_ns = 0;
    RectifiedGeometry geometry; // the mailbox's, with each frame
    while (true) {
        {
            std::unique_lock lock(mutex_);
            // While clients are connected, their waiting frames are offered to their
            // sockets every kPumpIntervalMs even when nothing new comes.
            const auto ready = [this] { return stopping_ || mailbox_.frame; };
            if (clients_.load(std::memory_order_relaxed) > 0)
                wake_.wait_for(lock, std::chrono::milliseconds(kPumpIntervalMs), ready);
            else
                wake_.wait(lock, ready);
            if (stopping_)
                return;
            // The buffers swap: the mailbox gets the ones this thread is done with, which
            // the next result is copied into without allocating.
            work.frame = mailbox_.frame;
            if (mailbox_.frame) {
                std::swap(work.left, mailbox_.left);
                std::swap(work.depth_m, mailbox_.depth_m);
                std::swap(work.confidence, mailbox_.confidence);
                std::swap(work.disparity, mailbox_.disparity);
                work.taken = mailbox_.taken;
                work.points_in_colour = mailbox_.points_in_colour;
                std::swap(work.cloud, mailbox_.cloud);
                std::swap(work.cloud_colour, mailbox_.cloud_colour);
                work.left_encoding = mailbox_.left_encoding;
                work.stamp_ns = mailbox_.stamp_ns;
                geometry = geometry_;
                work.min_disparity = mailbox_.min_disparity;
                work.max_disparity = mailbox_.max_disparity;
                mailbox_.frame = false;
            }
        }
        now_ns = monotonicNowNs();
        if (work.frame) {
            const int64_t t = work.stamp_ns;
            const ros2::Header left_header{ros2::Time::fromNs(t), kLeftOpticalFrame};
            if (!work.left.empty() && fresh(kLeftImage)) {
                const auto step = static_cast<uint32_t>(work.left.cols * work.left.elemSize());
                ros2::serializeImage(left_header, work.left.rows, work.left.cols,
                                     work.left_encoding, step, work.left.data,
                                     work.left.total() * work.left.elemSize(), message);
                send(kLeftImage, t, message);
            }
            if (!work.depth_m.empty() && fresh(kDepth)) {
                ros2::depthWithNan(work.depth_m, depth_nan);
                ros2::serializeImage(left_header, work.depth_m.rows, work.depth_m.cols, "32FC1",
                                     work.depth_m.cols * 4, depth_nan.data(), depth_nan.size() * 4,
                                     message);
                send(kDepth, t, message);
            }
            if (!work.confidence.empty() && fresh(kConfidence)) {
                ros2::serializeImage(left_header, work.confidence.rows, work.confidence.cols,
                                     "mono8", work.confidence.cols, work.confidence.data,
                                     work.confidence.total(), message);
                send(kConfidence, t, message);
            }
            if (!work.disparity.empty() && fresh(kDisparity)) {
                ros2::disparityForRos(work.disparity, work.min_disparity, disparity_ros);
                ros2::DisparityImage image;
                image.header = left_header;
                image.height = work.disparity.rows;
                image.width = work.disparity.cols;
                image.f = static_cast<float>(geometry.focal_px);
                image.t = static_cast<float>(geometry.baseline_m);
                image.valid_window = {0, 0, image.height, image.width, false};
                image.min_disparity = work.min_disparity;
                image.max_disparity = work.max_disparity;
                image.delta_d = 1.0f / 16.0f;
                ros2::serializeDisparityImage(image, disparity_ros.data(), disparity_ros.size() * 4,
                                              message);
                send(kDisparity, t, message);
            }
            if (fresh(kPoints)) {
                static_assert(sizeof(CloudPoint) == 4 * sizeof(float));
                if (work.points_in_colour && work.cloud_colour.size() == work.cloud.size()) {
                    ros2::xyziRgbCloud(work.cloud, work.cloud_colour, cloud_rgb);
                    ros2::serializeXyziRgbCloud(left_header, cloud_rgb.data(), work.cloud.size(),
                                                message);
                } else {
                    ros2::serializeXyziCloud(left_header,
                                             reinterpret_cast<const float*>(work.cloud.data()),
                                             work.cloud.size(), message);
                }
                send(kPoints, t, message);
            }
            for (const bool right : {false, true}) {
                const Channel channel = right ? kRightInfo : kLeftInfo;
                if (!due(channel))
                    continue;
                ros2::serializeCameraInfo(ros2::rectifiedCameraInfo(geometry, right, t), message);
                send(channel, t, message);
            }
            work.frame = false;
        }
        if (now_ns - last_pump_ns >= kPumpIntervalMs * 1'000'000) {
            last_pump_ns = now_ns;
            pumpAll();
        }
    }
}

void LiveView::send(Channel channel, int64_t log_time_ns, std::string_view payload)
{
    // Framed once; each client's copy differs only in its subscription id, patched in
    // before the transport copies the frame out.
    auto frame = std::make_shared<std::string>();
    appendMessageData(0, static_cast<uint64_t>(log_time_ns), payload, *frame);
    transport_->post([this, channel, frame] {
        const int64_t now_ns = monotonicNowNs();
        for (auto& [id, client] : sessions_->clients) {
            bool wanted = false;
            for (const auto& [sub, subscribed_channel] : client.subscriptions)
                wanted = wanted || subscribed_channel == channel;
            if (!wanted || !stillReading(id, client, now_ns))
                continue;
            if (isPriorityChannel(channel)) {
                sendTo(id, client, channel, *frame);
            } else {
                // Waits for room in the client's socket; a frame still waiting is
                // replaced, and keeps its place in the order.
                if (client.waiting[channel])
                    frames_dropped_.fetch_add(1, std::memory_order_relaxed);
                else
                    client.waiting_since[channel] = ++waiting_sequence_;
                client.waiting[channel] = frame;
            }
            handOverFrames(id, client);
        }
    });
}

bool LiveView::stillReading(WebSocketTransport::ConnectionId id, Client& client, int64_t now_ns)
{
    if (client.closing)
        return false;
    const std::size_t buffered = transport_->buffered(id);
    // Reading: the socket took bytes since our last send, or holds nothing.
    if (buffered == 0 || buffered < client.buffered_after_send) {
        client.stalled_since_ns = 0;
        client.buffered_after_send = buffered;
        return true;
    }
    if (client.stalled_since_ns == 0) {
        client.stalled_since_ns = now_ns;
        return true;
    }
    if (now_ns - client.stalled_since_ns <= kStuckMs * 1'000'000)
        return true;
    client.closing = true;
    for (auto& waiting : client.waiting) {
        if (waiting) {
            waiting.reset();
            frames_dropped_.fetch_add(1, std::memory_order_relaxed);
        }
    }
    clients_dropped_.fetch_add(1, std::memory_order_relaxed);
    spdlog::warn("live view: closing a client that has not read for {} s", kStuckMs / 1000);
    transport_->close(id, "too slow: not reading");
    return false;
}

void LiveView::sendTo(WebSocketTransport::ConnectionId id, Client& client, Channel channel,
                      std::string& frame)
{
    for (const auto& [sub, subscribed_channel] : client.subscriptions) {
        if (subscribed_channel != channel)
            continue;
        setSubscriptionId(frame, sub);
        if (transport_->sendBinary(id, frame)) {
            messages_.fetch_add(1, std::memory_order_relaxed);
            bytes_.fetch_add(frame.size(), std::memory_order_relaxed);
            if (channel == kNearest)
                readings_sent_.fetch_add(1, std::memory_order_relaxed);
        }
    }
    client.buffered_after_send = transport_->buffered(id);
}

std::size_t LiveView::replyBacklogAllowed(const Client& client)
{
    return std::max(kFrameBudgetBytes, client.buffered_after_send) + (std::size_t{1} << 20);
}

void LiveView::handOverFrames(WebSocketTransport::ConnectionId id, Client& client)
{
    while (client.buffered_after_send < kFrameBudgetBytes) {
        // The frame that has waited longest goes first.
        Channel next = kChannelEnd;
        for (uint32_t c = kLeftImage; c < kChannelEnd; ++c)
            if (client.waiting[c] &&
                (next == kChannelEnd || client.waiting_since[c] < client.waiting_since[next]))
                next = static_cast<Channel>(c);
        if (next == kChannelEnd)
            return;
        const std::shared_ptr<std::string> frame = std::move(client.waiting[next]);
        client.waiting[next].reset();
        sendTo(id, client, next, *frame);
    }
}

void LiveView::pumpAll()
{
    transport_->post([this] {
        const int64_t now_ns = monotonicNowNs();
        for (auto& [id, client] : sessions_->clients)
            if (stillReading(id, client, now_ns))
                handOverFrames(id, client);
    });
}

HttpResponse LiveView::serveFile(const std::string& request) const
{
    std::string path = request.substr(0, request.find('?'));
    if (path.empty() || path.front() != '/' || !safePath(path))
        return HttpResponse{400, "text/plain; charset=utf-8", "bad path\n"};
    if (path == "/")
        path = "/index.html";
    std::string file;
    if (path.rfind("/three/", 0) == 0)
        file = settings_.three_root + path.substr(6);
    else
        file = settings_.web_root + path;
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec))
        return notFound(path);
    std::ifstream in(file, std::ios::binary);
    std::ostringstream body;
    body << in.rdbuf();
    return HttpResponse{200, contentType(file), body.str()};
}

void LiveView::setGeometry(const RectifiedGeometry& geometry)
{
    std::lock_guard lock(mutex_);
    geometry_ = geometry;
}

StatusLiveView LiveView::status() const
{
    StatusLiveView c;
    c.listening = listening_.load(std::memory_order_acquire);
    c.listen = address_;
    c.error = error_;
    c.clients = clients_.load(std::memory_order_relaxed);
    c.messages_sent = messages_.load(std::memory_order_relaxed);
    c.bytes_sent = bytes_.load(std::memory_order_relaxed);
    c.frames_dropped = frames_dropped_.load(std::memory_order_relaxed);
    c.clients_dropped =
        clients_dropped_.load(std::memory_order_relaxed) + transport_->closedForReplies();
    c.readings_sent = readings_sent_.load(std::memory_order_relaxed);
    c.refused = transport_->refused();
    return c;
}

} // namespace stereod::live_view
