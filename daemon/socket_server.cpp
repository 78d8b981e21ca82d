#include "daemon/socket_server.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <system_error>

#include <spdlog/spdlog.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include "base/descriptor_budget.hpp"
#include "base/system_error.hpp"
#include "capture/frame.hpp"
#include "daemon/peer_credentials.hpp"

namespace stereod {

namespace {

// epoll tags (epoll_event.data.u64); clients from SocketServer::kFirstClientTag on.
constexpr uint64_t kTagListen = 1;
constexpr uint64_t kTagStop = 2;
constexpr uint64_t kTagTimer = 3;
constexpr uint64_t kTagPublisher = 4;
constexpr uint64_t kTagWatchBase = uint64_t{1} << 32;

// Read at most this much from one client per turn of the loop (epoll is level-triggered:
// the rest is read on a later turn).
constexpr std::size_t kReadChunkBytes = 64 * 1024;
constexpr int kMaxEvents = 64;

// Seconds as a person writes them: "30", "0.5".
std::string formatSeconds(double seconds)
{
    std::array<char, 32> text{};
    std::snprintf(text.data(), text.size(), "%g", seconds);
    return text.data();
}

// Turns a fresh connection away with one error line, then closes it. The line is short
// and the new socket's send buffer empty, so one non-blocking send takes it whole.
void sendRefusal(int connection, ErrorCode code, const std::string& message)
{
    std::string line;
    appendJsonLine(line, errorReply(code, message, std::nullopt));
    [[maybe_unused]] const ssize_t sent =
        ::send(connection, line.data(), line.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
}

void refuseConnection(UniqueFd connection, ErrorCode code, const std::string& message)
{
    sendRefusal(connection.get(), code, message);
}

} // namespace

SocketServer::SocketServer(const ServerOptions& options, Publisher& publisher,
                           ServerBackend& backend)
    : options_(options), publisher_(publisher), backend_(backend),
      listener_(options_.socket, options_.accept_systemd_socket), read_buffer_(kReadChunkBytes)
{
    epoll_fd_ = UniqueFd(::epoll_create1(EPOLL_CLOEXEC));
    stop_fd_ = UniqueFd(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
    timer_fd_ = UniqueFd(::timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC));
    if (!epoll_fd_ || !stop_fd_ || !timer_fd_)
        throw SocketError("socket " + options_.socket.path +
                          ": cannot set up the event loop: " + errnoText(errno));
    itimerspec tick{};
    tick.it_interval.tv_nsec = kTickNs;
    tick.it_value.tv_nsec = kTickNs;
    if (::timerfd_settime(timer_fd_.get(), 0, &tick, nullptr) != 0)
        throw SocketError("cannot start the service timer: " + errnoText(errno));

    addToEpoll(listener_.fd(), kTagListen, EPOLLIN);
    addToEpoll(stop_fd_.get(), kTagStop, EPOLLIN);
    addToEpoll(timer_fd_.get(), kTagTimer, EPOLLIN);
    addToEpoll(publisher_.eventFd(), kTagPublisher, EPOLLIN);
}

SocketServer::~SocketServer()
{
    for (auto& [id, client] : clients_)
        client.fd.reset();
    clients_.clear();
}

void SocketServer::addToEpoll(int fd, uint64_t tag, uint32_t events)
{
    epoll_event event{};
    event.events = events;
    event.data.u64 = tag;
    if (::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_ADD, fd, &event) != 0)
        throw SocketError("epoll_ctl(ADD): " + errnoText(errno));
}

void SocketServer::watch(int fd, std::function<void()> on_readable)
{
    addToEpoll(fd, kTagWatchBase + watches_.size(), EPOLLIN);
    watches_.push_back(std::move(on_readable));
}

void SocketServer::requestStop() noexcept
{
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = ::write(stop_fd_.get(), &one, sizeof one);
}

void SocketServer::setPublishConfig(const PublishConfig& publish)
{
    options_.publish = publish;
}

void SocketServer::setCalibration(const RectifiedGeometry& geometry, const std::string& path,
                                  const std::string& text)
{
    options_.geometry = geometry;
    options_.calibration_path = path;
    options_.calibration_text = text;
    options_.calibrated = true;
}

ClientCounters SocketServer::counters() const
{
    ClientCounters counters = counters_;
    counters.connected = live_clients_;
    counters.subscribers = 0;
    for (const auto& [id, client] : clients_)
        counters.subscribers += (!client.dead && client.subscribed()) ? 1 : 0;
    return counters;
}

void SocketServer::run()
{
    std::array<epoll_event, kMaxEvents> events{};
    stopping_ = false;
    while (!stopping_) {
        // Clients with requests waiting for their turn: look for new events without
        // sleeping, then serve them.
        const int count =
            ::epoll_wait(epoll_fd_.get(), events.data(), kMaxEvents, ready_.empty() ? -1 : 0);
        if (count < 0) {
            if (errno == EINTR)
                continue;
            throw SocketError("epoll_wait: " + errnoText(errno));
        }
        for (int i = 0; i < count && !stopping_; ++i) {
            const uint64_t tag = events[static_cast<std::size_t>(i)].data.u64;
            const uint32_t what = events[static_cast<std::size_t>(i)].events;
            if (tag >= kFirstClientTag) {
                const auto it = clients_.find(tag);
                if (it == clients_.end() || it->second.dead)
                    continue;
                Client& client = it->second;
                if ((what & EPOLLERR) != 0) {
                    closeClient(client);
                    continue;
                }
                if ((what & EPOLLIN) != 0)
                    readClient(client);
                // Both directions shut: the peer is gone, nothing more can reach it.
                if (!client.dead && (what & EPOLLHUP) != 0) {
                    closeClient(client);
                    continue;
                }
                if (!client.dead && (what & EPOLLOUT) != 0)
                    writeClient(client);
            } else if (tag >= kTagWatchBase) {
                watches_[tag - kTagWatchBase]();
            } else if (tag == kTagListen) {
                acceptClients();
            } else if (tag == kTagPublisher) {
                onPublished();
            } else if (tag == kTagTimer) {
                uint64_t expirations = 0;
                [[maybe_unused]] const ssize_t got =
                    ::read(timer_fd_.get(), &expirations, sizeof expirations);
                onTick();
            } else if (tag == kTagStop) {
                uint64_t value = 0;
                [[maybe_unused]] const ssize_t got = ::read(stop_fd_.get(), &value, sizeof value);
                stopping_ = true;
            }
        }
        if (!stopping_)
            serveReadyClients();
        reapClients();
    }
}

void SocketServer::acceptClients()
{
    for (;;) {
        const int fd = ::accept4(listener_.fd(), nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) {
            const int error = errno;
            if (error == EINTR || error == ECONNABORTED)
                continue;
            if (error == EAGAIN || error == EWOULDBLOCK)
                return;
            // Out of descriptors (EMFILE, ENFILE): the spare descriptor takes the waiting
            // connections one by one, each told why and closed, rather than leave them
            // hanging in the backlog. Then, as for memory, the listening socket is not
            // watched until the next tick: the loop backs off instead of spinning.
            if (outOfDescriptors(error)) {
                std::size_t refused = 0;
                while (spare_descriptor_.refuseWaitingConnection(listener_.fd(), [](int waiting) {
                    sendRefusal(waiting, ErrorCode::TooManyClients,
                                "the service is out of file descriptors; try again later");
                }))
                    ++refused;
                counters_.rejected += refused;
                log_limiter_.log(spdlog::level::err, "socket.out_of_descriptors", monotonicNowNs(),
                                 "socket {}: out of file descriptors ({} open, limit {}): "
                                 "{} connection(s) refused; accepting again in {} ms",
                                 options_.socket.path, countOpenDescriptors(), descriptorLimit(),
                                 refused, kTickNs / 1'000'000);
            } else {
                log_limiter_.log(spdlog::level::err, "socket.accept_failed", monotonicNowNs(),
                                 "socket {}: cannot accept a connection: {}", options_.socket.path,
                                 errnoText(error));
            }
            epoll_event event{};
            event.data.u64 = kTagListen;
            ::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_MOD, listener_.fd(), &event);
            listen_paused_ = true;
            return;
        }
        UniqueFd connection(fd);
        const bool allow_list =
            !options_.socket.allow_uids.empty() || !options_.socket.allow_gids.empty();
        PeerCredentials peer;
        if (!readPeerCredentials(connection.get(), !options_.socket.allow_gids.empty(), peer)) {
            const std::string why = errnoText(errno);
            spdlog::warn("socket {}: cannot read the credentials of a new connection: {}",
                         options_.socket.path, why);
            if (allow_list) {
                refuseConnection(std::move(connection), ErrorCode::NotAllowed,
                                 "the service cannot tell who is connecting (" + why + ")");
                ++counters_.not_allowed;
                continue;
            }
        } else if (!peerAllowed(options_.socket, peer)) {
            refuseConnection(std::move(connection), ErrorCode::NotAllowed,
                             "uid " + std::to_string(peer.uid) + " (gid " +
                                 std::to_string(peer.gid) +
                                 ") is not in socket.allow_uids and in no group of "
                                 "socket.allow_gids");
            ++counters_.not_allowed;
            log_limiter_.log(spdlog::level::warn, "socket.not_allowed", monotonicNowNs(),
                             "socket {}: refused pid {} uid {} gid {}: not in "
                             "socket.allow_uids or socket.allow_gids",
                             options_.socket.path, peer.pid, peer.uid, peer.gid);
            continue;
        }
        const auto max_clients = static_cast<std::size_t>(std::max(options_.socket.max_clients, 0));
        // Clients that hung up since the last turn still count until their events are
        // read: under fast connect/close churn they would fill the limit. Close them now.
        if (live_clients_ >= max_clients)
            closeHungUpClients();
        if (live_clients_ >= max_clients) {
            refuseConnection(std::move(connection), ErrorCode::TooManyClients,
                             std::to_string(options_.socket.max_clients) +
                                 " connections are open (socket.max_clients)");
            ++counters_.rejected;
            log_limiter_.log(spdlog::level::warn, "socket.too_many_clients", monotonicNowNs(),
                             "socket {}: connection refused, {} clients already connected",
                             options_.socket.path, live_clients_);
            continue;
        }
        const uint64_t id = kFirstClientTag + next_client_id_++;
        addToEpoll(connection.get(), id, EPOLLIN);
        Client& client = clients_[id];
        client.fd = std::move(connection);
        client.id = id;
        client.epoll_events = EPOLLIN;
        client.last_input_ns = monotonicNowNs();
        ++live_clients_;
        ++counters_.accepted;
        // Per uid: a client reconnecting in a loop shows as one line per interval with
        // its count, and every other user still gets its own line.
        log_limiter_.log(spdlog::level::info, fmt::format("client.connected.uid{}", peer.uid),
                         monotonicNowNs(), "client {} connected: pid {} uid {} gid {} ({} open)",
                         id - kFirstClientTag, peer.pid, peer.uid, peer.gid, live_clients_);
    }
}

void SocketServer::onTick()
{
    const int64_t now_ns = monotonicNowNs();
    log_limiter_.flush(now_ns);
    if (listen_paused_) {
        epoll_event event{};
        event.events = EPOLLIN;
        event.data.u64 = kTagListen;
        if (::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_MOD, listener_.fd(), &event) == 0)
            listen_paused_ = false;
    }
    const SourceHealth health = backend_.sourceHealth(now_ns);
    if (health.down && !source_was_down_) {
        spdlog::warn("frame source down: {}", health.message);
        broadcastSourceDown(health, now_ns);
    } else if (!health.down && source_was_down_) {
        spdlog::info("frame source producing again");
    }
    source_was_down_ = health.down;
    refreshRawInterest(now_ns);
    serveWaitingSnapshots(nullptr, &health, now_ns);

    if (options_.socket.idle_timeout_s > 0.0) {
        const auto idle_ns = static_cast<int64_t>(options_.socket.idle_timeout_s * 1e9);
        for (auto& [id, client] : clients_) {
            if (!client.dead && !client.subscribed() && !client.waiting && client.unsent() == 0 &&
                now_ns - client.last_input_ns > idle_ns) {
                spdlog::info("client {}: nothing received for {} s (socket.idle_timeout_s), "
                             "disconnected",
                             id - kFirstClientTag, options_.socket.idle_timeout_s);
                ++counters_.idle_closed;
                reply(client, errorReply(ErrorCode::IdleTimeout,
                                         "nothing received for " +
                                             formatSeconds(options_.socket.idle_timeout_s) +
                                             " s (socket.idle_timeout_s); closing the connection",
                                         std::nullopt));
                client.in.clear();
                client.in_start = 0;
                client.input_closed = true;
                client.close_when_flushed = true;
                writeClient(client);
            }
        }
    }
    notifyObserverOfStatus(now_ns);
    backend_.onTick(now_ns);
}

} // namespace stereod
