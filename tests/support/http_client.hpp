#pragma once
// Plain TCP and HTTP/1.1 on loopback for the live view's tests: a free port, a connection,
// one whole exchange. Blocking, no TLS, nothing parsed but what the tests look at.
//
// Reentrant: each call uses its own socket.

#include <cstdint>
#include <string>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "base/unique_fd.hpp"

namespace stereod::test {

// A port nobody listens on now (bound to 0, then released).
inline uint16_t freePort()
{
    const UniqueFd fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd.get(), reinterpret_cast<sockaddr*>(&address), sizeof address);
    socklen_t length = sizeof address;
    ::getsockname(fd.get(), reinterpret_cast<sockaddr*>(&address), &length);
    return ntohs(address.sin_port);
}

// A connected socket to 127.0.0.1:port; invalid when the connection failed.
inline UniqueFd connectLoopback(uint16_t port)
{
    UniqueFd fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(port);
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (!fd || ::connect(fd.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0)
        return UniqueFd();
    return fd;
}

// One HTTP exchange on 127.0.0.1:port; the whole answer, until the server closes.
inline std::string httpExchange(uint16_t port, const std::string& request)
{
    const UniqueFd fd = connectLoopback(port);
    if (!fd)
        return {};
    ::send(fd.get(), request.data(), request.size(), MSG_NOSIGNAL);
    std::string answer;
    char buffer[4096];
    ssize_t n = 0;
    while ((n = ::recv(fd.get(), buffer, sizeof buffer, 0)) > 0)
        answer.append(buffer, static_cast<std::size_t>(n));
    return answer;
}

// GET `target` ("/?token=...") with `headers` (lines ending in \r\n) added.
inline std::string httpGet(uint16_t port, const std::string& target,
                           const std::string& headers = {})
{
    return httpExchange(port, "GET " + target +
                                  " HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(port) +
                                  "\r\nConnection: close\r\n" + headers + "\r\n");
}

} // namespace stereod::test
