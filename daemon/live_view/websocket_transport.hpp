#pragma once
// The live view's network edge: an HTTP and WebSocket server on one port, on one I/O
// thread of its own, with websocketpp over standalone Asio (Debian's libwebsocketpp-dev
// and libasio-dev; Foxglove's own C++ server is built on them). Only this file's .cpp sees
// websocketpp, which predates C++20 and is compiled as C++17; this header is plain.
//
// Thread contract: start()/stop() from one controlling thread; post() from any thread;
// the handlers run on the I/O thread, and sendText()/sendBinary()/buffered()/close()
// must be called there (from a handler or a posted task).

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace stereod::live_view {

struct HttpResponse {
    int status = 200;
    std::string content_type = "text/plain; charset=utf-8";
    std::string body;
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
    std::string start(const std::string& host, uint16_t port, const std::string& subprotocol);
    // Closes every connection and joins the I/O thread. Idempotent.
    void stop();
    uint16_t port() const noexcept;

    // Runs `task` on the I/O thread.
    void post(std::function<void()> task);

    // I/O thread only. False when the connection is gone.
    bool sendText(ConnectionId id, const std::string& text);
    bool sendBinary(ConnectionId id, const std::string& bytes);
    // Bytes queued for the connection and not yet written to its socket.
    std::size_t buffered(ConnectionId id) const;
    // Closes with `reason` and shuts the socket down: the connection ends even when the
    // client reads nothing any more.
    void close(ConnectionId id, const std::string& reason);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace stereod::live_view
