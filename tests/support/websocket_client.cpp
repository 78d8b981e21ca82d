#include "tests/support/websocket_client.hpp"

#include <cstring>
#include <stdexcept>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include "base/system_error.hpp"

namespace stereod::test {

WebSocketClient::WebSocketClient(uint16_t port, const std::string& subprotocol,
                                 const Options& options)
    : fd_(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0))
{
    if (!fd_)
        throw std::runtime_error("websocket client: socket: " + errnoText(errno));
    if (options.receive_buffer > 0)
        ::setsockopt(fd_.get(), SOL_SOCKET, SO_RCVBUF, &options.receive_buffer,
                     sizeof options.receive_buffer);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(port);
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd_.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0)
        throw std::runtime_error("websocket client: connect to 127.0.0.1:" + std::to_string(port) +
                                 ": " + errnoText(errno));
    const std::string request = "GET " + options.resource +
                                " HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(port) +
                                "\r\nUpgrade: websocket\r\n"
                                "Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
                                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                                "Sec-WebSocket-Protocol: " +
                                subprotocol + "\r\n" + options.headers + "\r\n";
    if (::send(fd_.get(), request.data(), request.size(), MSG_NOSIGNAL) !=
        static_cast<ssize_t>(request.size()))
        throw std::runtime_error("websocket client: handshake not sent: " + errnoText(errno));
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    std::size_t end = std::string::npos;
    while ((end = buffer_.find("\r\n\r\n")) == std::string::npos)
        if (!fill(deadline))
            throw std::runtime_error("websocket client: no handshake answer");
    const std::string answer = buffer_.substr(0, end);
    buffer_.erase(0, end + 4);
    if (answer.rfind("HTTP/1.1 101", 0) != 0) {
        // The refusal's body too: what the server says is wrong.
        const auto body_deadline = std::chrono::steady_clock::now() + std::chrono::seconds(2);
        while (!closed_ && fill(body_deadline)) {
        }
        throw std::runtime_error("websocket client: handshake refused: " + answer + "\r\n\r\n" +
                                 buffer_);
    }
}

void WebSocketClient::sendText(const std::string& text)
{
    std::string frame;
    frame.push_back(static_cast<char>(0x81)); // FIN, text
    const std::size_t n = text.size();
    if (n < 126) {
        frame.push_back(static_cast<char>(0x80 | n));
    } else if (n < 65536) {
        frame.push_back(static_cast<char>(0x80 | 126));
        frame.push_back(static_cast<char>(n >> 8));
        frame.push_back(static_cast<char>(n & 0xff));
    } else {
        frame.push_back(static_cast<char>(0x80 | 127));
        for (int shift = 56; shift >= 0; shift -= 8)
            frame.push_back(static_cast<char>((n >> shift) & 0xff));
    }
    const unsigned char mask[4] = {0x12, 0x34, 0x56, 0x78};
    frame.append(reinterpret_cast<const char*>(mask), 4);
    for (std::size_t i = 0; i < n; ++i)
        frame.push_back(static_cast<char>(text[i] ^ static_cast<char>(mask[i % 4])));
    sendRaw(frame);
}

void WebSocketClient::sendRaw(const std::string& bytes)
{
    if (::send(fd_.get(), bytes.data(), bytes.size(), MSG_NOSIGNAL) !=
        static_cast<ssize_t>(bytes.size()))
        throw std::runtime_error("websocket client: send: " + errnoText(errno));
}

std::optional<WebSocketClient::Message> WebSocketClient::receive(std::chrono::milliseconds timeout)
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
        if (buffer_.size() >= 2) {
            const auto byte = [this](std::size_t i) { return static_cast<uint8_t>(buffer_[i]); };
            std::size_t header = 2;
            uint64_t length = byte(1) & 0x7f;
            if (length == 126) {
                header = 4;
                if (buffer_.size() >= header)
                    length = (uint64_t{byte(2)} << 8) | byte(3);
            } else if (length == 127) {
                header = 10;
                if (buffer_.size() >= header) {
                    length = 0;
                    for (std::size_t i = 2; i < 10; ++i)
                        length = (length << 8) | byte(i);
                }
            }
            if (buffer_.size() >= header && buffer_.size() - header >= length) {
                Message message{byte(0) & 0x0f, buffer_.substr(header, length)};
                buffer_.erase(0, header + length);
                return message;
            }
        }
        if (closed_ || !fill(deadline))
            return std::nullopt;
    }
}

bool WebSocketClient::fill(std::chrono::steady_clock::time_point deadline)
{
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0)
        return false;
    pollfd p{fd_.get(), POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0)
        return false;
    char chunk[65536];
    const ssize_t n = ::recv(fd_.get(), chunk, sizeof chunk, 0);
    if (n <= 0) {
        closed_ = true;
        return false;
    }
    buffer_.append(chunk, static_cast<std::size_t>(n));
    return true;
}

} // namespace stereod::test
