#include <cerrno>
#include <system_error>

#include <spdlog/spdlog.h>
#include <sys/epoll.h>
#include <sys/socket.h>

#include "base/system_error.hpp"
#include "capture/frame.hpp"
#include "daemon/socket_server.hpp"

namespace stereod {

namespace {

// Answer at most this many requests of one client per turn of the loop, then serve the
// others: a client pipelining a megabyte of requests delays another one by a few
// requests' work, not by its whole backlog. The rest waits in the client's input, and
// the client in the ready list, for the next turn.
constexpr int kRequestsPerTurn = 8;
// An output buffer that grew beyond this (a snapshot) is given back once sent.
constexpr std::size_t kKeepOutCapacity = 8u << 20;
// Unread input left at close makes the peer's read fail with ECONNRESET after our last
// reply; read (and drop) up to this much first.
constexpr std::size_t kCloseDrainBytes = 1 << 20;

} // namespace

void SocketServer::closeHungUpClients()
{
    hangup_poll_.clear();
    hangup_ids_.clear();
    for (const auto& [id, client] : clients_) {
        if (client.dead)
            continue;
        hangup_poll_.push_back(pollfd{client.fd.get(), 0, 0});
        hangup_ids_.push_back(id);
    }
    if (hangup_poll_.empty() ||
        ::poll(hangup_poll_.data(), static_cast<nfds_t>(hangup_poll_.size()), 0) <= 0)
        return;
    for (std::size_t i = 0; i < hangup_poll_.size(); ++i) {
        // POLLHUP: both directions shut, the peer is gone (one that only shut its writing
        // side still waits for its replies, and keeps its place).
        if ((hangup_poll_[i].revents & (POLLHUP | POLLERR)) != 0)
            closeClient(clients_.at(hangup_ids_[i]));
    }
}

void SocketServer::readClient(Client& client)
{
    // One chunk per turn, and nothing while requests already received wait for their
    // turn (EPOLLIN is off then, see updateEpoll()).
    while (!client.dead && !client.input_closed && !client.pending) {
        const ssize_t got = ::recv(client.fd.get(), read_buffer_.data(), read_buffer_.size(), 0);
        if (got > 0) {
            client.in.append(read_buffer_.data(), static_cast<std::size_t>(got));
            client.last_input_ns = monotonicNowNs();
            handleLines(client);
            break;
        }
        if (got == 0) {
            // The peer shut down its side: answer a last line without its newline, then
            // keep the connection only for subscriptions and unsent replies.
            client.input_closed = true;
            // Behind a waiting snapshot, the last line waits too (finishWaiting()).
            if (client.waiting)
                break;
            if (!client.in.empty() && client.in.size() < options_.socket.max_request_bytes) {
                const std::string last = std::move(client.in);
                client.in.clear();
                handleRequest(client, last);
            }
            client.in.clear();
            if (!client.dead && !client.subscribed() && !client.waiting)
                client.close_when_flushed = true;
            break;
        }
        if (errno == EINTR)
            continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) {
            closeClient(client);
            return;
        }
        break;
    }
    if (!client.dead)
        writeClient(client);
}

void SocketServer::serveReadyClients()
{
    std::vector<uint64_t> ready;
    ready.swap(ready_);
    for (const uint64_t id : ready) {
        const auto it = clients_.find(id);
        if (it == clients_.end() || it->second.dead)
            continue;
        Client& client = it->second;
        client.pending = false;
        handleLines(client);
        if (!client.dead)
            writeClient(client);
    }
    // The list's capacity is reused on the next turn.
    if (ready_.empty()) {
        ready.clear();
        ready_.swap(ready);
    }
}

void SocketServer::handleLines(Client& client)
{
    const std::size_t limit = options_.socket.max_request_bytes;
    std::size_t start = client.in_start;
    int served = 0;
    while (!client.dead && !client.input_closed && !client.waiting) {
        const std::size_t newline = client.in.find('\n', start);
        if (newline == std::string::npos)
            break;
        if (newline - start + 1 > limit) {
            rejectTooLarge(client);
            return;
        }
        if (served == kRequestsPerTurn) {
            // The others' turn: the rest of this input waits for the next turn.
            client.in_start = start;
            if (!client.pending) {
                client.pending = true;
                ready_.push_back(client.id);
            }
            return;
        }
        handleRequest(client, std::string_view(client.in).substr(start, newline - start));
        ++served;
        start = newline + 1;
    }
    if (client.dead || client.input_closed)
        return;
    client.in.erase(0, start);
    client.in_start = 0;
    // No newline within the limit: even if the next byte ended the line, it would be
    // longer than allowed.
    if (client.in.size() >= limit)
        rejectTooLarge(client);
}

void SocketServer::rejectTooLarge(Client& client)
{
    reply(client, errorReply(ErrorCode::RequestTooLarge,
                             "the request line exceeds " +
                                 std::to_string(options_.socket.max_request_bytes) +
                                 " bytes (socket.max_request_bytes); closing the connection",
                             std::nullopt));
    log_limiter_.log(spdlog::level::warn, "client.request_too_large", monotonicNowNs(),
                     "client {}: request line over {} bytes, connection closed",
                     client.id - kFirstClientTag, options_.socket.max_request_bytes);
    // The stream cannot be resynchronised: stop reading, send the reply, close.
    client.in.clear();
    client.in_start = 0;
    client.input_closed = true;
    client.close_when_flushed = true;
    client.readings.active = false;
    client.depth.active = false;
    client.raw.active = false;
    client.waiting.reset();
}

void SocketServer::compactOut(Client& client)
{
    if (client.out_sent > 0 && client.out_sent >= client.out.size() / 2) {
        client.out.erase(0, client.out_sent);
        client.out_sent = 0;
    }
}

bool SocketServer::dropIfBacklogged(Client& client)
{
    const std::size_t limit = options_.publish.max_client_backlog_bytes;
    if (client.unsent() <= limit)
        return false;
    ++counters_.disconnected_slow;
    log_limiter_.log(spdlog::level::warn, "client.backlog", monotonicNowNs(),
                     "client {}: disconnected, {} bytes unsent exceed "
                     "publish.max_client_backlog_bytes ({})",
                     client.id - kFirstClientTag, client.unsent(), limit);
    closeClient(client);
    return true;
}

void SocketServer::reply(Client& client, const Json& json)
{
    if (client.dead || dropIfBacklogged(client))
        return;
    compactOut(client);
    appendJsonLine(client.out, json);
}

JsonObjectWriter SocketServer::openDirectReply(Client& client, const std::optional<Json>& id)
{
    compactOut(client);
    JsonObjectWriter object(client.out);
    object.field("ok", true);
    if (id)
        object.rawField("id", id->dump(-1, ' ', false, Json::error_handler_t::replace));
    return object;
}

void SocketServer::writeClient(Client& client)
{
    while (client.unsent() > 0) {
        const ssize_t sent = ::send(client.fd.get(), client.out.data() + client.out_sent,
                                    client.unsent(), MSG_NOSIGNAL | MSG_DONTWAIT);
        if (sent > 0) {
            client.out_sent += static_cast<std::size_t>(sent);
            continue;
        }
        if (sent < 0 && errno == EINTR)
            continue;
        if (sent < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
            break;
        closeClient(client); // EPIPE, ECONNRESET: the peer is gone
        return;
    }
    if (client.unsent() == 0) {
        client.out.clear();
        client.out_sent = 0;
        if (client.out.capacity() > kKeepOutCapacity)
            std::string().swap(client.out);
        if (client.close_when_flushed) {
            closeClient(client);
            return;
        }
    }
    updateEpoll(client);
}

void SocketServer::updateEpoll(Client& client)
{
    const uint32_t wanted =
        (client.input_closed || client.pending ? 0u : static_cast<uint32_t>(EPOLLIN)) |
        (client.unsent() > 0 ? static_cast<uint32_t>(EPOLLOUT) : 0u);
    if (wanted == client.epoll_events)
        return;
    epoll_event event{};
    event.events = wanted;
    event.data.u64 = client.id;
    if (::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_MOD, client.fd.get(), &event) != 0) {
        spdlog::error("client {}: epoll_ctl(MOD): {}", client.id - kFirstClientTag,
                      errnoText(errno));
        closeClient(client);
        return;
    }
    client.epoll_events = wanted;
}

void SocketServer::closeClient(Client& client)
{
    if (client.dead)
        return;
    client.dead = true;
    ::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_DEL, client.fd.get(), nullptr);
    std::size_t drained = 0;
    while (drained < kCloseDrainBytes) {
        const ssize_t got =
            ::recv(client.fd.get(), read_buffer_.data(), read_buffer_.size(), MSG_DONTWAIT);
        if (got <= 0)
            break;
        drained += static_cast<std::size_t>(got);
    }
    client.fd.reset();
    --live_clients_;
    dead_clients_.push_back(client.id);
    spdlog::debug("client {} closed ({} open)", client.id - kFirstClientTag, live_clients_);
}

void SocketServer::reapClients()
{
    for (const uint64_t id : dead_clients_)
        clients_.erase(id);
    dead_clients_.clear();
}

} // namespace stereod
