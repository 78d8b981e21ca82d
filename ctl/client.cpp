#include "ctl/client.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <system_error>
#include <thread>

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "base/system_error.hpp"

namespace stereod {

namespace {

using Clock = std::chrono::steady_clock;

// How long a refused-because-busy connection (EAGAIN: the listen backlog is full) waits
// before trying again.
constexpr std::chrono::milliseconds kConnectRetry{10};

} // namespace

ProtocolClient::ProtocolClient(std::string socket_path, std::chrono::milliseconds timeout)
    : socket_path_(std::move(socket_path)), timeout_(timeout)
{
    connectSocket();
}

ProtocolClient::~ProtocolClient()
{
    close();
}

ProtocolClient::ProtocolClient(ProtocolClient&& other) noexcept
    : socket_path_(std::move(other.socket_path_)), timeout_(other.timeout_),
      fd_(std::move(other.fd_)), cancel_fd_(std::exchange(other.cancel_fd_, -1)),
      rx_(std::move(other.rx_)), rx_begin_(std::exchange(other.rx_begin_, 0))
{
}

ProtocolClient& ProtocolClient::operator=(ProtocolClient&& other) noexcept
{
    if (this != &other) {
        close();
        socket_path_ = std::move(other.socket_path_);
        timeout_ = other.timeout_;
        fd_ = std::move(other.fd_);
        cancel_fd_ = std::exchange(other.cancel_fd_, -1);
        rx_ = std::move(other.rx_);
        rx_begin_ = std::exchange(other.rx_begin_, 0);
    }
    return *this;
}

void ProtocolClient::close() noexcept
{
    fd_.reset();
}

void ProtocolClient::connectSocket()
{
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    if (socket_path_.empty() || socket_path_.size() >= sizeof(address.sun_path)) {
        throw ClientError("cannot connect to '" + socket_path_ +
                              "': a socket path must have 1 to " +
                              std::to_string(sizeof(address.sun_path) - 1) + " bytes",
                          ENAMETOOLONG);
    }
    std::memcpy(address.sun_path, socket_path_.data(), socket_path_.size());

    fd_.reset(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
    if (!fd_) {
        const int error_number = errno;
        throw ClientError("cannot create a socket to connect to " + socket_path_ + ": " +
                              errnoText(error_number),
                          error_number);
    }

    const auto deadline = Clock::now() + timeout_;
    for (;;) {
        if (::connect(fd_.get(), reinterpret_cast<const sockaddr*>(&address), sizeof(address)) ==
            0) {
            return;
        }
        const int error_number = errno;
        if (error_number == EINTR) {
            continue;
        }
        if (error_number == EINPROGRESS) {
            waitFor(POLLOUT, "connecting");
            int socket_error = 0;
            socklen_t length = sizeof(socket_error);
            ::getsockopt(fd_.get(), SOL_SOCKET, SO_ERROR, &socket_error, &length);
            if (socket_error == 0) {
                return;
            }
            close();
            throw ClientError("cannot connect to " + socket_path_ + ": " + errnoText(socket_error),
                              socket_error);
        }
        // A full listen backlog: the service is there but busy; try again until the
        // timeout runs out.
        if (error_number == EAGAIN &&
            (timeout_ < std::chrono::milliseconds::zero() || Clock::now() < deadline)) {
            std::this_thread::sleep_for(kConnectRetry);
            continue;
        }
        close();
        throw ClientError("cannot connect to " + socket_path_ + ": " + errnoText(error_number),
                          error_number);
    }
}

void ProtocolClient::waitFor(short events, const char* doing)
{
    if (!fd_) {
        throw ClientError("not connected to " + socket_path_, ENOTCONN);
    }
    pollfd fds[2] = {{fd_.get(), events, 0}, {cancel_fd_, POLLIN, 0}};
    const nfds_t count = cancel_fd_ >= 0 ? 2 : 1;
    const int timeout_ms = timeout_ < std::chrono::milliseconds::zero()
                               ? -1
                               : static_cast<int>(std::min<long long>(timeout_.count(), 1 << 30));
    const auto deadline = Clock::now() + timeout_;
    for (;;) {
        int remaining_ms = timeout_ms;
        if (timeout_ms >= 0) {
            const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - Clock::now());
            remaining_ms = static_cast<int>(std::max<long long>(left.count(), 0));
        }
        const int ready = ::poll(fds, count, remaining_ms);
        if (ready < 0) {
            const int error_number = errno;
            if (error_number == EINTR) {
                continue;
            }
            throw ClientError(std::string("poll failed while ") + doing + " " + socket_path_ +
                                  ": " + errnoText(error_number),
                              error_number);
        }
        if (ready == 0) {
            throw ClientError("timed out after " + std::to_string(timeout_.count()) + " ms " +
                                  doing + " " + socket_path_,
                              0);
        }
        if (count == 2 && fds[1].revents != 0) {
            throw ClientCancelled(std::string("cancelled while ") + doing + " " + socket_path_);
        }
        // POLLHUP and POLLERR fall through: the read or write that follows reports them
        // with their errno.
        return;
    }
}

void ProtocolClient::sendRequest(const nlohmann::ordered_json& request)
{
    std::string line = request.dump();
    line.push_back('\n');
    sendRaw(line);
}

void ProtocolClient::sendRaw(std::string_view bytes)
{
    std::size_t sent = 0;
    while (sent < bytes.size()) {
        const ssize_t n = ::send(fd_.get(), bytes.data() + sent, bytes.size() - sent,
                                 MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n >= 0) {
            sent += static_cast<std::size_t>(n);
            continue;
        }
        const int error_number = errno;
        if (error_number == EINTR) {
            continue;
        }
        if (error_number == EAGAIN || error_number == EWOULDBLOCK) {
            waitFor(POLLOUT, "sending to");
            continue;
        }
        throw ClientError("cannot send to " + socket_path_ + ": " + errnoText(error_number),
                          error_number);
    }
}

std::size_t ProtocolClient::receiveSome(char* data, std::size_t capacity, const char* doing)
{
    for (;;) {
        const ssize_t n = ::recv(fd_.get(), data, capacity, MSG_DONTWAIT);
        if (n >= 0) {
            return static_cast<std::size_t>(n);
        }
        const int error_number = errno;
        if (error_number == EINTR) {
            continue;
        }
        if (error_number == EAGAIN || error_number == EWOULDBLOCK) {
            waitFor(POLLIN, doing);
            continue;
        }
        throw ClientError("cannot read from " + socket_path_ + ": " + errnoText(error_number),
                          error_number);
    }
}

void ProtocolClient::receiveMore()
{
    // Keep the buffer from growing with consumed bytes: drop them before reading more.
    if (rx_begin_ > 0) {
        rx_.erase(0, rx_begin_);
        rx_begin_ = 0;
    }
    constexpr std::size_t kChunk = 64 * 1024;
    const std::size_t old_size = rx_.size();
    rx_.resize(old_size + kChunk);
    std::size_t received = 0;
    try {
        received = receiveSome(rx_.data() + old_size, kChunk, "waiting for");
    } catch (...) {
        rx_.resize(old_size);
        throw;
    }
    rx_.resize(old_size + received);
    if (received == 0) {
        throw ClientError("the service at " + socket_path_ + " closed the connection", 0);
    }
}

std::string ProtocolClient::readLine()
{
    std::size_t searched = rx_begin_;
    for (;;) {
        const std::size_t newline = rx_.find('\n', searched);
        if (newline != std::string::npos) {
            std::string line = rx_.substr(rx_begin_, newline - rx_begin_);
            rx_begin_ = newline + 1;
            return line;
        }
        if (rx_.size() - rx_begin_ > kMaxLineBytes) {
            throw ClientError("a line from " + socket_path_ + " exceeds " +
                                  std::to_string(kMaxLineBytes) + " bytes",
                              0);
        }
        // receiveMore() moves the unconsumed bytes to the front; resume the search where
        // it stopped.
        const std::size_t searched_unconsumed = rx_.size() - rx_begin_;
        receiveMore();
        searched = rx_begin_ + searched_unconsumed;
    }
}

nlohmann::ordered_json ProtocolClient::readJson()
{
    const std::string line = readLine();
    nlohmann::ordered_json value =
        nlohmann::ordered_json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!value.is_object()) {
        constexpr std::size_t kQuoted = 120;
        throw ClientError("the service at " + socket_path_ +
                              " sent a line that is not a JSON object: '" +
                              line.substr(0, kQuoted) + (line.size() > kQuoted ? "...'" : "'"),
                          0);
    }
    return value;
}

nlohmann::ordered_json ProtocolClient::request(const nlohmann::ordered_json& request)
{
    nlohmann::ordered_json reply;
    try {
        sendRequest(request);
        reply = readJson();
    } catch (const ClientError& e) {
        // A service that refuses a client (not allowed, too many clients) answers on
        // accept and closes: the send then fails with a broken pipe, but the answer is
        // waiting to be read and says why.
        if (e.errorNumber() != EPIPE && e.errorNumber() != ECONNRESET)
            throw;
        try {
            reply = readJson();
        } catch (const ClientError&) {
            throw e;
        }
    }
    const auto ok = reply.find("ok");
    if (ok == reply.end() || !ok->is_boolean()) {
        throw ClientError("the reply from " + socket_path_ + " has no boolean \"ok\"", 0);
    }
    if (!ok->get<bool>()) {
        std::string code = "unknown";
        std::string message = "(no message)";
        if (const auto error = reply.find("error"); error != reply.end() && error->is_object()) {
            code = error->value("code", code);
            message = error->value("message", message);
        }
        throw ServiceError(std::move(code), message);
    }
    return reply;
}

void ProtocolClient::readPayload(void* data, std::size_t bytes)
{
    if (bytes == 0) {
        return; // `data` may be null then (an empty vector's)
    }
    auto* out = static_cast<char*>(data);
    const std::size_t buffered = std::min(bytes, rx_.size() - rx_begin_);
    std::memcpy(out, rx_.data() + rx_begin_, buffered);
    rx_begin_ += buffered;
    std::size_t done = buffered;
    // The rest goes straight into the caller's buffer, without passing through rx_.
    while (done < bytes) {
        const std::size_t n =
            receiveSome(out + done, bytes - done, "waiting for payload bytes from");
        if (n == 0) {
            throw ClientError("the service at " + socket_path_ + " closed the connection after " +
                                  std::to_string(done) + " of " + std::to_string(bytes) +
                                  " payload bytes",
                              0);
        }
        done += n;
    }
}

void ProtocolClient::skipPayload(std::size_t bytes)
{
    char sink[64 * 1024];
    while (bytes > 0) {
        const std::size_t n = std::min(bytes, sizeof(sink));
        readPayload(sink, n);
        bytes -= n;
    }
}

} // namespace stereod
