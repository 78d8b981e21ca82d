#pragma once
// What the socket server (daemon/socket_server.hpp) needs from the service behind it: the
// source's health, the service's part of `status`, `reload`, the live view's links, and a
// periodic tick. The
// service implements it; the server's tests put a stub in its place.

#include <cstdint>
#include <string>
#include <vector>

#include "daemon/publisher.hpp"
#include "protocol/reply.hpp"
#include "protocol/status_reply.hpp"

namespace stereod {

// Whether the frame source is producing, as the service judges it.
struct SourceHealth {
    bool down = false;
    std::string message; // why, with numbers, when down
};

// The outcome of a `reload`, for its reply.
struct ReloadOutcome {
    bool ok = true;
    ErrorCode error = ErrorCode::Internal; // when !ok
    std::string message;                   // when !ok
    std::vector<std::string> changed;
    std::vector<std::string> restart_needed;
};

// Where the live view is, for `view`: its page and its WebSocket with the token in their
// URLs, or why it is not listening.
struct LiveViewLinks {
    bool listening = false;
    std::string listen;    // the address bound (or configured: "off", or why not)
    std::string error;     // why it is not listening, when it should be
    std::string page;      // http://HOST:PORT/?token=...
    std::string websocket; // ws://HOST:PORT/?token=... (Foxglove)
};

// Thread-bound: called on the server's I/O thread only.
class ServerBackend {
  public:
    virtual ~ServerBackend() = default;

    virtual SourceHealth sourceHealth(int64_t now_ns) = 0;

    // The service's part of the `status` reply: everything but "clients" and "reading",
    // which the server adds. `latest` is the newest result, or nullptr.
    virtual ServiceStatus serviceStatus(const PublishedFrame* latest, const SourceHealth& health,
                                        int64_t now_ns) = 0;

    // Re-reads the configuration and applies what can change live.
    virtual ReloadOutcome reload() = 0;

    // Runs on every timer tick (about every 100 ms).
    virtual void onTick(int64_t now_ns) = 0;

    // The live view's links (a service without one: not listening, listen "off").
    virtual LiveViewLinks liveViewLinks()
    {
        LiveViewLinks links;
        links.listen = "off";
        return links;
    }
};

} // namespace stereod
