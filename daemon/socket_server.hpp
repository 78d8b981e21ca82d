#pragma once
// The Unix-socket server of docs/protocol.md: one I/O thread, one epoll loop, every
// socket non-blocking.
//
// The loop serves the listening socket, the clients, the publisher's eventfd (a new
// result: events to subscribers), a 100 ms timer (health, idle clients, the service's
// periodic work) and descriptors the service adds with watch() (its stop and reload eventfds).
// Nothing in it blocks: a client's requests are answered into its output buffer, which is sent as
// the socket takes it (EPOLLOUT while data is unsent). A subscriber with unsent data
// skips frames (counted; its next event says how many); one whose unsent data exceed
// publish.max_client_backlog_bytes is disconnected (counted). So no client can slow down
// another one, the loop, or the worker. With the process out of descriptors, the
// connections waiting are accepted on a spare descriptor, refused (too_many_clients, "out
// of file descriptors") and closed, and accepting resumes on the next tick: the loop
// never spins on EMFILE.
//
// Thread contract: construction, run(), watch(), setPublishConfig(), setCalibration(),
// counters() and the destructor on one thread (the I/O thread); requestStop() from any
// thread and from a signal handler. The backend is called on the I/O thread only.
//
// The class spans several files, one job each: socket_server.cpp (set-up, the event loop,
// accepting connections, the timer), socket_server_connections.cpp (a connection's input,
// output and end), socket_server_requests.cpp (the request handlers) and
// socket_server_subscriptions.cpp (events to subscribers, snapshots waiting for raw
// frames).

#include <cstdint>
#include <exception>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include <poll.h>
#include <sys/types.h>

#include "base/descriptor_budget.hpp"
#include "base/unique_fd.hpp"
#include "config/service_config.hpp"
#include "daemon/listening_socket.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/publish_observer.hpp"
#include "daemon/publisher.hpp"
#include "daemon/server_backend.hpp"
#include "pipeline/calibration.hpp"
#include "protocol/json_writer.hpp"
#include "protocol/reading_json.hpp"
#include "protocol/request.hpp"
#include "protocol/status_reply.hpp"

namespace stereod {

struct ServerOptions {
    SocketConfig socket;
    PublishConfig publish;
    RectifiedGeometry geometry; // the calibration summary of snapshot replies
    // False in uncalibrated mode: readings say `uncalibrated`, only raw frames are served.
    bool calibrated = true;
    // The calibration in force, for the `calibration` request: its file and the file's
    // text as read at start-up (empty when it did not come from a file).
    std::string calibration_path;
    std::string calibration_text;
    // Use the listening socket systemd hands over (socket activation) when there is one
    // for socket.path; the file then belongs to systemd and is left in place at exit.
    bool accept_systemd_socket = false;
};

class SocketServer {
  public:
    // Binds and listens (daemon/listening_socket.hpp) and sets up the event loop. Throws
    // SocketError naming the path and the reason.
    SocketServer(const ServerOptions& options, Publisher& publisher, ServerBackend& backend);
    // Closes every connection and removes the socket file if it is still the one bound.
    ~SocketServer();

    SocketServer(const SocketServer&) = delete;
    SocketServer& operator=(const SocketServer&) = delete;

    // Serves until requestStop(). Throws SocketError only when epoll itself fails.
    void run();

    // Makes run() return soon. Any thread; async-signal-safe.
    void requestStop() noexcept;

    // Also watches `fd` (borrowed; it must stay open while watched) for input:
    // `on_readable` runs on the I/O thread when it is readable (level-triggered).
    void watch(int fd, std::function<void()> on_readable);

    // Also hands every new result, and the status once a second, to `observer` (the live
    // view; borrowed, it must outlive the server; nullptr: none). Before run().
    void setPublishObserver(PublishObserver* observer) noexcept { observer_ = observer; }

    // New publishing settings (from a reload); take effect with the next event.
    void setPublishConfig(const PublishConfig& publish);

    // The calibration that came after start (the service ran uncalibrated): snapshot
    // replies, `status` and the `calibration` request give it from the next request.
    void setCalibration(const RectifiedGeometry& geometry, const std::string& path,
                        const std::string& text);

    ClientCounters counters() const;
    const std::string& socketPath() const noexcept { return options_.socket.path; }

    // How often the timer ticks.
    static constexpr int64_t kTickNs = 100'000'000;

  private:
    // epoll tags (epoll_event.data.u64) from this one on are clients; a client's number in
    // the log is its tag minus this.
    static constexpr uint64_t kFirstClientTag = uint64_t{1} << 40;
    // Raw frames are copied by the worker for this long after a raw snapshot or the last
    // tick that saw a raw subscriber.
    static constexpr int64_t kRawInterestNs = 2'000'000'000;

    struct Subscription {
        bool active = false;
        std::optional<double> max_hz; // the client's own limit
        int64_t next_due_ns = 0;      // rate limit: earliest time of the next event
        uint64_t skipped = 0;         // events lost since the last one delivered
        uint64_t last_sequence = 0;   // publisher sequence of the last frame considered
        bool with_depth = false;      // raw only: each event carries the pair's depth
        bool with_cloud = false;      // raw only: each event carries the pair's cloud
        bool with_colour = false;     // raw only: and the colour (frames', cloud's)
    };

    // A snapshot with raw items that waits for the next pair carrying raw frames (raw
    // frames are copied only once someone asks). The client's later requests wait too,
    // so that replies keep their order.
    struct WaitingSnapshot {
        SnapshotRequest request;
        std::optional<Json> id;
        int64_t since_ns = 0;
    };

    struct Client {
        UniqueFd fd;
        uint64_t id = 0;
        std::string in;           // received bytes not yet framed into requests
        std::size_t in_start = 0; // where the unanswered part of `in` begins
        // Requests received and not answered yet wait for the client's next turn (it is
        // in ready_); nothing more is read from it meanwhile.
        bool pending = false;
        std::string out; // bytes to send; out_sent of them are sent
        std::size_t out_sent = 0;
        uint32_t epoll_events = 0; // what the client is registered for
        bool input_closed = false; // peer shut down its side, or we stopped reading
        bool close_when_flushed = false;
        bool dead = false;
        int64_t last_input_ns = 0;
        Subscription readings;
        Subscription depth;
        Subscription raw;
        Subscription zones;
        std::optional<WaitingSnapshot> waiting;

        std::size_t unsent() const noexcept { return out.size() - out_sent; }
        bool subscribed() const noexcept
        {
            return readings.active || depth.active || raw.active || zones.active;
        }
    };

    // socket_server.cpp: the loop and what it watches.
    void addToEpoll(int fd, uint64_t tag, uint32_t events);
    void acceptClients();
    void onTick();

    // socket_server_connections.cpp: a connection's input, output and end.
    void readClient(Client& client);
    // Closes the clients whose peers have hung up, without waiting for their events.
    void closeHungUpClients();
    // Answers the complete request lines received, at most kRequestsPerTurn of them; a
    // client with more waiting goes into ready_ for the next turn.
    void handleLines(Client& client);
    // Gives each client in ready_ its next turn.
    void serveReadyClients();
    void rejectTooLarge(Client& client);
    void writeClient(Client& client);
    void updateEpoll(Client& client);
    void closeClient(Client& client);
    void reapClients();
    // Makes room at the end of the client's output: drops the part already sent once it
    // is at least half of the buffer (amortised O(1) per byte, no per-send memmove).
    void compactOut(Client& client);
    void reply(Client& client, const Json& json);
    // A reply written straight into the client's output, without a Json tree: `"ok": true`
    // and the id written; the caller adds its fields, closes it and ends the line.
    JsonObjectWriter openDirectReply(Client& client, const std::optional<Json>& id);
    // Drops the client when its unsent data exceed the backlog limit; returns whether.
    bool dropIfBacklogged(Client& client);

    // socket_server_requests.cpp: the request handlers.
    void handleRequest(Client& client, std::string_view line);
    // Logs a request that threw and answers it with `internal`.
    void replyFailed(Client& client, const std::exception& error, const std::optional<Json>& id);
    // The reading to hand out now: judgeReading() of the newest pair's facts with the
    // source's health and the pair's age. The report borrows `health`'s and the frame's
    // detail texts.
    ReadingReport currentReading(const PublishedFrame* latest, double max_age_ms,
                                 const SourceHealth& health, int64_t now_ns) const;
    // The `status` object as of now.
    Json statusNow(int64_t now_ns);
    // Once a second, the status and the current reading to the observer.
    void notifyObserverOfStatus(int64_t now_ns);
    void handle(Client& client, const HelloRequest& request, const std::optional<Json>& id);
    void handle(Client& client, const DistanceRequest& request, const std::optional<Json>& id);
    void handle(Client& client, const StatusRequest& request, const std::optional<Json>& id);
    void handle(Client& client, const SnapshotRequest& request, const std::optional<Json>& id);
    void handle(Client& client, const ReloadRequest& request, const std::optional<Json>& id);
    void handle(Client& client, const CalibrationRequest& request, const std::optional<Json>& id);
    void handle(Client& client, const ZonesRequest& request, const std::optional<Json>& id);
    void handle(Client& client, const ViewRequest& request, const std::optional<Json>& id);
    // Answers a snapshot from `frame` (its raw frames must be present when asked for).
    void sendSnapshot(Client& client, const SnapshotRequest& request, const std::optional<Json>& id,
                      const PublishedFrame& frame);

    // socket_server_subscriptions.cpp: events to subscribers, snapshots waiting for raw
    // frames.
    void handle(Client& client, const SubscribeRequest& request, const std::optional<Json>& id);
    void onPublished();
    void dispatchFrame(const PublishedFrame& frame, int64_t now_ns);
    // Tells readings subscribers that the source went down (no frame will say so).
    void broadcastSourceDown(const SourceHealth& health, int64_t now_ns);
    bool due(Subscription& subscription, double max_hz_config, int64_t now_ns) const;
    // Answers the client's waiting snapshot from `frame` (nullptr: with `error`), then
    // serves the requests that queued up behind it.
    void finishWaiting(Client& client, const PublishedFrame* frame, std::string_view error);
    // Raw snapshots waiting: answered from a frame with raw frames, or refused once the
    // source is down or the wait is too long.
    void serveWaitingSnapshots(const PublishedFrame* frame, const SourceHealth* health,
                               int64_t now_ns);
    // Keeps the worker copying raw frames while raw subscribers exist.
    void refreshRawInterest(int64_t now_ns);

    ServerOptions options_;
    Publisher& publisher_;
    ServerBackend& backend_;

    ListeningSocket listener_;
    UniqueFd epoll_fd_;
    UniqueFd stop_fd_; // eventfd written by requestStop()
    UniqueFd timer_fd_;
    bool stopping_ = false;

    std::unordered_map<uint64_t, Client> clients_;
    std::vector<uint64_t> dead_clients_;
    std::vector<uint64_t> ready_;      // clients with requests waiting for their next turn
    std::vector<pollfd> hangup_poll_;  // closeHungUpClients(), reused
    std::vector<uint64_t> hangup_ids_; // the client of each hangup_poll_ entry
    uint64_t next_client_id_ = 0;
    std::vector<std::function<void()>> watches_;

    std::vector<char> read_buffer_;    // recv() target, reused
    std::string reading_event_;        // the frame's reading event line, built once per frame
    std::string depth_header_;         // the frame's depth event header, built once per frame
    std::string zones_event_;          // the frame's zones event line, built once per frame
    std::string raw_header_;           // the frame's raw event header, built once per frame
    std::size_t live_clients_ = 0;     // connections not closed yet
    bool listen_paused_ = false;       // out of descriptors: accept again on the next tick
    SpareDescriptor spare_descriptor_; // takes the connections waiting when none is left
    uint64_t last_dispatched_sequence_ = 0;
    PublishObserver* observer_ = nullptr;
    int64_t observer_status_ns_ = 0;
    std::string observer_reading_; // the reading object handed to the observer
    bool source_was_down_ = false;
    ClientCounters counters_;
    // Per-client and accept errors: one line per kind and 5 s, the rest counted.
    LogLimiter log_limiter_;
};

} // namespace stereod
