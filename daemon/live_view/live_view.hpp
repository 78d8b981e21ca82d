#pragma once
// The live view: what the robot sees, to Foxglove and to the built-in page, over the
// Foxglove WebSocket protocol on one port (default 127.0.0.1:8765), with the page served
// over HTTP on the same port.
//
// Three threads meet here, and the worker is none of them:
//  - the socket server's I/O thread offers each new result (onFrame) and, once a
//    second, the status (onStatus): a copy into a mailbox under a short lock, only of
//    the channels somebody subscribed to;
//  - the feed thread (ours) takes the newest mailbox content, serializes the channels
//    (ROS 2 CDR, JSON), each at most at its rate (live_view.rate_hz.*, else
//    live_view.max_rate_hz), and hands the messages to the transport;
//  - the transport's I/O thread (WebSocketTransport) keeps the clients and their
//    subscriptions and sends. A client whose socket holds more than kSkipBytes unsent
//    loses frames (counted); one that stays so for kStuckMs is closed (counted).
//
// Bounds (docs/live-view.md): who may connect and how many is the transport's
// (websocket_transport.hpp: the token, the Origin, max_clients, max_connections, the
// reply backlog); here, a client subscribes to each channel at most once (kChannelEnd - 1
// subscriptions), and a request gets at most one status reply.
//
// Thread contract: start()/stop() from the controlling thread; onFrame(),
// onStatus() from one thread (the socket server's); counters() from any thread.

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "daemon/live_view/foxglove_protocol.hpp"
#include "daemon/live_view/websocket_transport.hpp"
#include "daemon/publish_observer.hpp"
#include "daemon/publisher.hpp"
#include "pipeline/calibration.hpp"
#include "protocol/status_reply.hpp"

namespace stereod::live_view {

// The channels, by id (the ids advertised).
enum Channel : uint32_t {
    kLeftImage = 1,
    kDepth,
    kDisparity,
    kConfidence,
    kPoints,
    kLeftInfo,
    kRightInfo,
    kNearest,
    kStatus,
    kChannelEnd
};

struct LiveViewSettings {
    std::string host = "127.0.0.1";
    uint16_t port = 8765; // 0: any free port (tests)
    // Who may watch (daemon/live_view/admission.hpp): the token every request must carry
    // (empty: a new one from the kernel's random source at start()), and the pages besides
    // the live view's own whose browsers may connect.
    std::string token;
    std::vector<std::string> allowed_origins;
    // WebSocket sessions at most, and sockets of any kind at most (the service keeps this
    // below its descriptor limit).
    std::size_t max_clients = 16;
    std::size_t max_connections = 32;
    int points_step = 4;       // every n-th point of the cloud goes out
    double max_rate_hz = 10.0; // frame channels; status is once a second
    // Per channel, at most this often; 0 (and kStatus, once a second) follows max_rate_hz.
    std::array<double, kChannelEnd> rate_hz{};
    std::string web_root; // the page's files (index.html, viewer.js, ...)
    std::string three_root = "/usr/share/javascript/three"; // Debian's libjs-three
};

// What each channel is: topic, encoding and schema.
const std::vector<ChannelSpec>& channelSpecs();

class LiveView final : public PublishObserver {
  public:
    static constexpr std::size_t kSkipBytes = 4 * 1024 * 1024;
    static constexpr int64_t kStuckMs = 5000;

    LiveView(LiveViewSettings settings, RectifiedGeometry geometry);
    ~LiveView() override;
    LiveView(const LiveView&) = delete;
    LiveView& operator=(const LiveView&) = delete;

    // Listens and starts the threads; "" when listening, else the reason (the service
    // then runs without the live view).
    std::string start();
    void stop();
    uint16_t port() const noexcept;
    // The token every request must carry (made by start() when the settings had none).
    const std::string& token() const noexcept { return settings_.token; }

    // The socket server's I/O thread: a new result, and its reading as the protocol's
    // reading object (the same text `stereoctl distance --json` prints).
    void onFrame(const PublishedFrame& frame, std::string_view reading_json) override;
    // The same thread, once a second: `status` as `stereoctl status --json` prints it,
    // and the current reading (which says "source_down" when no frame comes any more).
    void onStatus(std::string_view status_json, std::string_view reading_json,
                  int64_t reading_stamp_ns) override;

    // The live view's part of `status`; `listen` is the address bound (or asked for).
    StatusLiveView status() const;

  private:
    struct Mailbox {
        bool frame = false;
        cv::Mat left, depth_m, confidence, disparity;
        std::vector<CloudPoint> cloud;
        int64_t stamp_ns = 0;
        float min_disparity = 0.0f;
        float max_disparity = 0.0f;
        std::string reading_json;
        bool status = false;
        std::string status_json;
        std::string status_reading_json;
        int64_t status_reading_stamp_ns = 0;
    };
    struct Client;
    struct Sessions;

    bool subscribed(Channel channel) const noexcept
    {
        return subscribers_[channel].load(std::memory_order_relaxed) > 0;
    }
    void feed();
    void send(Channel channel, int64_t log_time_ns, std::string_view payload);
    HttpResponse serveFile(const std::string& path) const;

    LiveViewSettings settings_;
    RectifiedGeometry geometry_;
    std::unique_ptr<WebSocketTransport> transport_;
    std::unique_ptr<Sessions> sessions_; // transport thread only
    std::array<std::atomic<int>, kChannelEnd> subscribers_{};

    std::mutex mutex_;
    std::condition_variable wake_;
    bool stopping_ = false;
    Mailbox mailbox_; // guarded by mutex_
    std::thread feed_thread_;

    std::string address_;
    std::string error_;
    std::atomic<bool> listening_{false};
    std::atomic<uint64_t> clients_{0}, messages_{0}, bytes_{0}, frames_dropped_{0},
        clients_dropped_{0};
};

} // namespace stereod::live_view
