#pragma once
// The live view's network edge: an HTTP and WebSocket server on one port, on one I/O
// thread of its own, with websocketpp over standalone Asio (Debian's libwebsocketpp-dev
// and libasio-dev; Foxglove's own C++ server is built on them). Only this file's .cpp sees
// websocketpp, which predates C++20 and is compiled as C++17; this header is plain.
//
// Admission and bounds, before anything reaches the handlers (docs/live-view.md):
//  - every request must pass daemon/live_view/admission.hpp (the token, the Origin):
//    else 403 (a foreign page) or 401 (no or a wrong token), with the reason;
//  - at most `max_clients` WebSocket sessions (the next handshake gets 503), and at most
//    `max_connections` sockets of any kind (handshakes, HTTP requests, sessions): at that
//    count no connection is accepted until one ends (the kernel's backlog holds them);
//  - out of descriptors (EMFILE), the connection waiting is taken on a spare descriptor,
//    answered 503 and closed, and accepting backs off (100 ms, doubling to 1.6 s) instead
//    of spinning;
//  - a reply to a client's request (sendReply) finds at most the backlog its caller
//    allows unsent to that client, or the client is closed: a client that sends and never
//    reads cannot make the service queue replies without end.
//
// Thread contract: start()/stop() from one controlling thread; post() and the counters
// from any thread; the handlers run on the I/O thread, and sendText()/sendBinary()/
// sendReply()/buffered()/close() must be called there (from a handler or a posted task).
// Units: bytes, connections.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace stereod::live_view {

struct HttpResponse {
    int status = 200;
    std::string content_type = "text/plain; charset=utf-8";
    std::string body;
};

// Who may connect, and how much each may hold.
struct TransportLimits {
    std::string token;                        // required on every request (admission.hpp)
    std::vector<std::string> allowed_origins; // pages besides the live view's own
    std::size_t max_clients = 16;             // WebSocket sessions
    std::size_t max_connections = 32;         // sockets of any kind, sessions included
};

class WebSocketTransport {
  public:
    using ConnectionId = uint64_t;
    struct Handlers {
        std::function<void(ConnectionId)> opened;
        std::function<void(ConnectionId)> closed;
        std::function<void(ConnectionId, const std::string&)> text;
        std::function<HttpResponse(const std::string& path)> http; // GET of a plain page
    };

    explicit WebSocketTransport(Handlers handlers);
    ~WebSocketTransport();
    WebSocketTransport(const WebSocketTransport&) = delete;
    WebSocketTransport& operator=(const WebSocketTransport&) = delete;

    // Binds host:port (port 0: any free port) and starts the I/O thread. Returns "" when
    // listening, else why not ("address already in use"). WebSocket clients must offer
    // `subprotocol`.
    std::string start(const std::string& host, uint16_t port, const std::string& subprotocol,
                      TransportLimits limits);
    // Closes every connection and joins the I/O thread. Idempotent.
    void stop();
    uint16_t port() const noexcept;

    // Runs `task` on the I/O thread.
    void post(std::function<void()> task);

    // I/O thread only. False when the connection is gone.
    bool sendText(ConnectionId id, const std::string& text);
    bool sendBinary(ConnectionId id, const std::string& bytes);
    // A reply to the client's own request; closes the client instead (and returns false)
    // when more than max_backlog_bytes wait unsent to it.
    bool sendReply(ConnectionId id, const std::string& text, std::size_t max_backlog_bytes);
    // Bytes queued for the connection and not yet written to its socket.
    std::size_t buffered(ConnectionId id) const;
    // Closes with `reason` and shuts the socket down: the connection ends even when the
    // client reads nothing any more.
    void close(ConnectionId id, const std::string& reason);

    // Any thread: requests refused (no or a wrong token, a foreign origin, too many
    // clients, out of descriptors), and clients closed for not reading their replies.
    uint64_t refused() const noexcept { return refused_.load(std::memory_order_relaxed); }
    uint64_t closedForReplies() const noexcept
    {
        return closed_for_replies_.load(std::memory_order_relaxed);
    }

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    std::atomic<uint64_t> refused_{0};
    std::atomic<uint64_t> closed_for_replies_{0};
};

} // namespace stereod::live_view
