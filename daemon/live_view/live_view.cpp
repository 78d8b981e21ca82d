#include "daemon/live_view/live_view.hpp"

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
#include "ros2/conventions.hpp"
#include "ros2/messages.hpp"

namespace stereod::live_view {

namespace {

using ros2::kLeftOpticalFrame;
using ros2::kRightOpticalFrame;

// The JSON schema of /stereo/nearest: the reading object of docs/protocol.md.
const char* kReadingSchema = R"({"type":"object","title":"stereod reading",)"
                             R"("description":"The reading object of stereod's protocol: )"
                             R"(valid with distance_m, or not valid with reason.",)"
                             R"("properties":{"valid":{"type":"boolean"},)"
                             R"("distance_m":{"type":"number"},"reason":{"type":"string"},)"
                             R"("message":{"type":"string"},"stamp_ns":{"type":"integer"},)"
                             R"("age_ms":{"type":"number"}},"required":["valid"]})";
const char* kStatusSchema = R"({"type":"object","title":"stereod status",)"
                            R"("description":"What stereoctl status --json prints."})";

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
    };
    return specs;
}

// One WebSocket client: its subscriptions, and since when it has been too slow.
struct LiveView::Client {
    std::map<uint32_t, Channel> subscriptions; // subscription id -> channel
    int64_t lagging_since_ns = 0;              // 0: keeping up
    bool closing = false;                      // closed for being stuck; gone soon
};

// The clients, on the transport's thread only.
struct LiveView::Sessions {
    std::map<WebSocketTransport::ConnectionId, Client> clients;
};

LiveView::LiveView(LiveViewSettings settings, RectifiedGeometry geometry)
    : settings_(std::move(settings)), geometry_(geometry), sessions_(std::make_unique<Sessions>())
{
    address_ = settings_.host + ":" + std::to_string(settings_.port);
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
        case ClientRequest::Kind::Subscribe:
            for (const auto& [sub, channel] : request.subscriptions) {
                if (channel < kLeftImage || channel >= kChannelEnd) {
                    transport_->sendText(
                        id, statusJson(2, "subscribe: no channel " + std::to_string(channel)));
                    continue;
                }
                if (client.subscriptions.count(sub) != 0)
                    continue; // the same id twice: already subscribed
                client.subscriptions[sub] = static_cast<Channel>(channel);
                subscribers_[channel].fetch_add(1, std::memory_order_relaxed);
            }
            break;
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
            transport_->sendText(
                id,
                statusJson(request.kind == ClientRequest::Kind::Invalid ? 2 : 1, request.problem));
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
    error_ = transport_->start(settings_.host, settings_.port, kSubprotocol);
    if (!error_.empty())
        return error_;
    address_ = settings_.host + ":" + std::to_string(transport_->port());
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

void LiveView::onFrame(const PublishedFrame& frame, std::string_view reading_json)
{
    if (!listening_.load(std::memory_order_acquire) ||
        clients_.load(std::memory_order_relaxed) == 0)
        return;
    const DepthResult& r = frame.result;
    {
        std::lock_guard lock(mutex_);
        Mailbox& m = mailbox_;
        m.frame = true;
        m.stamp_ns = r.stamp_ns;
        if (subscribed(kLeftImage))
            r.left_rectified.copyTo(m.left);
        if (subscribed(kDepth))
            ros2::copyTrustedDepth(r, frame.depth_valid, m.depth_m);
        if (subscribed(kConfidence))
            r.confidence.copyTo(m.confidence);
        if (subscribed(kDisparity))
            r.disparity.copyTo(m.disparity);
        m.min_disparity = static_cast<float>(frame.stats.range.min_disparity);
        m.max_disparity =
            static_cast<float>(frame.stats.range.min_disparity + frame.stats.range.num_disparities);
        m.cloud.clear();
        if (subscribed(kPoints) && frame.depth_valid) {
            const auto step = static_cast<std::size_t>(std::max(1, settings_.points_step));
            for (std::size_t i = 0; i < r.cloud.size(); i += step)
                m.cloud.push_back(r.cloud[i]);
        }
        m.reading_json.assign(reading_json);
    }
    wake_.notify_one();
}

void LiveView::onStatus(std::string_view status_json, std::string_view reading_json,
                        int64_t reading_stamp_ns)
{
    if (!listening_.load(std::memory_order_acquire) ||
        clients_.load(std::memory_order_relaxed) == 0)
        return;
    {
        std::lock_guard lock(mutex_);
        mailbox_.status = true;
        mailbox_.status_json.assign(status_json);
        mailbox_.status_reading_json.assign(reading_json);
        mailbox_.status_reading_stamp_ns = reading_stamp_ns;
    }
    wake_.notify_one();
}

void LiveView::feed()
{
    Mailbox work;
    std::string message;
    std::vector<float> depth_nan;
    std::vector<float> disparity_ros;
    int64_t last_frame_ns = 0;
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
    while (true) {
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [this] { return stopping_ || mailbox_.frame || mailbox_.status; });
            if (stopping_)
                return;
            std::swap(work, mailbox_);
            mailbox_.frame = false;
            mailbox_.status = false;
        }
        now_ns = monotonicNowNs();
        if (work.frame) {
            last_frame_ns = now_ns;
            const int64_t t = work.stamp_ns;
            const ros2::Header left_header{ros2::Time::fromNs(t), kLeftOpticalFrame};
            if (!work.left.empty() && due(kLeftImage)) {
                ros2::serializeImage(left_header, work.left.rows, work.left.cols, "mono8",
                                     work.left.cols, work.left.data, work.left.total(), message);
                send(kLeftImage, t, message);
            }
            if (!work.depth_m.empty() && due(kDepth)) {
                ros2::depthWithNan(work.depth_m, depth_nan);
                ros2::serializeImage(left_header, work.depth_m.rows, work.depth_m.cols, "32FC1",
                                     work.depth_m.cols * 4, depth_nan.data(), depth_nan.size() * 4,
                                     message);
                send(kDepth, t, message);
            }
            if (!work.confidence.empty() && due(kConfidence)) {
                ros2::serializeImage(left_header, work.confidence.rows, work.confidence.cols,
                                     "mono8", work.confidence.cols, work.confidence.data,
                                     work.confidence.total(), message);
                send(kConfidence, t, message);
            }
            if (!work.disparity.empty() && due(kDisparity)) {
                ros2::disparityForRos(work.disparity, work.min_disparity, disparity_ros);
                ros2::DisparityImage image;
                image.header = left_header;
                image.height = work.disparity.rows;
                image.width = work.disparity.cols;
                image.f = static_cast<float>(geometry_.focal_px);
                image.t = static_cast<float>(geometry_.baseline_m);
                image.valid_window = {0, 0, image.height, image.width, false};
                image.min_disparity = work.min_disparity;
                image.max_disparity = work.max_disparity;
                image.delta_d = 1.0f / 16.0f;
                ros2::serializeDisparityImage(image, disparity_ros.data(), disparity_ros.size() * 4,
                                              message);
                send(kDisparity, t, message);
            }
            if (due(kPoints)) {
                static_assert(sizeof(CloudPoint) == 4 * sizeof(float));
                ros2::serializeXyziCloud(left_header,
                                         reinterpret_cast<const float*>(work.cloud.data()),
                                         work.cloud.size(), message);
                send(kPoints, t, message);
            }
            for (const bool right : {false, true}) {
                const Channel channel = right ? kRightInfo : kLeftInfo;
                if (!due(channel))
                    continue;
                ros2::serializeCameraInfo(ros2::rectifiedCameraInfo(geometry_, right, t), message);
                send(channel, t, message);
            }
            if (due(kNearest))
                send(kNearest, t, work.reading_json);
        }
        if (work.status) {
            if (subscribed(kStatus))
                send(kStatus, now_ns, work.status_json);
            // No frame for a second: the reading says why (source down, stale).
            if (subscribed(kNearest) && now_ns - last_frame_ns > 1'000'000'000)
                send(kNearest, work.status_reading_stamp_ns, work.status_reading_json);
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
        std::vector<WebSocketTransport::ConnectionId> stuck;
        for (auto& [id, client] : sessions_->clients) {
            if (client.closing)
                continue;
            for (const auto& [sub, subscribed_channel] : client.subscriptions) {
                if (subscribed_channel != channel)
                    continue;
                if (transport_->buffered(id) > kSkipBytes) {
                    frames_dropped_.fetch_add(1, std::memory_order_relaxed);
                    if (client.lagging_since_ns == 0)
                        client.lagging_since_ns = now_ns;
                    else if (now_ns - client.lagging_since_ns > kStuckMs * 1'000'000) {
                        client.closing = true;
                        stuck.push_back(id);
                    }
                    break; // the client's other subscriptions to this channel wait too
                }
                client.lagging_since_ns = 0;
                setSubscriptionId(*frame, sub);
                if (transport_->sendBinary(id, *frame)) {
                    messages_.fetch_add(1, std::memory_order_relaxed);
                    bytes_.fetch_add(frame->size(), std::memory_order_relaxed);
                }
            }
        }
        for (const auto id : stuck) {
            clients_dropped_.fetch_add(1, std::memory_order_relaxed);
            spdlog::warn("live view: closing a client that has not read for {} s", kStuckMs / 1000);
            transport_->close(id, "too slow: not reading");
        }
    });
}

HttpResponse LiveView::serveFile(const std::string& request) const
{
    std::string path = request.substr(0, request.find('?'));
    if (!safePath(path))
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
    c.clients_dropped = clients_dropped_.load(std::memory_order_relaxed);
    return c;
}

} // namespace stereod::live_view
