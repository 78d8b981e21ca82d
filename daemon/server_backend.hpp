#pragma once
// What the socket server (daemon/socket_server.hpp) needs from the service behind it: the
// source's health, the service's part of `status`, `reload`, and a periodic tick. The
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
};

} // namespace stereod
