#pragma once
// A WebSocket client small enough to trust in a test (RFC 6455 over a blocking TCP socket
// on 127.0.0.1): the opening handshake with a subprotocol, masked text frames out,
// unfragmented frames in. It reads only when asked, so a test can also be the client
// that never reads.
//
// Thread-bound: each object belongs to the thread that uses it.

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "base/unique_fd.hpp"

namespace stereod::test {

class WebSocketClient {
  public:
    struct Message {
        int opcode = 0; // 1 text, 2 binary, 8 close
        std::string payload;
    };

    // What the handshake asks beyond the subprotocol.
    struct Options {
        std::string resource = "/"; // the request's target: "/?token=..."
        std::string headers;        // more header lines, each ending in \r\n ("Origin: ...")
        // Above 0: the socket's receive buffer, set first (a small one makes a client that
        // never reads fill the server's queue sooner).
        int receive_buffer = 0;
    };

    // Connects and completes the handshake offering `subprotocol`. Throws
    // std::runtime_error naming what failed; a refused handshake's message starts with
    // "websocket client: handshake refused: " and the server's answer ("HTTP/1.1 401 ...").
    WebSocketClient(uint16_t port, const std::string& subprotocol, const Options& options);
    WebSocketClient(uint16_t port, const std::string& subprotocol, int receive_buffer = 0)
        : WebSocketClient(port, subprotocol, Options{"/", "", receive_buffer})
    {
    }

    void sendText(const std::string& text);
    // Bytes as they are, framed or not: for the tests of what a server does with
    // malformed frames.
    void sendRaw(const std::string& bytes);
    // The next message; nullopt when none came within `timeout` or the server closed
    // the connection (closed() then says so).
    std::optional<Message> receive(std::chrono::milliseconds timeout);
    bool closed() const noexcept { return closed_; }

  private:
    bool fill(std::chrono::steady_clock::time_point deadline);

    UniqueFd fd_;
    std::string buffer_; // received, not yet parsed
    bool closed_ = false;
};

} // namespace stereod::test
