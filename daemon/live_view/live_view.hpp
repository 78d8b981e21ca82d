#pragma once
// The live view: what the robot sees, to Foxglove and to the built-in page, over the
// Foxglove WebSocket protocol on one port (default 127.0.0.1:8765), with the page served
// over HTTP on the same port.
//
// Three threads meet here, and the worker is none of them:
//  - the socket server's I/O thread offers each new result (onFrame) and, once a
//    second, the status (onStatus). The reading, the zones and the status are JSON
//    already: it frames them and posts them to the transport at once. The frame
//    channels it copies into a mailbox under a short lock, only those somebody
//    subscribed to, the newest result replacing one not taken yet;
//  - the feed thread (ours) takes the mailbox's content, serializes the frame channels
//    (ROS 2 CDR), each at most at its rate (live_view.rate_hz.*, else
//    live_view.max_rate_hz), and hands the messages to the transport;
//  - the transport's I/O thread (WebSocketTransport) keeps the clients and their
//    subscriptions and sends.
//
// Readings first: the reading, zones and status channels go to a client's socket the
// moment they are made, outside its byte budget, never behind the serializing of images. A frame
// message waits in the client's own slot for its channel until the client's socket holds less than
// kFrameBudgetBytes unsent, and a newer frame of the channel replaces one still waiting (counted in
// frames_dropped): a slow client gets fewer frames, never fewer readings, and a reading
// waits behind at most the budget and one frame. A client that reads nothing for
// kStuckMs while data waits for it is closed (counted in clients_dropped).
//
// Bounds (docs/live-view.md): who may connect and how many is the transport's
// (websocket_transport.hpp: the token, the Origin, max_clients, max_connections, the
// reply backlog); here, a client subscribes to each channel at most once (kChannelEnd - 1
// subscriptions), and a request gets at most one status reply.
//
// Thread contract: start()/stop() from the controlling thread; onFrame(),
// onStatus() from one thread (the socket server's); status() from any thread.
// Units: stamps and log times in ns; the stamps of the messages (header.stamp, log time)
// are the pair's realtime stamp (docs/architecture.md, "Time").

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
    kZones,
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
    // Per channel, at most this often. 0: a frame channel follows max_rate_hz; kNearest
    // and kZones carry every reading; kStatus is once a second whatever it says.
    std::array<double, kChannelEnd> rate_hz{};
    std::string web_root; // the page's files (index.html, viewer.js, ...)
    std::string three_root = "/usr/share/javascript/three"; // Debian's libjs-three
};

// What each channel is: topic, encoding and schema.
const std::vector<ChannelSpec>& channelSpecs();

// Whether a channel is one of the readings that go before frames (reading, zones,
// status), never dropped for a slow client.
constexpr bool isPriorityChannel(Channel channel) noexcept
{
    return channel == kNearest || channel == kStatus || channel == kZones;
}

class LiveView final : public PublishObserver {
  public:
    // A client's socket takes frame messages while it holds less than this unsent.
    static constexpr std::size_t kFrameBudgetBytes = 2 * 1024 * 1024;
    // A client that reads nothing this long while data waits for it is closed.
    static constexpr int64_t kStuckMs = 5000;
    // How often waiting frames are offered again to the clients' sockets, and a client
    // that reads nothing is looked at, ms.
    static constexpr int64_t kPumpIntervalMs = 10;

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
    // reading object (the same text `stereoctl distance --json` prints). Its messages are
    // stamped (header.stamp, log time) with frame.realtimeNs() of the pair's stamp.
    void onFrame(const PublishedFrame& frame, std::string_view reading_json) override;
    // The same thread, once a second: `status` as `stereoctl status --json` prints it,
    // and the current reading (which says "source_down" when no frame comes any more).
    void onStatus(std::string_view status_json, std::string_view reading_json,
                  int64_t reading_realtime_ns) override;

    // The live view's part of `status`; `listen` is the address bound (or asked for).
    StatusLiveView status() const;

    // The rectified geometry of a calibration that came after start (the service ran
    // uncalibrated): camera_info and the disparity's f and t follow it. Any thread.
    void setGeometry(const RectifiedGeometry& geometry);

  private:
    struct Mailbox {
        bool frame = false; // the frame channels below hold a result not sent yet
        // The frame channels whose part of the result was taken (they had subscribers
        // when it came): a channel subscribed since gets the next frame, never what its
        // buffer held from an older one, nor an empty cloud.
        std::array<bool, kChannelEnd> taken{};
        cv::Mat left, depth_m, confidence, disparity;
        const char* left_encoding = "mono8"; // "rgb8" where the left camera has colour
        std::vector<CloudPoint> cloud;
        std::vector<CloudColour> cloud_colour; // one per cloud point, or none (grey)
        // The left camera is in colour: the cloud carries it, empty or not, so that the
        // channel's layout does not change with a frame that has no depth.
        bool points_in_colour = false;
        int64_t stamp_ns = 0; // the pair's realtime stamp
        float min_disparity = 0.0f;
        float max_disparity = 0.0f;
    };
    struct Client;
    struct Sessions;

    bool subscribed(Channel channel) const noexcept
    {
        return subscribers_[channel].load(std::memory_order_relaxed) > 0;
    }
    // The socket server's thread: a JSON message to its subscribers now, unless its
    // channel's own rate (live_view.rate_hz.nearest) says it is too soon.
    void sendJson(Channel channel, int64_t log_time_ns, std::string_view text, int64_t now_ns);
    void feed();
    void send(Channel channel, int64_t log_time_ns, std::string_view payload);
    // Transport thread: false when the client is closed or closing; closes one that has
    // read nothing for kStuckMs while data waited for it.
    bool stillReading(WebSocketTransport::ConnectionId id, Client& client, int64_t now_ns);
    // Transport thread: `frame` (subscription id patched in) to each of the client's
    // subscriptions to `channel`.
    void sendTo(WebSocketTransport::ConnectionId id, Client& client, Channel channel,
                std::string& frame);
    // Transport thread: the client's waiting frames, longest waiting first, while its
    // socket holds less than kFrameBudgetBytes.
    void handOverFrames(WebSocketTransport::ConnectionId id, Client& client);
    // Transport thread: the unsent bytes a reply to the client may find. Frames go out
    // while less than kFrameBudgetBytes wait, so one large frame (a full-size cloud) may
    // sit above the budget: replies get 1 MiB of their own above what the frames left.
    // A client that lags behind its frames is not closed for one reply; one that never
    // reads its replies is.
    static std::size_t replyBacklogAllowed(const Client& client);
    // From the feed thread: every client's waiting frames offered again.
    void pumpAll();
    HttpResponse serveFile(const std::string& path) const;

    LiveViewSettings settings_;
    std::unique_ptr<WebSocketTransport> transport_;
    std::unique_ptr<Sessions> sessions_; // transport thread only
    uint64_t waiting_sequence_ = 0;      // transport thread only: orders waiting frames
    std::array<std::atomic<int>, kChannelEnd> subscribers_{};

    std::mutex mutex_;
    std::condition_variable wake_;
    bool stopping_ = false;
    Mailbox mailbox_;            // guarded by mutex_
    RectifiedGeometry geometry_; // guarded by mutex_
    std::thread feed_thread_;

    std::string address_;
    std::string error_;
    std::atomic<bool> listening_{false};
    // The socket server's thread only: when the last frame came, when each JSON channel
    // last went, and the zones' text.
    int64_t last_frame_ns_ = 0;
    std::array<int64_t, kChannelEnd> json_sent_ns_{};
    std::string zones_json_;
    std::atomic<uint64_t> clients_{0}, messages_{0}, bytes_{0}, frames_dropped_{0},
        clients_dropped_{0}, readings_sent_{0};
};

} // namespace stereod::live_view
