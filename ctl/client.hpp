#pragma once
// A client of the stereod socket protocol (docs/protocol.md): one connection to the
// service's Unix socket, JSON request lines out, JSON reply lines and binary payloads in.
// Used by every client command of `stereoctl` and by the tests; any program that talks
// to the service can use it.
//
// Thread-bound: one ProtocolClient per thread. Not copyable; movable.

#include <chrono>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include <nlohmann/json.hpp>

#include "base/unique_fd.hpp"

namespace stereod {

// The service cannot be reached or the connection failed: what() names the socket path
// and the reason (the errno text where a system call failed).
class ClientError : public std::runtime_error {
  public:
    ClientError(const std::string& message, int error_number)
        : std::runtime_error(message), error_number_(error_number)
    {
    }
    // errno of the failing call; 0 when the failure is not a system call's (a timeout, a
    // reply that is not JSON, the service closing the connection).
    int errorNumber() const noexcept { return error_number_; }

  private:
    int error_number_;
};

// A wait for the service was cut short because the cancel descriptor became readable
// (see ProtocolClient::setCancelFd).
class ClientCancelled : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

// The service answered `"ok": false`. code() is the protocol's stable error code
// ("not_available", "bad_request", ...); what() is "code: message".
class ServiceError : public std::runtime_error {
  public:
    ServiceError(std::string code, const std::string& message)
        : std::runtime_error(code + ": " + message), code_(std::move(code))
    {
    }
    const std::string& code() const noexcept { return code_; }

  private:
    std::string code_;
};

class ProtocolClient {
  public:
    // No limit on a wait (for streams that may be quiet for a long time).
    static constexpr std::chrono::milliseconds kWaitForever{-1};
    // Longest line accepted from the service, newline excluded: a guard against a peer
    // that never sends one.
    static constexpr std::size_t kMaxLineBytes = 16u << 20;

    // Connects to the socket at `socket_path`. `timeout` bounds the connection attempt and
    // then every later wait for the service (time without progress, not a total).
    // Throws ClientError naming the path and the errno text.
    ProtocolClient(std::string socket_path, std::chrono::milliseconds timeout);
    ~ProtocolClient();

    ProtocolClient(ProtocolClient&& other) noexcept;
    ProtocolClient& operator=(ProtocolClient&& other) noexcept;
    ProtocolClient(const ProtocolClient&) = delete;
    ProtocolClient& operator=(const ProtocolClient&) = delete;

    // Sends one request line and reads its reply. Throws ServiceError when the reply has
    // `"ok": false`, ClientError when the exchange fails. Payloads the reply announces
    // are left to be read with readPayload().
    nlohmann::ordered_json request(const nlohmann::ordered_json& request);

    // Sends `request` as one line (compact JSON and a newline).
    void sendRequest(const nlohmann::ordered_json& request);
    // Sends exactly these bytes: for requests that are deliberately not well-formed.
    void sendRaw(std::string_view bytes);

    // Reads one line (without its newline). Throws ClientError when the service closes
    // the connection first, when the wait times out, or when the line exceeds
    // kMaxLineBytes.
    std::string readLine();
    // Reads one line and parses it; throws ClientError unless it is a JSON object.
    nlohmann::ordered_json readJson();

    // Reads exactly `bytes` payload bytes into `data`.
    void readPayload(void* data, std::size_t bytes);
    // Reads and drops `bytes` payload bytes.
    void skipPayload(std::size_t bytes);

    // Changes the wait limit set at construction (kWaitForever: no limit).
    void setTimeout(std::chrono::milliseconds timeout) { timeout_ = timeout; }
    // While waiting for the service, also watch `fd` (a signalfd, an eventfd, a pipe):
    // when it becomes readable the wait throws ClientCancelled. -1 removes it. The
    // descriptor is borrowed, never read or closed here.
    void setCancelFd(int fd) { cancel_fd_ = fd; }

    const std::string& socketPath() const noexcept { return socket_path_; }
    // The connected socket, for poll() loops of the caller; -1 after a move.
    int fd() const noexcept { return fd_.get(); }

  private:
    void connectSocket();
    // Blocks until the socket is ready for `events` (POLLIN/POLLOUT); throws on timeout,
    // cancellation or a poll error. `doing` says what was waited for, for messages.
    void waitFor(short events, const char* doing);
    // Receives at most `capacity` bytes, waiting (as waitFor) until some come; 0 at the end
    // of the stream. Throws ClientError on a socket error.
    std::size_t receiveSome(char* data, std::size_t capacity, const char* doing);
    // Appends what is available to rx_; throws ClientError at the end of the stream.
    void receiveMore();
    void close() noexcept;

    std::string socket_path_;
    std::chrono::milliseconds timeout_;
    UniqueFd fd_;
    int cancel_fd_ = -1;
    std::string rx_;           // bytes received and not consumed yet
    std::size_t rx_begin_ = 0; // first unconsumed byte in rx_
};

} // namespace stereod
