#include "daemon/listening_socket.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <system_error>
#include <vector>

#include <fcntl.h>
#include <grp.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "base/system_error.hpp"

namespace stereod {

namespace {

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

ListeningSocket::ListeningSocket(const SocketConfig& config, bool accept_systemd_socket)
    : path_(config.path)
{
    BoundSocket bound = bindSocket(config, accept_systemd_socket);
    fd_ = std::move(bound.fd);
    owns_file_ = bound.owned;
    dev_ = bound.dev;
    ino_ = bound.ino;
    if (owns_file_) {
        OwnedSocketFile& file = ownedSocketFile();
        std::lock_guard lock(file.mutex);
        file.present = true;
        file.path = path_;
        file.dev = dev_;
        file.ino = ino_;
    }
}

ListeningSocket::~ListeningSocket()
{
    fd_.reset();
    if (owns_file_) {
        OwnedSocketFile& file = ownedSocketFile();
        std::lock_guard lock(file.mutex);
        if (file.present && file.dev == dev_ && file.ino == ino_)
            file.present = false;
        removeIfStillOurs(path_, dev_, ino_);
    }
}

} // namespace stereod
