#include "daemon/socket_server.hpp"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <mutex>
#include <system_error>
#include <type_traits>

#include <fcntl.h>
#include <grp.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/timerfd.h>
#include <sys/un.h>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "capture/frame.hpp"
#include "daemon/json_writer.hpp"

namespace stereod {

namespace {

static_assert(std::endian::native == std::endian::little,
              "payloads are sent in host byte order, which the protocol fixes as little-endian");
static_assert(sizeof(CloudPoint) == 16 && std::is_trivially_copyable_v<CloudPoint>,
              "a cloud point travels as four float32");

// epoll tags (epoll_event.data.u64).
constexpr uint64_t kTagListen = 1;
constexpr uint64_t kTagStop = 2;
constexpr uint64_t kTagTimer = 3;
constexpr uint64_t kTagPublisher = 4;
constexpr uint64_t kTagWatchBase = uint64_t{1} << 32;
constexpr uint64_t kFirstClientTag = uint64_t{1} << 40;

// Read at most this much from one client per turn of the loop (epoll is level-triggered:
// the rest is read on a later turn).
constexpr std::size_t kReadChunkBytes = 64 * 1024;
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
constexpr int kMaxEvents = 64;
// Raw frames are copied by the worker for this long after a raw snapshot or the last tick
// that saw a raw subscriber.
constexpr int64_t kRawInterestNs = 2'000'000'000;
// A raw snapshot waits at most this long for a pair with raw frames.
constexpr int64_t kRawSnapshotWaitNs = 5'000'000'000;

std::string errnoText(int error)
{
    return std::system_category().message(error);
}

struct BoundSocket {
    UniqueFd fd;
    bool owned = true;
    dev_t dev = 0;
    ino_t ino = 0;
};

sockaddr_un socketAddress(const std::string& path)
{
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    if (path.empty())
        throw SocketError("socket.path is empty");
    if (path.size() >= sizeof address.sun_path)
        throw SocketError("socket path " + path + " is too long: " + std::to_string(path.size()) +
                          " bytes, at most " + std::to_string(sizeof address.sun_path - 1));
    std::memcpy(address.sun_path, path.c_str(), path.size() + 1);
    return address;
}

gid_t lookUpGroup(const std::string& group, const std::string& path)
{
    if (std::all_of(group.begin(), group.end(), [](char c) { return c >= '0' && c <= '9'; }))
        return static_cast<gid_t>(std::stoul(group));
    struct group entry {};
    struct group* found = nullptr;
    std::vector<char> buffer(16384);
    const int error = ::getgrnam_r(group.c_str(), &entry, buffer.data(), buffer.size(), &found);
    if (error != 0)
        throw SocketError("socket " + path + ": cannot look up group " + group + ": " +
                          errnoText(error));
    if (found == nullptr)
        throw SocketError("socket " + path + ": no such group: " + group);
    return found->gr_gid;
}

// A listening socket systemd handed over for `path`, if any.
UniqueFd systemdSocket(const std::string& path)
{
    const int count = sd_listen_fds(1);
    for (int fd = SD_LISTEN_FDS_START; fd < SD_LISTEN_FDS_START + count; ++fd) {
        if (sd_is_socket_unix(fd, SOCK_STREAM, 1, path.c_str(), 0) > 0) {
            const int flags = ::fcntl(fd, F_GETFL);
            if (flags < 0 || ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) != 0)
                throw SocketError(
                    "socket " + path +
                    " from systemd: cannot make it non-blocking: " + errnoText(errno));
            return UniqueFd(fd);
        }
    }
    return UniqueFd();
}

// Who is at the other end of a connection, as the kernel says: SO_PEERCRED gives the
// process, user and group at connect time, SO_PEERGROUPS its supplementary groups.
struct PeerCredentials {
    pid_t pid = 0;
    uid_t uid = static_cast<uid_t>(-1);
    gid_t gid = static_cast<gid_t>(-1);
    std::vector<gid_t> groups; // supplementary groups; read only when allow_gids needs them
};

// False (errno set) when the kernel cannot say who it is.
bool readPeerCredentials(int fd, bool with_groups, PeerCredentials& peer)
{
    ucred credentials{};
    socklen_t length = sizeof credentials;
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &credentials, &length) != 0)
        return false;
    peer.pid = credentials.pid;
    peer.uid = credentials.uid;
    peer.gid = credentials.gid;
    if (!with_groups)
        return true;
    peer.groups.resize(32);
    for (int attempt = 0; attempt < 2; ++attempt) {
        auto bytes = static_cast<socklen_t>(peer.groups.size() * sizeof(gid_t));
        if (::getsockopt(fd, SOL_SOCKET, SO_PEERGROUPS, peer.groups.data(), &bytes) == 0) {
            peer.groups.resize(bytes / sizeof(gid_t));
            return true;
        }
        if (errno != ERANGE)
            break;
        peer.groups.resize(bytes / sizeof(gid_t)); // the kernel said how many there are
    }
    peer.groups.clear(); // an old kernel: only the primary group counts
    return true;
}

// Whether socket.allow_uids / socket.allow_gids let this peer in (both empty: anyone who
// can open the socket file).
bool peerAllowed(const SocketConfig& config, const PeerCredentials& peer)
{
    if (config.allow_uids.empty() && config.allow_gids.empty())
        return true;
    const auto listed = [](const std::vector<uint32_t>& ids, uint32_t id) {
        return std::find(ids.begin(), ids.end(), id) != ids.end();
    };
    if (listed(config.allow_uids, peer.uid) || listed(config.allow_gids, peer.gid))
        return true;
    return std::any_of(peer.groups.begin(), peer.groups.end(),
                       [&](gid_t group) { return listed(config.allow_gids, group); });
}

// Seconds as a person writes them: "30", "0.5".
std::string formatSeconds(double seconds)
{
    std::array<char, 32> text{};
    std::snprintf(text.data(), text.size(), "%g", seconds);
    return text.data();
}

// Turns a fresh connection away with one error line, then closes it. The line is short
// and the new socket's send buffer empty, so one non-blocking send takes it whole.
void refuseConnection(UniqueFd connection, ErrorCode code, const std::string& message)
{
    std::string line;
    appendJsonLine(line, errorReply(code, message, std::nullopt));
    [[maybe_unused]] const ssize_t sent =
        ::send(connection.get(), line.data(), line.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
}

// Removes a socket file nothing listens on; fails when something answers, or when the
// path holds something other than a socket (a symbolic link included: following it
// could remove or replace a file elsewhere).
void clearSocketPath(const std::string& path, const sockaddr_un& address)
{
    struct stat info {};
    if (::lstat(path.c_str(), &info) != 0) {
        if (errno == ENOENT)
            return;
        throw SocketError("cannot check socket path " + path + ": " + errnoText(errno));
    }
    if (S_ISLNK(info.st_mode))
        throw SocketError("refusing socket path " + path + ": it is a symbolic link");
    if (!S_ISSOCK(info.st_mode))
        throw SocketError("refusing socket path " + path +
                          ": something other than a socket is there");
    // Non-blocking, so that a live server with a full backlog cannot stall the probe.
    UniqueFd probe(::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    if (!probe)
        throw SocketError("cannot create a socket: " + errnoText(errno));
    if (::connect(probe.get(), reinterpret_cast<const sockaddr*>(&address), sizeof address) == 0 ||
        errno == EAGAIN || errno == EINPROGRESS)
        throw SocketError("another service is listening on " + path +
                          " (a stereod already running?): stop it or choose another socket.path");
    if (errno != ECONNREFUSED)
        throw SocketError("cannot tell whether socket " + path + " is in use: " + errnoText(errno));
    if (::unlink(path.c_str()) != 0 && errno != ENOENT)
        throw SocketError("cannot remove the stale socket " + path + ": " + errnoText(errno));
    spdlog::info("removed the stale socket file {}", path);
}

BoundSocket bindSocket(const SocketConfig& config, bool accept_systemd_socket)
{
    const std::string& path = config.path;
    const sockaddr_un address = socketAddress(path);
    BoundSocket bound;

    if (accept_systemd_socket) {
        bound.fd = systemdSocket(path);
        if (bound.fd) {
            bound.owned = false;
            spdlog::info("listening on {} (socket from systemd)", path);
            return bound;
        }
    }

    const std::filesystem::path parent = std::filesystem::path(path).parent_path();
    if (!parent.empty()) {
        std::error_code error;
        std::filesystem::create_directories(parent, error);
        if (error)
            throw SocketError("cannot create directory " + parent.string() + " for socket " + path +
                              ": " + error.message());
    }
    clearSocketPath(path, address);

    bound.fd = UniqueFd(::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    if (!bound.fd)
        throw SocketError("cannot create a socket: " + errnoText(errno));
    // Created owner-only, then opened up to socket.mode: never briefly wider than asked.
    const mode_t old_mask = ::umask(0177);
    const int bound_rc =
        ::bind(bound.fd.get(), reinterpret_cast<const sockaddr*>(&address), sizeof address);
    const int bind_error = errno;
    ::umask(old_mask);
    if (bound_rc != 0)
        throw SocketError("cannot bind socket " + path + ": " + errnoText(bind_error));

    const auto fail = [&](const std::string& message) {
        ::unlink(path.c_str());
        throw SocketError(message);
    };
    if (::chmod(path.c_str(), static_cast<mode_t>(config.mode)) != 0)
        fail("cannot set the mode of socket " + path + ": " + errnoText(errno));
    if (!config.group.empty()) {
        gid_t gid = 0;
        try {
            gid = lookUpGroup(config.group, path);
        } catch (const SocketError& e) {
            fail(e.what());
        }
        if (::chown(path.c_str(), static_cast<uid_t>(-1), gid) != 0)
            fail("cannot give socket " + path + " to group " + config.group + ": " +
                 errnoText(errno));
    }
    if (::listen(bound.fd.get(), SOMAXCONN) != 0)
        fail("cannot listen on socket " + path + ": " + errnoText(errno));
    struct stat info {};
    if (::stat(path.c_str(), &info) != 0)
        fail("cannot stat socket " + path + ": " + errnoText(errno));
    bound.dev = info.st_dev;
    bound.ino = info.st_ino;
    return bound;
}

void appendMatBytes(std::string& out, const cv::Mat& mat)
{
    if (mat.empty())
        return;
    const std::size_t row_bytes = static_cast<std::size_t>(mat.cols) * mat.elemSize();
    if (mat.isContinuous()) {
        out.append(reinterpret_cast<const char*>(mat.data),
                   row_bytes * static_cast<std::size_t>(mat.rows));
        return;
    }
    for (int row = 0; row < mat.rows; ++row)
        out.append(reinterpret_cast<const char*>(mat.ptr(row)), row_bytes);
}

uint64_t matBytes(const cv::Mat& mat)
{
    return mat.empty() ? 0 : static_cast<uint64_t>(mat.total()) * mat.elemSize();
}

Json imagePayload(const char* name, const char* format, const cv::Mat& mat)
{
    Json payload = Json::object();
    payload["name"] = name;
    payload["format"] = format;
    payload["width"] = mat.empty() ? 0 : mat.cols;
    payload["height"] = mat.empty() ? 0 : mat.rows;
    payload["bytes"] = matBytes(mat);
    return payload;
}

// The socket file bound by this process's server, for removeOwnedSocketFile().
struct OwnedSocketFile {
    std::mutex mutex;
    bool present = false; // guarded by mutex
    std::string path;     // guarded by mutex
    dev_t dev = 0;        // guarded by mutex
    ino_t ino = 0;        // guarded by mutex
};

OwnedSocketFile& ownedSocketFile()
{
    static OwnedSocketFile file;
    return file;
}

// Removes `path` if it is still the socket file bound (same device and inode).
void removeIfStillOurs(const std::string& path, dev_t dev, ino_t ino) noexcept
{
    struct stat info {};
    if (::lstat(path.c_str(), &info) == 0 && S_ISSOCK(info.st_mode) && info.st_dev == dev &&
        info.st_ino == ino)
        ::unlink(path.c_str());
}

} // namespace

void removeOwnedSocketFile() noexcept
{
    OwnedSocketFile& file = ownedSocketFile();
    std::lock_guard lock(file.mutex);
    if (file.present)
        removeIfStillOurs(file.path, file.dev, file.ino);
    file.present = false;
}

SocketServer::SocketServer(const ServerOptions& options, Publisher& publisher,
                           ServerBackend& backend)
    : options_(options), publisher_(publisher), backend_(backend), read_buffer_(kReadChunkBytes)
{
    BoundSocket bound = bindSocket(options_.socket, options_.accept_systemd_socket);
    listen_fd_ = std::move(bound.fd);
    owns_socket_file_ = bound.owned;
    socket_dev_ = bound.dev;
    socket_ino_ = bound.ino;
    if (owns_socket_file_) {
        OwnedSocketFile& file = ownedSocketFile();
        std::lock_guard lock(file.mutex);
        file.present = true;
        file.path = options_.socket.path;
        file.dev = socket_dev_;
        file.ino = socket_ino_;
    }

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

    addToEpoll(listen_fd_.get(), kTagListen, EPOLLIN);
    addToEpoll(stop_fd_.get(), kTagStop, EPOLLIN);
    addToEpoll(timer_fd_.get(), kTagTimer, EPOLLIN);
    addToEpoll(publisher_.eventFd(), kTagPublisher, EPOLLIN);
}

SocketServer::~SocketServer()
{
    for (auto& [id, client] : clients_)
        client.fd.reset();
    clients_.clear();
    listen_fd_.reset();
    if (owns_socket_file_) {
        OwnedSocketFile& file = ownedSocketFile();
        std::lock_guard lock(file.mutex);
        if (file.present && file.dev == socket_dev_ && file.ino == socket_ino_)
            file.present = false;
        removeIfStillOurs(options_.socket.path, socket_dev_, socket_ino_);
    }
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
        const int fd = ::accept4(listen_fd_.get(), nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) {
            const int error = errno;
            if (error == EINTR || error == ECONNABORTED)
                continue;
            if (error == EAGAIN || error == EWOULDBLOCK)
                return;
            // Out of descriptors (EMFILE, ENFILE) or memory: the listening socket stays
            // readable, so stop watching it until the next tick instead of spinning.
            log_limiter_.log(spdlog::level::err, "socket.accept_failed", monotonicNowNs(),
                             "socket {}: cannot accept a connection: {}", options_.socket.path,
                             errnoText(error));
            epoll_event event{};
            event.data.u64 = kTagListen;
            ::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_MOD, listen_fd_.get(), &event);
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

void SocketServer::handleRequest(Client& client, std::string_view line)
{
    ParseResult parsed = parseRequest(line);
    if (ProtocolError* error = std::get_if<ProtocolError>(&parsed)) {
        reply(client, errorReply(error->code, error->message, error->id));
        return;
    }
    Request& request = std::get<Request>(parsed);
    try {
        std::visit([&](const auto& command) { handle(client, command, request.id); },
                   request.command);
    } catch (const std::exception& e) {
        log_limiter_.log(spdlog::level::err, "client.request_failed", monotonicNowNs(),
                         "client {}: request failed: {}", client.id - kFirstClientTag, e.what());
        if (!client.dead)
            reply(client, errorReply(ErrorCode::Internal, e.what(), request.id));
    }
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

bool SocketServer::due(Subscription& subscription, double max_hz_config, int64_t now_ns) const
{
    double hz = max_hz_config;
    if (subscription.max_hz)
        hz = hz > 0.0 ? std::min(hz, *subscription.max_hz) : *subscription.max_hz;
    if (hz <= 0.0)
        return true;
    const auto interval_ns = static_cast<int64_t>(1e9 / hz);
    // A frame up to a tenth of the interval early still counts, so that a source at the
    // very rate of the limit is not halved by jitter; the schedule advances by whole
    // intervals, so the mean rate stays at the limit.
    if (now_ns < subscription.next_due_ns - interval_ns / 10)
        return false;
    subscription.next_due_ns += interval_ns;
    if (subscription.next_due_ns <= now_ns)
        subscription.next_due_ns = now_ns + interval_ns;
    return true;
}

void SocketServer::onPublished()
{
    publisher_.clearEvent();
    const PublishedFrame* frame = publisher_.latest();
    if (frame == nullptr || frame->sequence == last_dispatched_sequence_)
        return;
    dispatchFrame(*frame, monotonicNowNs());
    last_dispatched_sequence_ = frame->sequence;
}

void SocketServer::dispatchFrame(const PublishedFrame& frame, int64_t now_ns)
{
    ReadingReport report;
    report.reading = frame.result.reading;
    report.message = frame.reason_message.view();
    reading_event_.clear();
    depth_header_.clear();
    zones_event_.clear();

    const cv::Mat& depth = frame.depth_mm;
    DepthEventHeader header;
    header.frame = frame.result.frame;
    header.stamp_ns = frame.result.stamp_ns;
    header.width = depth.empty() ? 0 : depth.cols;
    header.height = depth.empty() ? 0 : depth.rows;
    header.bytes = matBytes(depth);
    header.depth_valid = frame.depth_valid;

    const RawPair& raw = frame.raw;
    raw_header_.clear();
    RawEventHeader raw_header;
    raw_header.frame = frame.result.frame;
    raw_header.left_stamp_ns = raw.left_stamp_ns;
    raw_header.right_stamp_ns = raw.right_stamp_ns;
    raw_header.width = raw.left.cols;
    raw_header.height = raw.left.rows;
    const cv::Mat& depth_m = frame.result.depth_m;
    raw_header.depth_valid = frame.depth_valid;
    raw_header.depth_width = depth_m.empty() ? 0 : depth_m.cols;
    raw_header.depth_height = depth_m.empty() ? 0 : depth_m.rows;
    raw_header.cloud_points = frame.result.cloud.size();

    serveWaitingSnapshots(&frame, nullptr, now_ns);

    for (auto& [id, client] : clients_) {
        if (client.dead || !client.subscribed() || dropIfBacklogged(client))
            continue;
        const bool pending = client.unsent() > 0;
        bool appended = false;
        for (const StreamKind stream :
             {StreamKind::Readings, StreamKind::Depth, StreamKind::Raw, StreamKind::Zones}) {
            const bool is_depth = stream == StreamKind::Depth;
            const bool is_raw = stream == StreamKind::Raw;
            const bool is_zones = stream == StreamKind::Zones;
            Subscription& subscription =
                is_zones ? client.zones
                         : (is_raw ? client.raw : (is_depth ? client.depth : client.readings));
            if (!subscription.active)
                continue;
            // A pair taken before the subscriber's interest reached the worker has no raw
            // frames: it was never available to this stream, so it is not counted lost.
            if (is_raw && !raw.present)
                continue;
            // The raw stream is limited only by the subscriber's own max_hz: a recorder
            // wants every pair.
            const double config_hz = is_raw ? 0.0
                                     : is_depth
                                         ? options_.publish.depth_max_hz
                                         : options_.publish.readings_max_hz; // readings, zones
            // Frames this thread never saw (it was busy) are lost to a stream that wants
            // every frame.
            const bool every_frame = config_hz <= 0.0 && !subscription.max_hz;
            if (every_frame && subscription.last_sequence != 0 &&
                frame.sequence > subscription.last_sequence + 1) {
                const uint64_t lost = frame.sequence - subscription.last_sequence - 1;
                subscription.skipped += lost;
                counters_.frames_dropped += lost;
            }
            subscription.last_sequence = frame.sequence;
            if (!due(subscription, config_hz, now_ns))
                continue;
            if (pending) {
                ++subscription.skipped;
                ++counters_.frames_dropped;
                continue;
            }
            compactOut(client);
            if (is_zones) {
                if (subscription.skipped > 0) {
                    appendZonesEvent(client.out, frame.zones, frame.result.frame,
                                     frame.result.stamp_ns, now_ns, subscription.skipped);
                } else {
                    if (zones_event_.empty())
                        appendZonesEvent(zones_event_, frame.zones, frame.result.frame,
                                         frame.result.stamp_ns, now_ns, 0);
                    client.out.append(zones_event_);
                }
            } else if (is_raw) {
                const bool with = subscription.with_depth || subscription.with_cloud;
                if (subscription.skipped > 0 || with) {
                    appendRawEventHeader(client.out, raw_header, subscription.skipped,
                                         subscription.with_depth, subscription.with_cloud);
                } else {
                    if (raw_header_.empty())
                        appendRawEventHeader(raw_header_, raw_header, 0);
                    client.out.append(raw_header_);
                }
                appendMatBytes(client.out, raw.left);
                appendMatBytes(client.out, raw.right);
                if (subscription.with_depth)
                    appendMatBytes(client.out, depth_m);
                if (subscription.with_cloud)
                    client.out.append(reinterpret_cast<const char*>(frame.result.cloud.data()),
                                      frame.result.cloud.size() * sizeof(CloudPoint));
            } else if (!is_depth) {
                if (subscription.skipped > 0) {
                    appendReadingEvent(client.out, report, now_ns, subscription.skipped);
                } else {
                    if (reading_event_.empty())
                        appendReadingEvent(reading_event_, report, now_ns, 0);
                    client.out.append(reading_event_);
                }
            } else {
                if (subscription.skipped > 0) {
                    appendDepthEventHeader(client.out, header, report, now_ns,
                                           subscription.skipped);
                } else {
                    if (depth_header_.empty())
                        appendDepthEventHeader(depth_header_, header, report, now_ns, 0);
                    client.out.append(depth_header_);
                }
                appendMatBytes(client.out, depth);
            }
            subscription.skipped = 0;
            appended = true;
        }
        if (appended)
            writeClient(client);
    }
}

void SocketServer::broadcastSourceDown(const SourceHealth& health, int64_t now_ns)
{
    std::string message;
    const ReadingReport report = currentReading(
        publisher_.latest(), std::numeric_limits<double>::infinity(), health, now_ns, message);
    for (auto& [id, client] : clients_) {
        if (client.dead || !client.readings.active || dropIfBacklogged(client))
            continue;
        if (client.unsent() > 0) {
            ++client.readings.skipped;
            ++counters_.frames_dropped;
            continue;
        }
        compactOut(client);
        appendReadingEvent(client.out, report, now_ns, client.readings.skipped);
        client.readings.skipped = 0;
        writeClient(client);
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
        if (::epoll_ctl(epoll_fd_.get(), EPOLL_CTL_MOD, listen_fd_.get(), &event) == 0)
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
    backend_.onTick(now_ns);
}

ReadingReport SocketServer::currentReading(const PublishedFrame* latest, double max_age_ms,
                                           const SourceHealth& health, int64_t now_ns,
                                           std::string& message) const
{
    ReadingReport report;
    if (latest == nullptr) {
        report.has_frame = false;
        report.reading.valid = false;
        if (!options_.calibrated && !health.down) {
            report.reading.reason = NoReadingReason::Uncalibrated;
            message = reasonText(NoReadingReason::Uncalibrated);
        } else if (health.down) {
            report.reading.reason = NoReadingReason::SourceDown;
            message = std::string(reasonText(NoReadingReason::SourceDown)) + ": " + health.message;
        } else {
            report.reading.reason = NoReadingReason::NoFrameYet;
            message = reasonText(NoReadingReason::NoFrameYet);
        }
        report.message = message;
        return report;
    }
    report.reading = latest->result.reading;
    report.message = latest->reason_message.view();
    const auto refuse = [&](NoReadingReason reason) {
        report.reading.valid = false;
        report.reading.distance_m = 0.0;
        report.reading.reason = reason;
        report.message = message;
    };
    if (health.down) {
        message = std::string(reasonText(NoReadingReason::SourceDown)) + ": " + health.message;
        refuse(NoReadingReason::SourceDown);
        return report;
    }
    // Without a calibration no reading will ever carry a distance: that is the reason to
    // give, whatever the age of the frame.
    if (report.reading.reason == NoReadingReason::Uncalibrated)
        return report;
    const double age_ms = static_cast<double>(now_ns - report.reading.stamp_ns) / 1e6;
    if (age_ms > max_age_ms) {
        std::array<char, 160> text{};
        std::snprintf(text.data(), text.size(), "%s: %.1f ms old, %.1f ms allowed",
                      reasonText(NoReadingReason::Stale), age_ms, max_age_ms);
        message = text.data();
        refuse(NoReadingReason::Stale);
    }
    return report;
}

void SocketServer::handle(Client& client, const HelloRequest&, const std::optional<Json>& id)
{
    Json answer = helloReply(id);
    answer["calibrated"] = options_.calibrated;
    reply(client, answer);
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

void SocketServer::handle(Client& client, const DistanceRequest& request,
                          const std::optional<Json>& id)
{
    const int64_t now_ns = monotonicNowNs();
    const SourceHealth health = backend_.sourceHealth(now_ns);
    std::string message;
    const ReadingReport report = currentReading(
        publisher_.latest(), request.max_age_ms.value_or(options_.publish.max_reading_age_ms),
        health, now_ns, message);
    if (client.dead || dropIfBacklogged(client))
        return;
    // Written directly: `distance` may be polled at a high rate.
    JsonObjectWriter object = openDirectReply(client, id);
    appendReadingJson(object.openField("reading"), report, now_ns);
    object.close();
    client.out.push_back('\n');
}

void SocketServer::handle(Client& client, const StatusRequest&, const std::optional<Json>& id)
{
    const int64_t now_ns = monotonicNowNs();
    const PublishedFrame* latest = publisher_.latest();
    const SourceHealth health = backend_.sourceHealth(now_ns);
    Json status = Json::object();
    backend_.describe(status, latest, health, now_ns);
    const ClientCounters clients = counters();
    status["clients"] = {{"connected", clients.connected},
                         {"subscribers", clients.subscribers},
                         {"frames_dropped", clients.frames_dropped},
                         {"disconnected_slow", clients.disconnected_slow},
                         {"accepted", clients.accepted},
                         {"rejected", clients.rejected},
                         {"not_allowed", clients.not_allowed},
                         {"idle_closed", clients.idle_closed}};
    std::string message;
    status["reading"] = readingToJson(
        currentReading(latest, options_.publish.max_reading_age_ms, health, now_ns, message),
        now_ns);
    Json answer = okReply(id);
    answer["status"] = std::move(status);
    reply(client, answer);
}

void SocketServer::handle(Client& client, const SnapshotRequest& request,
                          const std::optional<Json>& id)
{
    const bool wants_raw =
        std::any_of(request.items.begin(), request.items.end(), [](SnapshotItem item) {
            return item == SnapshotItem::RawLeft || item == SnapshotItem::RawRight;
        });
    const int64_t now_ns = monotonicNowNs();
    const PublishedFrame* latest = publisher_.latest();
    if (wants_raw) {
        publisher_.wantRawUntil(now_ns + kRawInterestNs);
        // The newest pair has raw frames only if someone asked for them recently; else
        // the next pair will (answered by serveWaitingSnapshots()).
        if (latest == nullptr || !latest->raw.present) {
            client.waiting = WaitingSnapshot{request, id, now_ns};
            return;
        }
    }
    if (latest == nullptr) {
        reply(client, errorReply(ErrorCode::NotAvailable, "no frame processed yet", id));
        return;
    }
    sendSnapshot(client, request, id, *latest);
}

void SocketServer::sendSnapshot(Client& client, const SnapshotRequest& request,
                                const std::optional<Json>& id, const PublishedFrame& frame)
{
    const PublishedFrame* latest = &frame;
    const int64_t now_ns = monotonicNowNs();
    const DepthResult& result = latest->result;
    const struct {
        const cv::Mat& mat;
        int type;
        const char* name;
    } images[] = {{latest->depth_mm, CV_16UC1, "depth"},
                  {result.disparity, CV_32FC1, "disparity"},
                  {result.left_rectified, CV_8UC1, "left"}};
    for (const auto& image : images) {
        if (!image.mat.empty() && image.mat.type() != image.type)
            throw std::logic_error(std::string("the ") + image.name +
                                   " image of the result has an unexpected pixel type");
    }

    std::string message;
    const ReadingReport report = currentReading(latest, options_.publish.max_reading_age_ms,
                                                backend_.sourceHealth(now_ns), now_ns, message);
    const RectifiedGeometry& geometry = options_.geometry;
    Json answer = okReply(id);
    answer["frame"] = result.frame;
    answer["stamp_ns"] = result.stamp_ns;
    answer["depth_valid"] = latest->depth_valid;
    answer["reading"] = readingToJson(report, now_ns);
    answer["calibration"] = {{"focal_px", geometry.focal_px},
                             {"baseline_m", geometry.baseline_m},
                             {"cx_px", geometry.cx_px},
                             {"cy_px", geometry.cy_px},
                             {"doffs_px", geometry.doffs_px}};
    Json payloads = Json::array();
    const uint64_t cloud_bytes = static_cast<uint64_t>(result.cloud.size()) * sizeof(CloudPoint);
    for (const SnapshotItem item : request.items) {
        switch (item) {
        case SnapshotItem::Depth:
            payloads.push_back(imagePayload("depth", "u16_mm", latest->depth_mm));
            break;
        case SnapshotItem::Disparity:
            payloads.push_back(imagePayload("disparity", "f32_px", result.disparity));
            break;
        case SnapshotItem::Left:
            payloads.push_back(imagePayload("left", "u8_gray", result.left_rectified));
            break;
        case SnapshotItem::Cloud: {
            Json payload = Json::object();
            payload["name"] = "cloud";
            payload["format"] = "f32_xyzi";
            payload["points"] = result.cloud.size();
            payload["bytes"] = cloud_bytes;
            payloads.push_back(std::move(payload));
            break;
        }
        case SnapshotItem::RawLeft:
        case SnapshotItem::RawRight: {
            const bool left = item == SnapshotItem::RawLeft;
            Json payload = imagePayload(snapshotItemName(item), "u8_gray",
                                        left ? latest->raw.left : latest->raw.right);
            payload["stamp_ns"] = left ? latest->raw.left_stamp_ns : latest->raw.right_stamp_ns;
            payloads.push_back(std::move(payload));
            break;
        }
        case SnapshotItem::Confidence:
            payloads.push_back(imagePayload("confidence", "u8_confidence", result.confidence));
            break;
        }
    }
    answer["payloads"] = std::move(payloads);
    reply(client, answer);
    if (client.dead)
        return;
    for (const SnapshotItem item : request.items) {
        switch (item) {
        case SnapshotItem::Depth:
            appendMatBytes(client.out, latest->depth_mm);
            break;
        case SnapshotItem::Disparity:
            appendMatBytes(client.out, result.disparity);
            break;
        case SnapshotItem::Left:
            appendMatBytes(client.out, result.left_rectified);
            break;
        case SnapshotItem::Cloud:
            client.out.append(reinterpret_cast<const char*>(result.cloud.data()), cloud_bytes);
            break;
        case SnapshotItem::RawLeft:
            appendMatBytes(client.out, latest->raw.left);
            break;
        case SnapshotItem::RawRight:
            appendMatBytes(client.out, latest->raw.right);
            break;
        case SnapshotItem::Confidence:
            appendMatBytes(client.out, result.confidence);
            break;
        }
    }
}

void SocketServer::finishWaiting(Client& client, const PublishedFrame* frame,
                                 std::string_view error)
{
    const WaitingSnapshot waiting = std::move(*client.waiting);
    client.waiting.reset();
    try {
        if (frame != nullptr)
            sendSnapshot(client, waiting.request, waiting.id, *frame);
        else
            reply(client, errorReply(ErrorCode::NotAvailable, error, waiting.id));
    } catch (const std::exception& e) {
        log_limiter_.log(spdlog::level::err, "client.request_failed", monotonicNowNs(),
                         "client {}: request failed: {}", client.id - kFirstClientTag, e.what());
        reply(client, errorReply(ErrorCode::Internal, e.what(), waiting.id));
    }
    if (client.dead)
        return;
    if (client.input_closed) {
        // The peer closed its side while its snapshot waited: serve what it sent last.
        while (!client.dead && !client.waiting && !client.in.empty()) {
            const std::size_t newline = client.in.find('\n');
            const std::string line = client.in.substr(0, newline);
            client.in.erase(0, newline == std::string::npos ? client.in.size() : newline + 1);
            if (line.size() < options_.socket.max_request_bytes)
                handleRequest(client, line);
        }
        if (!client.dead && !client.subscribed() && !client.waiting)
            client.close_when_flushed = true;
    } else {
        handleLines(client);
    }
    if (!client.dead)
        writeClient(client);
}

void SocketServer::serveWaitingSnapshots(const PublishedFrame* frame, const SourceHealth* health,
                                         int64_t now_ns)
{
    for (auto& [id, client] : clients_) {
        if (client.dead || !client.waiting)
            continue;
        if (frame != nullptr && frame->raw.present) {
            finishWaiting(client, frame, {});
        } else if (health != nullptr && health->down) {
            finishWaiting(client, nullptr,
                          "no raw frames: " + std::string(reasonText(NoReadingReason::SourceDown)) +
                              ": " + health->message);
        } else if (now_ns - client.waiting->since_ns > kRawSnapshotWaitNs) {
            finishWaiting(client, nullptr,
                          "no raw frames: no pair arrived within " +
                              std::to_string(kRawSnapshotWaitNs / 1'000'000'000) + " s");
        }
    }
}

void SocketServer::refreshRawInterest(int64_t now_ns)
{
    for (const auto& [id, client] : clients_) {
        if (!client.dead && client.raw.active) {
            publisher_.wantRawUntil(now_ns + kRawInterestNs);
            return;
        }
    }
}

void SocketServer::handle(Client& client, const SubscribeRequest& request,
                          const std::optional<Json>& id)
{
    Subscription& subscription = request.stream == StreamKind::Raw     ? client.raw
                                 : request.stream == StreamKind::Depth ? client.depth
                                 : request.stream == StreamKind::Zones ? client.zones
                                                                       : client.readings;
    if (request.stream == StreamKind::Raw)
        publisher_.wantRawUntil(monotonicNowNs() + kRawInterestNs);
    subscription = Subscription{};
    subscription.active = true;
    subscription.max_hz = request.max_hz;
    subscription.last_sequence = last_dispatched_sequence_;
    subscription.with_depth = request.with_depth;
    subscription.with_cloud = request.with_cloud;
    Json answer = okReply(id);
    answer["stream"] = streamName(request.stream);
    reply(client, answer);
}

void SocketServer::handle(Client& client, const ReloadRequest&, const std::optional<Json>& id)
{
    const ReloadOutcome outcome = backend_.reload();
    if (!outcome.ok) {
        reply(client, errorReply(outcome.error, outcome.message, id));
        return;
    }
    Json answer = okReply(id);
    answer["changed"] = outcome.changed;
    answer["restart_needed"] = outcome.restart_needed;
    reply(client, answer);
}

void SocketServer::handle(Client& client, const ZonesRequest&, const std::optional<Json>& id)
{
    const int64_t now_ns = monotonicNowNs();
    const PublishedFrame* latest = publisher_.latest();
    if (client.dead || dropIfBacklogged(client))
        return;
    JsonObjectWriter object = openDirectReply(client, id);
    if (latest == nullptr) {
        object.nullField("frame");
        object.openField("zones").append("[]");
    } else {
        object.field("frame", latest->result.frame);
        object.field("stamp_ns", latest->result.stamp_ns);
        object.field("age_ms",
                     roundTo(static_cast<double>(now_ns - latest->result.stamp_ns) / 1e6, 3));
        appendZonesJson(object.openField("zones"), latest->zones);
        appendCameraPoseJson(object.openField("camera_pose"), latest->camera_pose);
        if (options_.calibrated) {
            // What a client needs to draw the zones on the rectified left image.
            JsonObjectWriter camera(object.openField("camera"));
            camera.field("focal_px", options_.geometry.focal_px);
            camera.field("cx_px", options_.geometry.cx_px);
            camera.field("cy_px", options_.geometry.cy_px);
            camera.field("width", options_.geometry.image_size.width);
            camera.field("height", options_.geometry.image_size.height);
            camera.close();
        }
    }
    object.close();
    client.out.push_back('\n');
}

void SocketServer::handle(Client& client, const CalibrationRequest&, const std::optional<Json>& id)
{
    Json answer = okReply(id);
    answer["calibrated"] = options_.calibrated;
    if (options_.calibrated) {
        if (options_.calibration_text.empty()) {
            reply(client, errorReply(ErrorCode::NotAvailable,
                                     "the calibration in force was not read from a file", id));
            return;
        }
        answer["path"] = options_.calibration_path;
        answer["text"] = options_.calibration_text;
    }
    reply(client, answer);
}

} // namespace stereod
